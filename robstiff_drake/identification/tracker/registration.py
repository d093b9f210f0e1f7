"""The instrument's frame against the robot's base: closed-form point-set
registration (Kabsch/Horn, SVD) of measured points to the nominal arm's,
alternated with a linear solve for the measured point on the flange, so
that a Gauss-Newton refinement starts near the answer whatever the
instrument's pose.  Plain numpy.

Model: m_i = R (o6_i + R6_i u) + t, with (R, t) the registration (base to
instrument), o6_i, R6_i the flange's position and rotation at row i and u
the measured point on the flange (flange frame).  With R fixed, (u, t) is a
linear least-squares problem; with u fixed, (R, t) is Kabsch's.
"""

import numpy as np

from robstiff_drake.errors import InputError

COLLINEAR_REL = 1e-3  # second singular value of the centred points below this fraction of the first: a line
ALTERNATIONS = 30


def kabsch(P, Q, w=None):
    """(R, t) minimising sum w |R P_i + t - Q_i|^2, R a proper rotation."""
    P, Q = np.asarray(P, float), np.asarray(Q, float)
    w = np.ones(len(P)) if w is None else np.asarray(w, float)
    cp = (w[:, None] * P).sum(0) / w.sum()
    cq = (w[:, None] * Q).sum(0) / w.sum()
    H = ((P - cp) * w[:, None]).T @ (Q - cq)
    U, _, Vt = np.linalg.svd(H)
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(Vt.T @ U.T))])
    R = Vt.T @ D @ U.T
    return R, cq - R @ cp


def check_geometry(path, points_mm):
    """InputError when the measured points cannot fix a frame: (nearly) all
    on one line (the rotation about it is free)."""
    p = np.asarray(points_mm, float)
    s = np.linalg.svd(p - p.mean(axis=0), compute_uv=False)
    if s[0] == 0 or s[1] < COLLINEAR_REL * s[0]:
        raise InputError(f"{path}: the measured points lie on one line (spread {s[1] / max(s[0], 1e-300):.2g} of "
                         "their length across it): the instrument's frame cannot be registered; measure poses "
                         "off that line")


def solve_tool_and_translation(R, o6, R6, m):
    """With the rotation R fixed: (u, t) by linear least squares."""
    n = len(m)
    A = np.zeros((3 * n, 6))
    A[:, :3] = np.einsum("ij,njk->nik", R, R6).reshape(-1, 3)
    A[:, 3:] = np.tile(np.eye(3), (n, 1))
    b = (m - o6 @ R.T).reshape(-1)
    x, *_ = np.linalg.lstsq(A, b, rcond=None)
    return x[:3], x[3:]


def register(o6, R6, m, tool_guess):
    """Registration (R, t) and measured point u (flange frame), all in the
    units of ``m``/``o6``: Kabsch on the nominal tool points at the guess,
    then alternate the linear (u, t) solve and Kabsch until they settle."""
    u = np.asarray(tool_guess, float)
    R, t = kabsch(o6 + np.einsum("nij,j->ni", R6, u), m)
    for _ in range(ALTERNATIONS):
        u_new, _ = solve_tool_and_translation(R, o6, R6, m)
        R, t = kabsch(o6 + np.einsum("nij,j->ni", R6, u_new), m)
        done = np.max(np.abs(u_new - u)) < 1e-9 * max(1.0, np.max(np.abs(u_new)))
        u = u_new
        if done:
            break
    return R, t, u
