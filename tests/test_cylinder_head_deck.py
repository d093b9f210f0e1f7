"""The cylinder head's deck (studies/cylinder_head_deck.py,
diagrams/cylinder_head_deck.yaml): its geometry, the material each of its
side-by-side passes meets, and the finished face read from several passes.
Geometry only: no simulation."""

import math
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "studies"))

import cylinder_head_deck as deck  # noqa: E402
import paper_reproduction as pr  # noqa: E402


def _material(boxes, x, y):
    return bool(deck.material_mask(boxes, np.array([x]), y)[0])


def test_the_deck_has_its_chambers_and_bridges():
    """No material over a chamber's centre nor across the cutter-sized disc
    around it; material on the bridges between bores and beyond the bores;
    the boxes' area is the deck's less four bores within 2 %."""
    boxes = deck.deck_boxes_mm()
    centres = deck.bore_centres_mm()
    for c in centres:
        assert not _material(boxes, c, 0.0)
        assert not _material(boxes, c + 36.0, 5.0)  # inside the 42.4 mm radius
    for a, b in zip(centres[:-1], centres[1:]):
        assert _material(boxes, 0.5 * (a + b), 0.0)  # the 8.2 mm bridge
    assert _material(boxes, centres[0], 60.0) and _material(boxes, centres[0], -60.0)
    x0, x1 = deck.deck_x_mm()
    area = sum((b[1] - b[0]) * (b[3] - b[2]) for b in boxes)
    expected = (x1 - x0) * deck.WIDTH_MM - 4 * math.pi * (deck.BORE_MM / 2) ** 2
    assert area == pytest.approx(expected, rel=0.02)


def test_the_scenario_file_holds_the_generated_deck_and_the_first_pass():
    sc = pr.load_scenario(deck.DECK_YAML)
    assert np.allclose(sc.workpiece.boxes_mm, deck.deck_boxes_mm(), atol=1e-3)
    assert np.allclose(sc.path.waypoints_mm, deck.pass_waypoints_mm(0))


def test_each_pass_meets_only_what_the_earlier_passes_left():
    boxes = deck.deck_boxes_mm()
    first, second, third = (deck.pass_boxes_mm(boxes, k) for k in range(3))
    assert first == boxes
    assert min(b[2] for b in second) == pytest.approx(-50.0 + 37.5)
    assert min(b[2] for b in third) == pytest.approx(37.5)
    # the passes' stripes together cover the deck across its width
    assert deck.PASSES_Y_MM[0] - 37.5 <= -deck.WIDTH_MM / 2 and deck.PASSES_Y_MM[-1] + 37.5 >= deck.WIDTH_MM / 2


def _track(y_mm, z_mm, x0=1330.0, x1=1870.0, n=600):
    p = np.column_stack([np.linspace(x0, x1, n), np.full(n, y_mm), np.full(n, z_mm)]) / 1e3
    return p, np.tile([0.0, 0.0, 1.0], (n, 1))


def test_the_finished_face_is_the_lowest_pass_and_paint_and_touch_reads_its_steps():
    """Three flat passes, the middle one 0.3 mm deeper than the program and
    the others 0.1 mm: the face reads 0.1 mm deep under the outer passes'
    own stripes, 0.3 mm where the middle pass reached (its overlap with the
    others included: the lowest cut stays), nothing over the chambers; paint
    and touch reads the step: touch at 0.1, clean at 0.3."""
    boxes = deck.deck_boxes_mm()
    ref = [_track(y, 700.0) for y in deck.PASSES_Y_MM]
    cut = [_track(y, 700.0 - dz) for y, dz in zip(deck.PASSES_Y_MM, (0.1, 0.3, 0.1))]
    d = deck.deck_depth_mm(boxes, cut, ref)
    x, y = deck.grid_mm(boxes)
    assert np.nanmin(d) == pytest.approx(0.1) and np.nanmax(d) == pytest.approx(0.3)
    assert np.isnan(d[np.argmin(np.abs(y - 2.5)), np.argmin(np.abs(x - deck.bore_centres_mm()[1]))])
    assert np.nanmean(d[np.abs(y + 20.0) < 3.0]) == pytest.approx(0.3)  # the overlap of passes 1 and 2
    assert np.nanmean(d[y < -40.0]) == pytest.approx(0.1)
    assert pr.touch_reading(d) == pytest.approx((0.1, 0.3, 0.2))
    assert deck.pass_steps_mm(boxes, d) == pytest.approx([0.1, 0.3, 0.1], abs=1e-9)


def test_the_tilted_raw_deck_keeps_the_footprint_and_tilts_the_stock_within_the_tolerance():
    """The raw casting tilted within +-1.5 mm: the same material in x and y
    (the area and the mask unchanged), the top within +-1.5 mm of nominal,
    rising along x, each step at the tilt's height at its middle (so within
    half a step's rise of the plane everywhere); a flat deck unchanged."""
    boxes = deck.deck_boxes_mm()
    assert deck.raw_deck_boxes_mm(boxes, 0.0) == boxes
    tilt = deck.RAW_DECK_TOLERANCE_MM[1]
    raw = deck.raw_deck_boxes_mm(boxes, tilt)
    area = sum((b[1] - b[0]) * (b[3] - b[2]) for b in boxes)
    assert sum((b[1] - b[0]) * (b[3] - b[2]) for b in raw) == pytest.approx(area, rel=1e-9)
    x0, x1 = deck.deck_x_mm()
    xs = np.linspace(x0 + 0.1, x1 - 0.1, 500)
    for y in (-60.0, -20.0, 2.5, 40.0):
        assert np.array_equal(deck.material_mask(raw, xs, y), deck.material_mask(boxes, xs, y))
    tops = np.array([b[4] for b in raw])
    assert tops.min() >= deck.TOP_MM - tilt - 1e-9 and tops.max() <= deck.TOP_MM + tilt + 1e-9
    half_rise = tilt * deck.RAW_DECK_STEP_MM / (x1 - x0)
    for b in raw:
        plane = deck.TOP_MM + tilt * (2.0 * (b[0] + b[1]) / 2 - x0 - x1) / (x1 - x0)
        assert b[4] == pytest.approx(plane, abs=1e-3)
        assert b[1] - b[0] <= deck.RAW_DECK_STEP_MM + 1e-9
    first = [b[4] for b in raw if b[0] == pytest.approx(x0)]
    last = [b[4] for b in raw if b[1] == pytest.approx(x1)]
    assert max(first) < deck.TOP_MM - tilt + half_rise + 1e-3 and min(last) > deck.TOP_MM + tilt - half_rise - 1e-3


def test_the_raw_deck_tilt_outside_its_range_is_refused_before_any_cut(capsys):
    assert deck.main(["--raw-deck-tilt", "3"]) == 2
    err = capsys.readouterr().err
    assert "--raw-deck-tilt" in err and "[0, 2.5]" in err
