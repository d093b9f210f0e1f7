"""Measurement planning for joint-stiffness identification: pick N
(pose, load direction) pairs from a candidate set so that the identification
is well conditioned (D-optimal design: maximise det(A^T A) of the
nominal-scaled regressor, greedy selection then Fedorov exchanges).  Plain
numpy; no Drake.

The predicted standard errors follow from cov(x) = sigma^2 (A^T A)^-1 with
x_j = c_j / c_nom_j, so sqrt(diag) is the relative standard error of each
joint's compliance (and, to first order, of its stiffness).
"""

from dataclasses import dataclass

import numpy as np

from robstiff_drake.identification.stiffness.joint_stiffness import ZERO_COLUMN_REL, regressor
from robstiff_drake.identification.stiffness.synth import sample_poses


def load_directions():
    """26 unit directions: axes, face diagonals and cube diagonals."""
    dirs = []
    for x in (-1, 0, 1):
        for y in (-1, 0, 1):
            for z in (-1, 0, 1):
                if (x, y, z) != (0, 0, 0):
                    dirs.append(np.array([x, y, z], dtype=float))
    d = np.array(dirs)
    return d / np.linalg.norm(d, axis=1, keepdims=True)


@dataclass
class Plan:
    q_rad: np.ndarray  # (N, 6)
    force_N: np.ndarray  # (N, 3)
    pose_index: np.ndarray  # (N,) index into the candidate poses
    rel_std_planned: np.ndarray  # (6,) NaN where not identifiable
    rel_std_random: np.ndarray  # (6,) median over random draws
    identifiable: np.ndarray  # (6,) bool
    logdet_planned: float
    logdet_random: float


def _blocks(robot, q_rad, forces, tool_m):
    W = np.hstack([forces, np.zeros_like(forces)])
    A_d, _ = regressor(robot.dh, q_rad, W, tool_m)
    return A_d * (1.0 / robot.joint_stiffness_Nm_per_rad)  # (M, 3, 6), columns in m


def _rel_std(A_blocks, sigma_m, free):
    A = A_blocks[:, :, free].reshape(-1, free.size)
    info = A.T @ A
    out = np.full(6, np.nan)
    try:
        out[free] = sigma_m * np.sqrt(np.diag(np.linalg.inv(info)))
    except np.linalg.LinAlgError:
        out[free] = np.inf
    return out, float(np.linalg.slogdet(info)[1])


def plan_poses(robot, n, *, n_candidate_poses=120, force_N=300.0, noise_mm=0.01, tool_m=None, seed=0,
               n_random=30, exchange_passes=2):
    rng = np.random.default_rng(seed)
    tool = np.zeros(3) if tool_m is None else np.asarray(tool_m, dtype=float)
    poses = sample_poses(robot, n_candidate_poses, rng, tool)
    dirs = load_directions()
    cand_q = np.repeat(poses, len(dirs), axis=0)
    cand_f = np.tile(dirs, (len(poses), 1)) * force_N
    cand_pose = np.repeat(np.arange(len(poses)), len(dirs))
    B = _blocks(robot, cand_q, cand_f, tool)  # (M, 3, 6)
    colnorm = np.linalg.norm(B.reshape(-1, 6), axis=0)
    free = np.flatnonzero(colnorm > ZERO_COLUMN_REL * colnorm.max())
    Bf = B[:, :, free]
    p = free.size
    sigma_m = noise_mm * 1e-3

    # greedy: add the candidate with the largest log det gain
    scale = np.mean(np.einsum("mij,mij->j", Bf, Bf)) / len(Bf)
    info = 1e-9 * scale * np.eye(p)
    chosen = []
    for _ in range(n):
        Minv = np.linalg.inv(info)
        S = np.eye(3) + np.einsum("mip,pq,mjq->mij", Bf, Minv, Bf)
        gain = np.linalg.slogdet(S)[1]
        gain[chosen] = -np.inf
        best = int(np.argmax(gain))
        chosen.append(best)
        info = info + Bf[best].T @ Bf[best]
    # Fedorov exchanges: swap a chosen point for a better candidate
    for _ in range(exchange_passes):
        improved = False
        for k in range(n):
            out_i = chosen[k]
            reduced = info - Bf[out_i].T @ Bf[out_i]
            if np.linalg.matrix_rank(reduced) < p:
                continue
            Minv = np.linalg.inv(reduced)
            S = np.eye(3) + np.einsum("mip,pq,mjq->mij", Bf, Minv, Bf)
            gain = np.linalg.slogdet(S)[1]
            gain[[c for c in chosen if c != out_i]] = -np.inf
            best = int(np.argmax(gain))
            if best != out_i and gain[best] > gain[out_i] + 1e-9:
                chosen[k] = best
                info = reduced + Bf[best].T @ Bf[best]
                improved = True
        if not improved:
            break
    chosen = np.array(chosen)
    rel_planned, logdet_planned = _rel_std(B[chosen], sigma_m, free)

    # random designs of the same size: random poses, random load directions
    rel_random, logdets = [], []
    for _ in range(n_random):
        q_r = sample_poses(robot, max(1, n // 4), rng, tool)[rng.integers(0, max(1, n // 4), n)]
        f_r = rng.normal(size=(n, 3))
        f_r *= force_N / np.linalg.norm(f_r, axis=1, keepdims=True)
        r, ld = _rel_std(_blocks(robot, q_r, f_r, tool), sigma_m, free)
        rel_random.append(r)
        logdets.append(ld)
    identifiable = np.zeros(6, dtype=bool)
    identifiable[free] = True
    return Plan(cand_q[chosen], cand_f[chosen], cand_pose[chosen], rel_planned,
                np.median(np.array(rel_random), axis=0), identifiable, logdet_planned, float(np.median(logdets)))
