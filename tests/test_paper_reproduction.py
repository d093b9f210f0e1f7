"""The paper's figures from its stated imperfections (studies/paper_reproduction.py),
on the plant's own cutting law: the block test within +-25 % of the paper's 0.4 mm
and below 0.1 mm compensated, and the cylinder head read as the paper read it
(paint and touch: the same arm lowered 0.1 mm per pass along the same program).
Each cut runs in a few seconds; the full study (five mastering draws each) is in
docs/results.md."""

import copy
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "studies"))

import paper_reproduction as pr  # noqa: E402


def test_touch_reading_is_the_papers_reading():
    """The paper's own example: the highest point 0.35 mm above the commanded
    surface, the lowest 0.55 mm below: the tool touches at -0.3, cleans at
    0.6, a range of 0.9 mm; a paint film is touched earlier; the reading the
    study used before read one step wider."""
    depth = np.array([np.nan, -0.35, 0.2, 0.55, np.nan])
    assert pr.touch_reading(depth) == pytest.approx((-0.3, 0.6, 0.9))
    assert pr.touch_reading(depth, paint_mm=0.06) == pytest.approx((-0.4, 0.6, 1.0))
    assert pr.paint_and_touch_range({"max": 0.55, "min": -0.35}) == pytest.approx(1.0)
    # a pass that runs 0.08 mm deep touches a step early; one 0.08 mm high cleans a step late
    assert pr.touch_reading(depth, lambda k: 0.08 if k == -4 else (-0.08 if k == 6 else 0.0)) == \
        pytest.approx((-0.4, 0.7, 1.1))


def test_repeatability_spreads_the_reading_without_biasing_it():
    """Every pass off by its own height error (the paper's 0.05-0.1 mm
    repeatability, one value per pass): the range read scatters by about a
    step and its mean stays within half a step of the true range."""
    depth = np.linspace(-0.13, 0.51, 50)  # a true range of 0.64 mm
    mean, lo, hi = pr.repeatability_reading(depth, 0.1 / pr.RP_PER_SIGMA, seed=0)
    assert abs(mean - 0.64) < 0.05
    assert lo < mean < hi and hi - lo >= 0.1 - 1e-9


@pytest.fixture(scope="module")
def block(robot):
    sc = pr.paper_scenario("block", robot, 0)
    return pr.cut_stats(copy.deepcopy(sc), robot, False), pr.cut_stats(copy.deepcopy(sc), robot, True)


def test_the_block_is_the_papers_within_25_percent(block):
    """The paper: on average 0.4 mm cut more without compensation, a mean
    error below 0.1 mm with it (Section 5.1).  Mastering draw 0:
    +0.456 -> +0.013 mm (largest 0.090) on the plant's own law."""
    off, on = block
    assert 0.75 * 0.4 <= off["mean"] <= 1.25 * 0.4, off
    assert abs(on["mean"]) < 0.1, on
    assert max(abs(on["max"]), abs(on["min"])) < 0.12, on  # the largest error, entry included: 0.090 mm


def test_the_cylinder_head_read_as_the_paper_read_it(robot):
    """Mastering draw 0, read by paint and touch against the same program's
    unloaded pass (the paper's way): the uncompensated range reads 0.6 mm
    (the paper 0.9: -33 %, outside +-25 %), the compensated 0.1 mm (the
    paper 0.4).  The compensation takes off more than the paper's "more than
    50 %" and the compensated reading stays at most one step above the
    compensated range against the unloaded pass, so the arm's path accuracy
    (which the same program repeats) is not what is read."""
    sc = pr.paper_scenario("cylinder head", robot, 0)
    _, f_off = pr.cut_stats(copy.deepcopy(sc), robot, False, field=True)
    on, f_on = pr.cut_stats(copy.deepcopy(sc), robot, True, field=True)
    u = pr.unloaded_pass_mm(sc, robot)
    before, after = pr.touch_reading(f_off - u)[2], pr.touch_reading(f_on - u)[2]
    assert 0.5 <= before <= 0.8, before
    assert after <= 0.5 * before, (before, after)
    rel = f_on - u
    assert after <= np.nanmax(rel) - np.nanmin(rel) + 0.1 + 1e-9
    # against the commanded surface (an outside reference) the path accuracy counts: the range is wider
    assert on["pv"] > np.nanmax(rel) - np.nanmin(rel)


def test_the_worst_a_repeatability_can_read():
    """Every pass off by the full RP the adverse way widens the reading by
    at most 2 RP (and the steps): 0.64 mm true, RP 0.1 mm: 0.9 at most."""
    depth = np.linspace(-0.13, 0.51, 50)
    assert pr.worst_reading(depth, 0.1) == pytest.approx(0.9)  # touch at -0.2, clean at 0.7
    assert pr.worst_reading(depth, 0.0) == pytest.approx(pr.touch_reading(depth)[2])
