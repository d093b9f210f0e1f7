"""The floor's generating place (model/floor_generation.py): which tool
sample cut each point of a face, and the raise along the path that cancels
the floor's error where a transient dip of the tool was stamped over the
cutter's width."""

import numpy as np

from robstiff_drake.model.floor_generation import floor_raise_mm, lowest_faces
from robstiff_drake.model.surface import envelope_heights_at

R_M = 0.0375  # a 75 mm face mill


def _pass(dip_mm=0.1, at_m=0.05):
    """A level pass along x at z = 0 every 1 mm with one sample dipped
    ``dip_mm`` at x = ``at_m``; the scan points every 0.5 mm along its
    centre line."""
    x = np.arange(0.0, 0.2001, 0.001)
    p = np.column_stack([x, np.zeros_like(x), np.zeros_like(x)])
    k = int(np.argmin(np.abs(x - at_m)))
    p[k, 2] -= dip_mm / 1e3
    scan = np.arange(0.04, 0.16, 0.0005)
    return x, p, k, scan


def test_the_dip_generates_the_floor_over_the_cutter_width():
    x, p, k, scan = _pass()
    up = np.tile([0.0, 0.0, 1.0], (len(x), 1))
    h, who = lowest_faces(scan, np.zeros_like(scan), p, up, R_M)
    under = np.abs(scan - x[k]) < R_M - 1e-6
    assert np.all(who[under] == k) and np.allclose(h[under], -1e-4)  # stamped over the cutter's width
    assert np.all(who[~under] != k) and np.allclose(h[~under], 0.0)
    # the same heights as the scan's own envelope
    assert np.allclose(h, envelope_heights_at(scan, np.zeros_like(scan), p, up, R_M, np.inf))


def test_a_tilted_face_is_generated_by_its_lowest_edge():
    x, p, _, scan = _pass(dip_mm=0.0)
    n = np.tile([np.sin(1e-3), 0.0, np.cos(1e-3)], (len(x), 1))  # 1 mrad: the face lower ahead of the tool point
    h, who = lowest_faces(scan, np.zeros_like(scan), p, n, R_M)
    mid = (scan > 0.08) & (scan < 0.12)
    # each point is cut by the sample R behind it (the face's leading edge), R * 1 mrad deep
    assert np.allclose(x[who[mid]], scan[mid] - R_M, atol=1.01e-3)
    assert np.allclose(h[mid], -R_M * np.tan(1e-3), rtol=0.03)


def test_the_raise_is_the_mean_error_per_place_interpolated_and_held():
    raise_mm = floor_raise_mm([0.0, 1.0, 2.0, 3.0, 4.0], [1.0, 1.0, 3.0], [0.1, 0.3, -0.2])
    assert np.allclose(raise_mm, [0.2, 0.2, 0.0, -0.2, -0.2])
    assert np.all(floor_raise_mm([0.0, 1.0], [np.nan], [0.1]) == 0.0)


def test_raising_the_generating_places_levels_the_floor():
    x, p, _, scan = _pass(dip_mm=0.1)
    up = np.tile([0.0, 0.0, 1.0], (len(x), 1))
    y = np.zeros_like(scan)
    for _ in range(3):  # the fixed-point iteration the refinement runs on the model's twin
        h, who = lowest_faces(scan, y, p, up, R_M)
        err_mm = (0.0 - h) * 1e3
        p = p.copy()
        p[:, 2] += floor_raise_mm(x, x[who], err_mm) / 1e3
    h, _ = lowest_faces(scan, y, p, up, R_M)
    assert np.max(np.abs(h)) * 1e3 < 1e-3  # the 0.1 mm dip is gone from the floor
    before, _ = lowest_faces(scan, y, _pass(dip_mm=0.1)[1], up, R_M)
    assert np.max(np.abs(before)) * 1e3 > 0.099
