"""diagrams/chatter_check.py: the paper's block at the paper's forces
chatters (studies/chip_coupling_stability.py: +36.7 1/s at 68.6 Hz, arm
modes 4 and 5, stable up to 1.74 mm at x = 1600 mm) and would be stable
with those modes damped about 25 % (diagrams/chatter_damping.py), the
block at its own forces does not chatter (-1.77 1/s fully engaged, -1.08
entering), nor at a 1 mm/s crawl (its chip below the law's validity), the
KR 240's block entering the cut is at the edge (a pose of less than the
largest force), and the check stays silent where it does not apply."""

import copy

import numpy as np
import pytest

from robstiff_drake.diagrams.chatter_check import (MAX_POSES, MIN_SPACING, chatter_check, chatter_warning,
                                                   poses_to_check)
from robstiff_drake.diagrams.chatter_damping import MAX_RATIO
from robstiff_drake.diagrams.path_references import planned_path
from robstiff_drake.diagrams.scenario import load_scenario, scenario_robot
from robstiff_drake.diagrams.scenario_models import plant_cutting_setup
from robstiff_drake.paths import scenario_file


@pytest.fixture(scope="module")
def block():
    sc = load_scenario(scenario_file("block_milling"))
    return sc, scenario_robot(sc)


@pytest.fixture(scope="module")
def paper_block():
    # the paper's block with the paper's forces: the study's paper_reproduction scenario differs from it only in
    # what the linear arm does not see (the gears' play, the controller's mode, the plant step, the compensator's
    # model)
    sc = load_scenario(scenario_file("block_milling_paper_forces"))
    return sc, scenario_robot(sc)


def test_the_paper_block_at_the_papers_forces_is_flagged(paper_block):
    sc, robot = paper_block
    c = chatter_check(sc, robot)
    assert c is not None and not c["stable"]
    assert c["growth_per_s"] == pytest.approx(36.7, abs=1.5)  # the study: +36.66 at x = 1600 mm, +37.01 at 1634
    assert c["frequency_hz"] == pytest.approx(68.6, abs=1.0)
    assert {m["mode"] for m in c["modes"]} == {4, 5}
    assert c["modes"][0]["drives_closed_hz"] == pytest.approx(39.0, abs=1.0)
    assert 1525.0 <= c["x_mm"] <= 1640.0  # fully engaged, the cutter's front still on the block
    assert c["depth_mm"] == pytest.approx(3.0, abs=1e-6)
    assert c["largest_stable_depth_mm"] == pytest.approx(1.74, abs=0.1)  # the study's bisection: 1.74 mm
    assert c["damping_ratio_assumed"] == [pytest.approx(0.05)] * 6
    line = chatter_warning(c)
    assert line.startswith("chatter: ")
    for part in ("+37.", "68.6 Hz", "arm modes 4", "leaves the regenerative chip out", "5 %", "modal test",
                 "1.7", "faster spindle", "stable if arm modes 4-5 were damped at least 24.9 %"):
        assert part in line
    # the damping that decides it: modes 4-5 are damped 10 % by the drives and the gears, 24.9 % would be stable
    d = c["damping_to_stabilise"]
    assert d["modes"] == [4, 5] and d["ratio_now"] == [pytest.approx(0.104, abs=0.002), pytest.approx(0.101, abs=0.002)]
    assert d["on_these_modes"] == pytest.approx(0.249, abs=0.003)
    assert d["realised_on_these_modes"] == [pytest.approx(0.249, abs=0.003)] * 2
    assert d["on_every_mode"] == pytest.approx(0.246, abs=0.003)
    assert d["searched_up_to"] == MAX_RATIO and d["stated_on"] == "drives_closed"


def test_the_block_at_its_own_forces_is_not_flagged(block):
    sc, robot = block
    c = chatter_check(sc, robot)
    assert c is not None and c["stable"]
    # the study: -1.77 1/s at x = 1600 mm; the least stable pose is the entry (x = 1508 mm, -1.08 1/s)
    assert c["growth_per_s"] == pytest.approx(-1.08, abs=0.3)
    assert c["modes"] is None and c["largest_stable_depth_mm"] is None and c["damping_to_stabilise"] is None
    assert chatter_warning(c) is None


def test_a_crawling_feed_is_not_linearised_below_the_laws_validity(block):
    """At 1 mm/s the feed per tooth is 2.8 um, below the plant law's 10 um
    edge ramp (the minimum chip of its edge): linearised there, the ramp's
    slope (edge coefficient / 10 um, three times the cutting slope) and the
    force's turn with a chip of 2.8 um made a root of +0.97 1/s at 124.5 Hz,
    an artefact (without the ramp: -2.4 1/s); the law is linearised at its
    validity's edge instead (chatter_check.MIN_CHIP_M), stable as at 2 to
    20 mm/s (docs/results.md: the slow feed)."""
    sc, robot = block
    slow = copy.deepcopy(sc)
    slow.path.feed_mm_per_s = 1.0
    c = chatter_check(slow, robot)
    assert c["feed_mm_per_s"] == pytest.approx(1.0)
    assert c["stable"] and c["growth_per_s"] < -1.0, c
    assert chatter_warning(c) is None


def test_a_pose_of_less_than_the_largest_force_is_checked():
    """The KR 240's block: at full engagement (the largest force) stable
    (-4.31 1/s), entering the cut (x = 1814 mm, 179 N of 188) at the edge:
    +1.59 1/s at 55.3 Hz on its modes 4 and 5 (studies/chatter_check_scenarios.py
    --dense), which the 3 poses of the largest force missed."""
    sc = load_scenario(scenario_file("block_milling_kr240_r2900"))
    robot = scenario_robot(sc)
    c = chatter_check(sc, robot)
    assert not c["stable"] and c["growth_per_s"] == pytest.approx(1.59, abs=0.3)
    assert c["frequency_hz"] == pytest.approx(55.3, abs=1.0)
    assert 1800.0 <= c["x_mm"] <= 1825.0
    assert "at the edge of stability" in chatter_warning(c)
    few = chatter_check(sc, robot, max_poses=3, min_spacing=0.2)
    assert few["stable"] and few["growth_per_s"] == pytest.approx(-4.31, abs=0.3)


def test_less_damping_is_flagged_more(block):
    """The check follows the scenario's damping assumption: the block at
    its own forces with 0.5 % modal damping is no longer stable."""
    sc, robot = block
    sc = copy.deepcopy(sc)
    sc.plant.modal_damping_ratio = 0.005
    c = chatter_check(sc, robot)
    assert c["damping_ratio_assumed"] == [pytest.approx(0.005)] * 6
    assert c["growth_per_s"] > chatter_check(block[0], robot)["growth_per_s"]


def test_not_checked_without_an_averaged_cut(block):
    sc, robot = block
    tooth = copy.deepcopy(sc)
    tooth.cutting.mode = "tooth"
    assert chatter_check(tooth, robot) is None
    away = copy.deepcopy(sc)
    away.workpiece.boxes_mm = [[0.0, 10.0, 500.0, 510.0, 0.0]]  # far from the path: no cut
    assert chatter_check(away, robot) is None
    assert chatter_warning(None) is None


def test_the_poses_are_spread_and_of_the_largest_force(paper_block):
    sc, robot = paper_block
    path, _, _ = planned_path(sc, robot, robot.tool_point())
    _, law, wp = plant_cutting_setup(sc)
    poses = poses_to_check(path, law, wp, max_poses=3, min_spacing=0.2)
    assert 1 <= len(poses) <= 3
    span = path.duration_s - 2 * path.dwell_s
    t = np.array([p[0] for p in poses])
    assert np.all(np.abs(t[:, None] - t[None, :])[np.triu_indices(len(t), 1)] >= 0.2 * span - 1e-9)
    F = [p[3] for p in poses]
    assert F == sorted(F, reverse=True)
    every = poses_to_check(path, law, wp, max_poses=1000, min_spacing=0.0)
    assert F[0] == pytest.approx(max(p[3] for p in every))
    # the check's own: every sampled time that cuts
    assert MIN_SPACING == 0.0 and len(poses_to_check(path, law, wp)) == len(every) <= MAX_POSES


def test_the_depth_is_under_the_tools_axis():
    from robstiff_drake.diagrams.chatter_check import depth_of_cut_mm

    boxes = [[0.0, 100.0, -10.0, 10.0, 703.0], [200.0, 300.0, -10.0, 10.0, 710.0]]
    assert depth_of_cut_mm(boxes, np.array([0.05, 0.0, 0.700])) == pytest.approx(3.0)
    assert depth_of_cut_mm(boxes, np.array([0.25, 0.0, 0.700])) == pytest.approx(10.0)
    assert depth_of_cut_mm(boxes, np.array([0.15, 0.0, 0.700])) == pytest.approx(10.0)  # over none: the highest


def test_a_root_at_the_edge_is_worded_as_the_damping_assumptions_to_decide():
    """A growth that is less than MARGINAL_DAMPING of negative damping (the
    shipped cylinder head: +0.22 1/s at 11.2 Hz, 0.3 %) is called the edge of
    stability, which the assumed damping decides, not an unstable cut; a
    clear one (+36.9 1/s at 68.6 Hz, 8.6 %) is called unstable."""
    from robstiff_drake.diagrams.chatter_check import MARGINAL_DAMPING

    check = {"stable": False, "damping_ratio_assumed": [0.05] * 6, "damping_on": "drives_closed", "x_mm": 1622.0,
             "y_mm": 0.0, "t_s": 11.15, "modes": [{"mode": 3, "drives_closed_hz": 11.1, "share": 0.74}],
             "largest_stable_depth_mm": None, "depth_mm": None}
    edge = chatter_warning(dict(check, growth_per_s=0.22, frequency_hz=11.2))
    assert 0.22 / (2 * np.pi * 11.2) < MARGINAL_DAMPING
    assert "at the edge of stability (short of 0.31 % of damping" in edge and "is unstable" not in edge
    clear = chatter_warning(dict(check, growth_per_s=36.9, frequency_hz=68.6))
    assert "is unstable: growth +36.9 1/s" in clear and "edge" not in clear
