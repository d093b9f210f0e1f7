"""Inverse kinematics along a whole path at once: the joint references of
a sampled tool path, the same answers as model/ik.solve_for called sample
by sample with each solution as the next one's reference (to round-off),
at a fraction of the cost.

Plain numpy.  Angles in radians (the model's joint angles), lengths metres.

How.  model/ik's closed form does not depend on the reference except in
the choice among its candidates (the two wrist branches), in wrapping each
joint near the reference, and at the wrist singularity (axes 4 and 6
aligned, where axis 4 stays at its reference).  So the closed form, its
Newton polish and the Jacobian's conditioning are computed for all samples
in one vectorised pass (the same formulas on arrays of poses), and only the
choice walks the path in order: each sample's two candidates wrapped near
the previous answer, the nearer taken, the working ranges checked for all
answers at once.  Where that shortcut could differ from the sample-by-sample
solver (a wrist singularity; the nearer candidate outside the working
ranges; a pose out of reach) that sample is solved by model/ik.solve_for
itself and the walk goes on from its answer.  ``joint_references`` adds
model/path.PlannedPath.joint_references' singularity check, vectorised.  An arm without the closed
form's layout is solved sample by sample (model/ik's damped least squares,
warm-started from the previous answer).
"""

import math

import numpy as np

from robstiff_drake.model import ik
from robstiff_drake.model import kinematics as kin


def _links(dh, i, theta):
    """Standard-DH link transforms i (0-based) at DH angles theta (N,): (N, 4, 4)."""
    ct, st = np.cos(theta), np.sin(theta)
    ca, sa = math.cos(dh.alpha_rad[i]), math.sin(dh.alpha_rad[i])
    A = np.zeros(theta.shape + (4, 4))
    A[:, 0, 0], A[:, 0, 1], A[:, 0, 2], A[:, 0, 3] = ct, -st * ca, st * sa, dh.a_m[i] * ct
    A[:, 1, 0], A[:, 1, 1], A[:, 1, 2], A[:, 1, 3] = st, ct * ca, -ct * sa, dh.a_m[i] * st
    A[:, 2, 1], A[:, 2, 2], A[:, 2, 3], A[:, 3, 3] = sa, ca, dh.d_m[i], 1.0
    return A


def _inv_apply(T, p):
    """T^-1 p for rigid transforms T (N, 4, 4) and points p (N, 3)."""
    return np.einsum("nji,nj->ni", T[:, :3, :3], p - T[:, :3, 3])


def _arm(dh, pc):
    """model/ik._arm for wrist centres pc (N, 3): theta1..3 (N, 3), NaN where out of reach."""
    n = len(pc)
    base = np.eye(4) if dh.base is None else np.asarray(dh.base, dtype=float)
    x, y, z = np.linalg.solve(base, np.column_stack([pc, np.ones(n)]).T)[:3]
    d, a, al = dh.d_m, dh.a_m, dh.alpha_rad
    e = d[1] + d[2] + np.cos(al[2]) * d[3]
    k = (e - np.cos(al[0]) * (z - d[0])) / np.sin(al[0])
    r = np.hypot(x, y)
    reach = np.abs(k) <= r + 1e-12
    phi = np.arctan2(y, x)
    with np.errstate(divide="ignore", invalid="ignore"):
        shift = np.where(r > 1e-12, np.arcsin(np.clip(k / np.where(r > 0, r, 1.0), -1.0, 1.0)), 0.0)
    w = np.array([a[2], -np.sin(al[2]) * d[3]])
    L = np.hypot(*w)
    phi_w = np.arctan2(w[1], w[0])
    best_score = np.full(n, -1)
    best = np.full((n, 3), np.nan)
    bxy = base[:2, 3]
    for th1 in (phi + shift, phi + np.pi - shift):
        T1 = base @ _links(dh, 0, th1)
        v = _inv_apply(T1, pc)
        c = (v[:, 0] ** 2 + v[:, 1] ** 2 - a[1] ** 2 - L ** 2) / (2 * a[1] * L)
        ok = np.abs(c) <= 1.0
        shoulder = T1[:, :3, 3]
        to_pc = pc[:, :2] - bxy
        if abs(a[0]) > 1e-9:
            front = np.einsum("ni,ni->n", shoulder[:, :2] - bxy, to_pc) >= 0
        else:
            front = np.einsum("ni,ni->n", T1[:, :2, 0], to_pc) >= 0
        for sign in (1.0, -1.0):
            beta = sign * np.arccos(np.clip(c, -1.0, 1.0))
            th3 = beta - phi_w
            th2 = np.arctan2(v[:, 1], v[:, 0]) - np.arctan2(L * np.sin(beta), a[1] + L * np.cos(beta))
            elbow = (T1 @ _links(dh, 1, th2))[:, :3, 3]
            s2w, s2e = pc - shoulder, elbow - shoulder
            nrm = s2w / np.maximum(np.linalg.norm(s2w, axis=1), 1e-300)[:, None]
            up = (s2e - np.einsum("ni,ni->n", s2e, nrm)[:, None] * nrm)[:, 2] >= 0
            score = np.where(ok, 2 * front + up, -1)
            better = score > best_score  # strictly: the first of equal scores stays, as in model/ik._arm
            best_score = np.where(better, score, best_score)
            best[better] = np.column_stack([th1, th2, th3])[better]
    best[~reach] = np.nan
    return best


def closed_form_candidates(dh, T, tool):
    """The closed form's two wrist branches for poses T (N, 4, 4): (N, 2, 6)
    rad (not wrapped), and a mask (N,) of the samples it cannot settle
    without the reference (out of reach, or axes 4 and 6 aligned)."""
    home = dh.home_rad
    R6 = T[:, :3, :3]
    a6, d6, al6 = dh.a_m[5], dh.d_m[5], dh.alpha_rad[5]
    p6 = T[:, :3, 3] - R6 @ tool
    pc = p6 - R6 @ np.array([a6, d6 * np.sin(al6), d6 * np.cos(al6)])
    theta123 = _arm(dh, pc)
    hard = np.isnan(theta123[:, 0])
    theta123[hard] = 0.0
    q123 = theta123 - home[:3]
    R3 = kin.frames(dh, np.column_stack([q123, np.zeros((len(T), 3))]))[:, 3, :3, :3]
    al4, al5 = dh.alpha_rad[3], dh.alpha_rad[4]
    s4, s5 = np.sign(np.sin(al4)), np.sign(np.sin(al5))
    z6 = R6 @ np.array([0.0, np.sin(al6), np.cos(al6)])
    nz = np.cross(R3[:, :, 2], z6)
    nn = np.linalg.norm(nz, axis=1)
    hard |= nn < 1e-12
    nz = nz / np.where(nn > 0, nn, 1.0)[:, None]
    L6T = np.swapaxes(_links(dh, 5, np.zeros(len(T)))[:, :3, :3], 1, 2)
    out = np.empty((len(T), 2, 6))
    for b, branch in enumerate((1.0, -1.0)):
        u = np.einsum("nji,nj->ni", R3, branch * nz)
        th4 = np.arctan2(s4 * u[:, 0], -s4 * u[:, 1])
        R4 = R3 @ _links(dh, 3, th4)[:, :3, :3]
        w = np.einsum("nji,nj->ni", R4, z6)
        th5 = np.arctan2(s5 * w[:, 0], -s5 * w[:, 1])
        R5 = R4 @ _links(dh, 4, th5)[:, :3, :3]
        M = np.swapaxes(R5, 1, 2) @ R6 @ L6T
        th6 = np.arctan2(M[:, 1, 0], M[:, 0, 0])
        out[:, b, :3] = q123
        out[:, b, 3:] = np.column_stack([th4, th5, th6]) - home[3:]
    return out, hard


def polish(dh, q, T, tool, tol_m=1e-12, max_iter=10):
    """model/ik._polish for many candidates at once: q (M, 6), T (M, 4, 4)."""
    q = q.copy()
    todo = np.arange(len(q))
    for _ in range(max_iter):
        Tq = kin.tool_pose(dh, q[todo], tool)
        Tt = T[todo]
        dp = Tt[:, :3, 3] - Tq[:, :3, 3]
        Re = Tt[:, :3, :3] @ np.swapaxes(Tq[:, :3, :3], 1, 2)
        dphi = 0.5 * np.stack([Re[:, 2, 1] - Re[:, 1, 2], Re[:, 0, 2] - Re[:, 2, 0], Re[:, 1, 0] - Re[:, 0, 1]], 1)
        e = np.concatenate([dp, dphi], axis=1)
        left = np.max(np.abs(e), axis=1) >= tol_m
        todo, e = todo[left], e[left]
        if not len(todo):
            break
        J = kin.jacobian(dh, q[todo], tool)
        try:
            q[todo] += np.linalg.solve(J, e[:, :, None])[:, :, 0]
        except np.linalg.LinAlgError:  # a singular Jacobian somewhere: each row as model/ik does it
            q[todo] += np.array([np.linalg.lstsq(Ji, ei, rcond=None)[0] for Ji, ei in zip(J, e)])
    return q


def _wrap(q, ref):
    two_pi = 2 * math.pi
    return [r + (a - r + math.pi) % two_pi - math.pi for a, r in zip(q, ref)]


def _violations(robot, q, tol_deg=1e-7):
    """Mask (N,) of rows of q (N, 6) rad outside the working ranges (RobotModel.limit_violation's test)."""
    c = robot.controller_deg(q)
    lo, hi = np.rad2deg(robot.q_lower_rad) - tol_deg, np.rad2deg(robot.q_upper_rad) + tol_deg
    return ~np.all((c >= lo) & (c <= hi), axis=1)


class PathIKError(ik.IKError):
    """A sample of the path cannot be solved: ``index`` says which."""

    def __init__(self, message, index):
        super().__init__(message)
        self.index = index


def solve_path(robot, poses, tool_m, q_start_rad=None):
    """Joint angles (N, 6) rad for tool poses (N, 4, 4), as
    ``ik.solve_for(robot, poses[k], tool_m, q_ref_rad=q[k-1])`` in turn
    (``q_start_rad`` the first one's reference).  Raises PathIKError (its
    ``index`` the sample) where that raises IKError."""
    T = np.asarray(poses, dtype=float)
    tool = np.zeros(3) if tool_m is None else np.asarray(tool_m, dtype=float)
    n = len(T)
    out = np.empty((n, 6))

    def single(k, ref):
        try:
            return ik.solve_for(robot, T[k], tool, q_ref_rad=ref)
        except ik.IKError as e:
            raise PathIKError(str(e), k) from None

    ref = None if q_start_rad is None else np.asarray(q_start_rad, dtype=float)
    if ik.closed_form_reason(robot.dh) is not None or n == 0:
        for k in range(n):
            out[k] = ref = single(k, ref)
        return out
    cand, hard = closed_form_candidates(robot.dh, T, tool)
    easy = ~hard
    cand[easy] = polish(robot.dh, cand[easy].reshape(-1, 6), np.repeat(T[easy], 2, axis=0), tool).reshape(-1, 2, 6)
    rows = cand.tolist()
    hard = hard.tolist()
    k = 0
    while k < n:
        # the walk: each sample's branches wrapped near the previous answer, the nearer taken
        start = k
        prev = [0.0] * 6 if ref is None else list(ref)
        while k < n and not hard[k]:
            a, b = _wrap(rows[k][0], prev), _wrap(rows[k][1], prev)
            da = sum((x - p) ** 2 for x, p in zip(a, prev))
            db = sum((x - p) ** 2 for x, p in zip(b, prev))
            prev = a if da <= db else b
            out[k] = prev
            k += 1
        bad = np.flatnonzero(_violations(robot, out[start:k]))
        if len(bad):  # the nearer branch outside the ranges: that sample as model/ik does it, then on
            k = start + int(bad[0])
        if k < n:
            out[k] = single(k, out[k - 1] if k > 0 else ref)
            ref = out[k]
            k += 1
        else:
            ref = out[k - 1]
    return out


def tool_down_poses(points_m, yaw_rad):
    """model/ik.tool_down_pose for points (N, 3): (N, 4, 4)."""
    T = np.broadcast_to(ik.tool_down_pose([0.0, 0.0, 0.0], yaw_rad), (len(points_m), 4, 4)).copy()
    T[:, :3, 3] = points_m
    return T


def sample_times(path, dt_s):
    """The reference's times (s): every dt_s from 0 to the path's end."""
    return np.arange(0.0, path.duration_s + 0.5 * dt_s, dt_s)


def joint_references(path, robot, tool_m, dt_s, q_start=None, points_m=None):
    """model/path.PlannedPath.joint_references (the same answers, the same
    PathError at the same first sample), vectorised: (times (N,), q (N, 6)
    rad) along the path every dt_s.  ``points_m``: the tool points at
    ``sample_times`` when the caller has them already."""
    from robstiff_drake.model.path import MIN_JACOBIAN_CONDITION, PathError
    from robstiff_drake.model.stiffness import describe_singularity, singular_joints

    ts = sample_times(path, dt_s)
    p = path.positions(ts) if points_m is None else np.asarray(points_m, dtype=float)
    tool = np.zeros(3) if tool_m is None else np.asarray(tool_m, dtype=float)

    def where(k):
        return f"path point at t = {ts[k]:.3f} s, tool point ({p[k, 0] * 1e3:.1f}, {p[k, 1] * 1e3:.1f}, " \
               f"{p[k, 2] * 1e3:.1f}) mm"

    failed = None
    try:
        qs = solve_path(robot, tool_down_poses(p, path.yaw), tool, q_start)
        n = len(ts)
    except PathIKError as e:
        failed, n = e, e.index
        qs = None
    if n:
        if qs is None:  # the samples before the one out of reach, for the singularity check
            qs = solve_path(robot, tool_down_poses(p[:n], path.yaw), tool, q_start)
        J = kin.jacobian(robot.dh, qs[:n], tool)
        s = np.linalg.svd(J, compute_uv=False)
        sing = np.flatnonzero(s[:, -1] < MIN_JACOBIAN_CONDITION * s[:, 0])
        if len(sing):
            k = int(sing[0])
            joints = singular_joints(J[k], rel_tol=MIN_JACOBIAN_CONDITION) or (5,)
            raise PathError(f"{where(k)} passes through a singularity ({describe_singularity(joints)})",
                            where=path.tag_at(ts[k]))
    if failed is not None:
        raise PathError(f"{where(failed.index)}: {failed}", where=path.tag_at(ts[failed.index]))
    return ts, qs
