"""The mechanistic force model alone (plain numpy): the revolution average
is the time mean of the tooth-resolved force, the engagement geometry."""

import numpy as np
import pytest

from robstiff_drake.model.milling import Cutter, CuttingCoefficients, MillingForceModel, Workpiece

CUTTER = Cutter(0.075, 6, 3600.0)
COEFFS = CuttingCoefficients(631 * 2.2, 99 * 2.2, 273 * 0.72, 13 * 2.2, 10 * 2.2, 2.8 * 0.72)
MODEL = MillingForceModel(CUTTER, COEFFS, 0.02)


def time_mean(tool_point, u, workpiece, n=20000):
    """The tooth-resolved wrench averaged over one revolution, by brute force."""
    t = (np.arange(n) + 0.5) / n * (60.0 / CUTTER.spindle_rpm)
    return MODEL.tooth_wrench(t, tool_point, u, workpiece) / n


@pytest.mark.parametrize("seed", range(4))
def test_revolution_average_is_the_time_mean_of_the_tooth_force(seed):
    """Random cutter positions and feed directions over overlapping boxes of
    different heights: the closed-form average agrees with the brute-force
    mean to 0.2 % of the force (the brute force's own angle step)."""
    rng = np.random.default_rng(seed)
    wp = Workpiece.from_boxes([[0.00, 0.10, -0.02, 0.03, 0.003],
                               [0.04, 0.07, 0.00, 0.06, 0.005],
                               [0.09, 0.15, -0.05, 0.00, 0.002]])
    engaged = 0
    for _ in range(15):
        p = np.array([rng.uniform(-0.03, 0.18), rng.uniform(-0.07, 0.08), rng.uniform(-0.001, 0.004)])
        a = rng.uniform(0, 2 * np.pi)
        u = (np.cos(a), np.sin(a))
        exact, brute = MODEL.average_wrench(p, u, wp), time_mean(p, u, wp)
        scale = max(1.0, np.abs(brute[:3]).max())
        np.testing.assert_allclose(exact[:3], brute[:3], atol=2e-3 * scale)
        np.testing.assert_allclose(exact[3:], brute[3:], atol=2e-3 * scale * CUTTER.radius_m)
        engaged += np.abs(brute[:3]).max() > 10
    assert engaged >= 5  # most positions cut


def test_full_slot_engagement_and_direction():
    """A slot through a wide block: the whole leading half is engaged (pi), at
    the full depth; the feed force opposes the feed, the cross-feed force of
    a clockwise (M03) cutter points to the left of the feed (+v: at the
    front the tooth moves to the right, the chip pushes the tool back to the
    left), and the cutting torque resists the spindle's clockwise turn."""
    wp = Workpiece.from_boxes([[-1.0, 1.0, -1.0, 1.0, 0.003]])
    arc, depth = MODEL.engagement([0.0, 0.0, 0.0], (1.0, 0.0), wp)
    assert arc == pytest.approx(np.pi)
    assert depth == pytest.approx(0.003)
    w = MODEL.average_wrench([0.0, 0.0, 0.0], (1.0, 0.0), wp)
    assert w[0] < -100 and w[2] > 0  # against the feed; the tool pushed up, away from the part
    assert w[1] > 100 and w[5] > 0
    # the same cut fed along +y: the wrench turns with the feed
    w_y = MODEL.average_wrench([0.0, 0.0, 0.0], (0.0, 1.0), wp)
    np.testing.assert_allclose(w_y[:3], [-w[1], w[0], w[2]], atol=1e-9)
    # out of the material: nothing
    assert not MODEL.average_wrench([0.0, 0.0, 0.004], (1.0, 0.0), wp).any()
    assert MODEL.engagement([0.0, 0.0, 0.004], (1.0, 0.0), wp) == (0.0, 0.0)


WP3 = Workpiece.from_boxes([[0.00, 0.10, -0.02, 0.03, 0.003],
                            [0.04, 0.07, 0.00, 0.06, 0.005],
                            [0.09, 0.15, -0.05, 0.00, 0.002]])


def test_tip_depths_box_by_box_and_all_at_once_agree_with_a_loop_over_tips():
    """The depth of cut under each tip, both ways tip_depths computes it,
    against a plain loop over tips and boxes (the highest top above the
    cutter bottom among the boxes holding the tip, else 0)."""
    import robstiff_drake.model.milling as milling

    rng = np.random.default_rng(3)
    x, y = rng.uniform(-0.03, 0.18, 400), rng.uniform(-0.07, 0.08, 400)
    for z_b in (-0.001, 0.0025, 0.004, 0.006):
        want = np.array([max([top - z_b for x0, x1, y0, y1, top in WP3.boxes
                              if x0 <= xi <= x1 and y0 <= yi <= y1 and top > z_b], default=0.0)
                         for xi, yi in zip(x, y)])
        for few in (8, 0):
            old, milling.FEW_BOXES = milling.FEW_BOXES, few
            try:
                np.testing.assert_array_equal(milling.tip_depths(x, y, z_b, WP3), want)
            finally:
                milling.FEW_BOXES = old
        assert np.any(want > 0) or z_b > 0.005


@pytest.mark.parametrize("few_boxes", [8, 0])
def test_the_vectorised_tooth_wrenches_are_the_tooth_wrench_at_each_instant(monkeypatch, few_boxes):
    """tooth_wrenches (the simulation's, summed in the average's basis, box
    by box or all boxes at once) against tooth_wrench (each tooth's force
    and lever, summed) at each instant: overlapping boxes of different
    heights, random positions, feed directions and feeds, a zero feed among
    them (no chip: no force), to round-off."""
    import robstiff_drake.model.milling as milling

    monkeypatch.setattr(milling, "FEW_BOXES", few_boxes)
    rng = np.random.default_rng(7)
    wp = WP3
    engaged = 0
    for k in range(60):
        t = rng.uniform(0, 1) + np.arange(17) * 1e-4
        p = np.array([rng.uniform(-0.03, 0.18), rng.uniform(-0.07, 0.08), rng.uniform(-0.001, 0.004)])
        a = rng.uniform(0, 2 * np.pi)
        u = (np.cos(a), np.sin(a))
        feed = 0.0 if k % 10 == 0 else rng.uniform(0.005, 0.05)
        rows = MODEL.tooth_wrenches(t, p, u, wp, 0.3, feed)
        each = np.array([MODEL.tooth_wrench(tk, p, u, wp, 0.3, feed) for tk in t])
        np.testing.assert_allclose(rows, each, rtol=0, atol=1e-12 * max(1.0, np.abs(each).max()))
        if feed == 0.0:
            assert not np.any(rows)
        engaged += np.abs(each[:, :3]).max() > 10
    assert engaged >= 20
