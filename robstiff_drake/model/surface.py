"""The machined surface as a laser line scan sees it (the paper's Fig. 6): the
envelope of the cutter's bottom face over the pass.  Plain numpy; no Drake.

The cutter's bottom face is a disc of radius R around the tool point p with
unit axis n (pointing up the spindle).  At a scan point (x, y) covered by the
disc, the face lies at height z = p_z - (n_x (x - p_x) + n_y (y - p_y)) / n_z.
The surface left behind is the lowest face height that ever covered the
point, or the material's original top where the cutter never went below it.

Surface error = commanded height - machined height, positive where more
material was removed than commanded ("cut more", the paper's sign).  The
commanded height is the same envelope of the reference (undeflected) path.
"""

import numpy as np


def envelope_heights(x_grid_m, y_line_m, p_m, n_up, radius_m, top_m):
    """Height (m) of the surface along the scan line y = y_line_m.

    p_m (N, 3) tool points, n_up (N, 3) unit spindle axes (pointing up),
    top_m: height of the uncut material (scalar or per x)."""
    x = np.asarray(x_grid_m, dtype=float)
    h = np.full(x.shape, np.inf)
    dy = y_line_m - p_m[:, 1]
    covered = np.abs(dy) < radius_m
    half = np.sqrt(np.maximum(radius_m**2 - dy**2, 0.0))
    for i in np.flatnonzero(covered):
        lo = np.searchsorted(x, p_m[i, 0] - half[i], side="left")
        hi = np.searchsorted(x, p_m[i, 0] + half[i], side="right")
        if hi <= lo:
            continue
        n = n_up[i]
        z = p_m[i, 2] - (n[0] * (x[lo:hi] - p_m[i, 0]) + n[1] * dy[i]) / n[2]
        np.minimum(h[lo:hi], z, out=h[lo:hi])
    return np.minimum(h, top_m)


def surface_error_stats(err_m):
    """mean, rms, max_abs, pv of a surface-error profile, in mm."""
    e = np.asarray(err_m, dtype=float) * 1e3
    e = e[np.isfinite(e)]
    return {
        "mean": float(e.mean()),
        "rms": float(np.sqrt(np.mean(e**2))),
        "max_abs": float(np.max(np.abs(e))),
        "pv": float(e.max() - e.min()),
    }


def faces_over_points(x_m, y_m, p_m, n_up, radius_m):
    """For each sample i of tool points p (N, 3) and spindle axes n (N, 3)
    whose cutter face covers some of the points (x_m[j], y_m[j]): (i, the
    indices j it covers, the face's heights there (m)).  A generator."""
    from scipy.spatial import cKDTree

    x = np.asarray(x_m, dtype=float)
    y = np.asarray(y_m, dtype=float)
    if x.size == 0:
        return
    tree = cKDTree(np.column_stack([x, y]))
    hits = tree.query_ball_point(p_m[:, :2], radius_m * (1 - 1e-12))
    for i, idx in enumerate(hits):
        if not idx:
            continue
        idx = np.asarray(idx)
        n = n_up[i]
        yield i, idx, p_m[i, 2] - (n[0] * (x[idx] - p_m[i, 0]) + n[1] * (y[idx] - p_m[i, 1])) / n[2]


def envelope_heights_at(x_m, y_m, p_m, n_up, radius_m, top_m):
    """Height (m) of the surface at scan points (x_m[i], y_m[i]) anywhere
    (not only along a line of constant y): the lowest cutter face that
    covered each point, or ``top_m`` (scalar or per point) where none did.
    Same geometry as ``envelope_heights``."""
    h = np.full(np.shape(x_m), np.inf)
    for _, idx, z in faces_over_points(x_m, y_m, p_m, n_up, radius_m):
        h[idx] = np.minimum(h[idx], z)
    return np.minimum(h, top_m)
