"""Where a residual lives: how much of it each campaign variable explains.
Plain numpy.

For each variable (each joint angle, the load's direction, its magnitude,
the sign and size of each joint's torque, the measurement order, the pose)
the residual's three components are regressed on a small basis of it (with
an intercept); the strength is the adjusted R^2 (the share of the residual's
variance the variable explains beyond what chance gives a basis of that
size, 0 when none), and ``rms_mm`` the RMS of the explained part.
"""

import numpy as np

MIN_SPAN_DEG = 1.0


def _explained(resid, B):
    """(adjusted R^2, RMS of the fitted part) of resid (N, 3) on basis B (N, k) plus an intercept."""
    n = len(resid)
    X = np.column_stack([np.ones(n), B])
    k = X.shape[1] - 1
    if n - k - 1 <= 0:
        return 0.0, 0.0
    coef, *_ = np.linalg.lstsq(X, resid, rcond=None)
    fitted = X @ coef
    centred = resid - resid.mean(axis=0)
    ss_tot = float(np.sum(centred**2))
    ss_res = float(np.sum((resid - fitted) ** 2))
    if ss_tot == 0:
        return 0.0, 0.0
    adj = 1 - (ss_res / (n - k - 1)) / (ss_tot / (n - 1))
    part = fitted - resid.mean(axis=0)
    return max(float(adj), 0.0), float(np.sqrt(np.mean(part**2)))


def _scaled(x):
    span = np.ptp(x)
    return (x - x.mean()) / (span if span > 0 else 1.0)


def variables(ctx, rows):
    """name -> basis (len(rows), k) for the residual's regressions."""
    out = {}
    q = np.asarray(ctx.campaign.q_deg)[rows]  # the controller's angles, as in the file
    for j in range(6):
        if np.ptp(q[:, j]) >= MIN_SPAN_DEG:
            x = _scaled(q[:, j])
            out[f"q{j + 1}"] = np.column_stack([x, x**2])
    F = ctx.W[rows, :3]
    mag = np.linalg.norm(F, axis=1)
    out["load direction"] = F / np.maximum(mag, 1e-12)[:, None]
    if np.ptp(mag) > 0.01 * mag.max():
        x = _scaled(mag)
        out["load magnitude"] = np.column_stack([x, x**2])
    tau = ctx.tau[rows]
    for j in range(6):
        tm = np.max(np.abs(tau[:, j]))
        if tm > 0:
            out[f"torque of joint {j + 1} (sign and size)"] = np.column_stack([np.sign(tau[:, j]), tau[:, j] / tm])
    if ctx.seq is not None:
        x = _scaled(ctx.seq[rows])
        out["measurement order"] = np.column_stack([x, x**2])
    return out


def _explained_by_groups(resid, g):
    """(adjusted R^2, RMS of the fitted part) of resid (N, 3) on one indicator
    per group (the groups' means), without forming the (N, groups) basis."""
    n = len(resid)
    _, inv = np.unique(g, return_inverse=True)
    k = inv.max()  # groups - 1 (the intercept takes one)
    if k < 1 or n - k - 1 <= 0:
        return 0.0, 0.0
    sums = np.zeros((k + 1, 3))
    np.add.at(sums, inv, resid)
    means = sums / np.bincount(inv)[:, None]
    fitted = means[inv]
    centred = resid - resid.mean(axis=0)
    ss_tot = float(np.sum(centred**2))
    if ss_tot == 0:
        return 0.0, 0.0
    ss_res = float(np.sum((resid - fitted) ** 2))
    adj = 1 - (ss_res / (n - k - 1)) / (ss_tot / (n - 1))
    part = fitted - resid.mean(axis=0)
    return max(float(adj), 0.0), float(np.sqrt(np.mean(part**2)))


def residual_structure(ctx, resid_rows_m, rows):
    """[{variable, strength, rms_mm}] strongest first, for the residual (N, 3) m of ``rows``."""
    r = resid_rows_m[rows] * 1e3
    out = []
    for name, B in variables(ctx, rows).items():
        adj, rms = _explained(r, B)
        out.append({"variable": name, "strength": adj, "rms_mm": rms})
    g = ctx.groups[rows]
    if 1 < len(np.unique(g)) < len(rows):
        adj, rms = _explained_by_groups(r, g)
        out.append({"variable": "pose", "strength": adj, "rms_mm": rms})
    return sorted(out, key=lambda d: -d["strength"])
