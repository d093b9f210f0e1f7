"""Which place of the cutter cut each point of a face, and how a corrected
program should move that place: the surface-generating point of a face mill.
Plain numpy; no Drake.

A face mill's floor is the lowest its bottom face ever reached over a point
(model/surface.py): with a 75 mm cutter every point is covered for 75 mm of
travel, so a transient dip of the tool (the ringing after a plunge, the
arm's spring-back when the cutter leaves the plate) is stamped over the
cutter's width, and a flat correction of the tool point by its mean
deflection leaves those dips in the floor.  The floor is set at the few
places along the path where the tool was lowest; correcting the floor is
correcting those places.

``lowest_faces`` finds, for each scan point, the sample whose face was the
lowest there (the generating sample); ``floor_raise_mm`` turns the floor's
error at the points each generating place cut into a raise of the tool point
along the path, interpolated between the generating places (a smooth
function of arc length, spanning tens of millimetres between generating
places, so it does not ring the arm's modes itself).

Units: m unless named otherwise; errors in mm, positive where more was cut
than commanded (model/surface.py's sign)."""

import numpy as np

from robstiff_drake.model.surface import faces_over_points


def lowest_faces(x_m, y_m, p_m, n_up, radius_m):
    """(heights (n,) m, generating sample index (n,)): the lowest cutter
    face over each scan point (x_m[i], y_m[i]) among tool points p (N, 3)
    with spindle axes n (N, 3), and which sample it was; inf and -1 where no
    face covered the point."""
    h = np.full(np.shape(x_m), np.inf)
    who = np.full(np.shape(x_m), -1, dtype=int)
    for i, idx, z in faces_over_points(x_m, y_m, p_m, n_up, radius_m):
        lower = z < h[idx]
        h[idx[lower]] = z[lower]
        who[idx[lower]] = i
    return h, who


def floor_raise_mm(s_grid_m, s_generating_m, error_mm):
    """The raise of the tool point (mm, (len(s_grid),)) along the path's
    arc length ``s_grid_m`` that cancels the floor's error: at each
    generating place (arc length ``s_generating_m``, one per scan point, the
    place of the tool when it cut that point) the mean error of the points
    it cut (``error_mm``, + = cut too deep, so the tool goes up), linearly
    interpolated between the places and held beyond the first and last."""
    s = np.asarray(s_generating_m, dtype=float)
    e = np.asarray(error_mm, dtype=float)
    ok = np.isfinite(s) & np.isfinite(e)
    if not np.any(ok):
        return np.zeros(np.shape(s_grid_m))
    places, inverse = np.unique(np.round(s[ok], 6), return_inverse=True)
    mean = np.bincount(inverse, weights=e[ok]) / np.bincount(inverse)
    return np.interp(np.asarray(s_grid_m, dtype=float), places, mean)
