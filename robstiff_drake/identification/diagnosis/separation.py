"""Measurements that separate two confounded effects (``robstiff plan-poses
N --separate A,B``).  Plain numpy; no Drake.

A and B are a joint's stiffness (``stiffness_jN``) or a term of the
diagnosis (a named effect or a dictionary term, identification/diagnosis/candidates.py
and dictionary.py).  The model is the six springs plus A and B, linearised
where the campaign puts it (its identified compliances; a Gauss-Newton term
at zero, i.e. its local sensitivity; a grid term at the middle of its grid).
From candidate poses (identification/stiffness/synth.py's sampler) times 26 load
directions, N (pose, load) rows are chosen greedily to minimise the sum of
the logarithms of the variances of A's and B's parameters, each with the
springs and the other effect free (the widths the diagnosis would report:
a variance is inflated by 1 / (1 - r^2) when the other effect explains the
same residual, so this is what separates them), starting from the
information of the user's campaign when one is given.  Reported: each parameter's predicted
95 % half-width (at the stated noise per displacement component) and the
correlation of A's and B's estimates, with the campaign alone and with the
plan added.
"""

from dataclasses import dataclass

import numpy as np

from robstiff_drake.errors import InputError
from robstiff_drake.identification.stiffness.campaign import StiffnessCampaign
from robstiff_drake.identification.diagnosis.candidates import CANDIDATES
from robstiff_drake.identification.diagnosis.confounding import correlation
from robstiff_drake.identification.diagnosis.dictionary import DICTIONARY
from robstiff_drake.identification.stiffness.pose_planning import load_directions
from robstiff_drake.identification.stiffness.synth import sample_poses
from robstiff_drake.identification.diagnosis.terms import GAUSS_NEWTON, GRID, Context, gauss_newton_columns, term_columns

Z95 = 1.96
MAX_TILT_DEG = 60.0


def effect_names():
    return [f"stiffness_j{j}" for j in range(1, 7)] + list(CANDIDATES) + list(DICTIONARY)


def parse_pair(text):
    """'A,B' -> (A, B), or InputError naming the allowed names."""
    parts = [p.strip() for p in str(text).split(",")]
    if len(parts) != 2 or parts[0] == parts[1]:
        raise InputError(f"--separate {text!r}: expected two different effects, EFFECT_A,EFFECT_B")
    known = effect_names()
    for p in parts:
        if p not in known:
            raise InputError(f"--separate: unknown effect {p!r}; allowed: stiffness_j1..stiffness_j6, the named "
                             f"effects ({', '.join(CANDIDATES)}) and the dictionary's terms (robstiff diagnose "
                             "--json lists them)")
    return tuple(parts)


def _campaign(q_deg, force_N, path="plan"):
    n = len(q_deg)
    return StiffnessCampaign(path, np.asarray(q_deg, float), np.asarray(force_N, float), np.zeros((n, 3)),
                             np.zeros((n, 3)), None, [f"P{i}" for i in range(n)], np.arange(1.0, n + 1),
                             np.arange(1, n + 1), [], False)


def _columns(ctx, name, c):
    """(3N, p) columns of effect ``name`` at compliances c, and its parameters' (name, unit, scale)."""
    if name.startswith("stiffness_j"):
        j = int(name[-1]) - 1
        col = ctx.from_dq(np.eye(6)[j] * ctx.tau[:, j:j + 1] * c[j]).reshape(-1, 1)
        return col, [(f"k{j + 1}", "% of the stiffness", 100.0)]
    t = CANDIDATES.get(name) or DICTIONARY[name]
    reason = t.needs(ctx) if t.needs else None
    if reason:
        raise InputError(f"--separate: {name} cannot be planned for: {reason}")
    if t.kind == GAUSS_NEWTON:
        return gauss_newton_columns(ctx, t, c, None)[0], t.params
    g = None
    if t.kind == GRID:
        grid = t.grid(ctx)
        g = grid[len(grid) // 2]
    return term_columns(ctx, t, c, None, g)[0], t.params


@dataclass
class SeparationPlan:
    effects: tuple
    q_rad: np.ndarray  # (N, 6) model angles of the planned rows
    force_N: np.ndarray  # (N, 3)
    pose_index: np.ndarray
    params: list  # [(effect, name, unit)]
    half_width_before: np.ndarray | None  # 95 % half-width per parameter, in its unit; None without a campaign
    half_width_after: np.ndarray
    correlation_before: float | None
    correlation_after: float


def _design(robot, q_rad, force_N, tool_m, effects, c):
    """Per-row blocks (N, 3, p): the six springs' columns (coefficient: the
    compliance relative to c) then the columns of the effects that are not
    a spring; and per effect its parameters' indices and labels."""
    camp = _campaign(robot.controller_deg(q_rad), force_N)
    ctx = Context(robot, camp, tool_m, np.ones(6, dtype=bool))
    springs = np.stack([ctx.from_dq(np.eye(6)[j] * ctx.tau[:, j:j + 1] * c[j]) for j in range(6)], axis=-1)
    blocks, index, labels, p = [springs], {}, {}, 6
    for name in effects:
        if name.startswith("stiffness_j"):
            j = int(name[-1]) - 1
            index[name], labels[name] = np.array([j]), [(f"k{j + 1}", "%", 100.0)]
            continue
        Z, params = _columns(ctx, name, c)
        blocks.append(Z.reshape(len(camp), 3, -1))
        index[name] = np.arange(p, p + Z.shape[1])
        labels[name] = list(params)
        p += Z.shape[1]
    return np.concatenate(blocks, axis=-1), index, labels


def plan_separation(robot, effects, n, *, campaign=None, compliance=None, n_candidate_poses=120, force_N=300.0,
                    noise_mm=0.01, tool_m=None, seed=0):
    """N rows that best separate ``effects`` (a pair of names, see module
    docstring), added to ``campaign`` (a StiffnessCampaign) when given."""
    rng = np.random.default_rng(seed)
    tool = np.zeros(3) if tool_m is None else np.asarray(tool_m, dtype=float)
    c = 1.0 / np.asarray(robot.joint_stiffness_Nm_per_rad, float) if compliance is None else np.asarray(compliance)
    # a wider spread of tool orientations than the identification planner's (<= 25 deg from
    # vertical): effects at the tool point separate by the wrist's orientation
    poses = sample_poses(robot, n_candidate_poses, rng, tool, max_tilt_deg=MAX_TILT_DEG, max_yaw_deg=180.0)
    dirs = load_directions()
    cand_q = np.repeat(poses, len(dirs), axis=0)
    cand_f = np.tile(dirs, (len(poses), 1)) * force_N
    B, index, labels = _design(robot, cand_q, cand_f, tool, effects, c)
    p = B.shape[-1]
    S = np.concatenate([index[e] for e in effects])
    scale = np.sqrt(np.mean(np.einsum("mij,mij->j", B, B)))
    info0 = 1e-9 * scale**2 * np.eye(p)
    before = None
    if campaign is not None:
        Bc, _, _ = _design(robot, robot.joint_rad(campaign.q_deg), campaign.force_N, tool, effects, c)
        info0 = info0 + np.einsum("mip,miq->pq", Bc, Bc)
        before = np.linalg.pinv(info0)
    info = info0.copy()
    chosen = []
    for _ in range(n):
        Minv = np.linalg.pinv(info)
        K = np.einsum("pq,miq->mpi", Minv, B)  # M^-1 B^T, (m, p, 3)
        inner = np.eye(3) + np.einsum("mip,mpj->mij", B, K)
        KS = K[:, S, :]
        upd = np.einsum("msi,mij,msj->ms", KS, np.linalg.inv(inner), KS)
        score = np.sum(np.log(np.maximum(np.diag(Minv)[S][None] - upd, 1e-300)), axis=1)
        score[chosen] = np.inf
        best = int(np.argmin(score))
        chosen.append(best)
        info = info + B[best].T @ B[best]
    after = np.linalg.pinv(info)
    sigma_m = noise_mm * 1e-3
    unit_scale = np.array([lab[2] for e in effects for lab in labels[e]])

    def half(cov):
        return Z95 * sigma_m * np.sqrt(np.maximum(np.diag(cov)[S], 0.0)) * unit_scale

    ia, ib = index[effects[0]], index[effects[1]]
    chosen = np.array(chosen)
    return SeparationPlan(
        effects=tuple(effects), q_rad=cand_q[chosen], force_N=cand_f[chosen],
        pose_index=np.repeat(np.arange(len(poses)), len(dirs))[chosen],
        params=[(e, lab[0], lab[1]) for e in effects for lab in labels[e]],
        half_width_before=None if before is None else half(before), half_width_after=half(after),
        correlation_before=None if before is None else correlation(before, ia, ib),
        correlation_after=correlation(after, ia, ib))
