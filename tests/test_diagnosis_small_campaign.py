"""A five-pose campaign of pure six springs plus noise must not come back
with an effect named (studies/small_campaigns.py measures the rate).

The campaign is the newcomer's: `robstiff synth stiffness --robot
kr210_r2700.yaml --n 15 --loads-per-pose 3 --seed 4` (tests/data's copy of
the KR 210 R2700 file, tool point 320 mm along the flange axis).  Before the
fix the diagnosis named angle_compliance_j4_q1 (and angle_compliance_j2)
from a pose-clustered test on 5 poses for 7 parameters, and its joint-4
stiffness moved from identify's 3.33e5 to 3.15e5 N*m/rad."""

from pathlib import Path

import numpy as np
import pytest

from robstiff_drake.identification.diagnosis import selection
from robstiff_drake.identification.diagnosis.candidate_evaluation import CandidateResult
from robstiff_drake.identification.diagnosis.campaign_diagnosis import diagnose
from robstiff_drake.identification.stiffness import synth
from robstiff_drake.model.robot import load_robot

DATA = Path(__file__).parent / "data"
TOOL_M = np.array([0.0, 0.0, 0.32])


@pytest.fixture(scope="module")
def newcomer():
    robot = load_robot(DATA / "kr210_r2700.yaml")
    c = synth.stiffness_campaign(robot, n=15, loads_per_pose=3, seed=4, noise_mm=0.01, tool_m=TOOL_M)
    return robot, c.to_campaign()


@pytest.mark.parametrize("noise_mm", [None, 0.01])
def test_five_poses_of_pure_springs_name_no_effect(newcomer, noise_mm):
    robot, campaign = newcomer
    d = diagnose(robot, campaign, tool_m=TOOL_M, noise_mm=noise_mm)
    assert [t["name"] for t in d.terms] == []
    # the final stiffness is the six springs' (identify's): no term pulls joint 4's
    assert d.joint_stiffness_Nm_per_rad[3] == pytest.approx(3.328e5, rel=0.01)
    # no candidate of the dictionary gets a clustered p on 5 poses for 7 parameters
    assert all(np.isnan(r.p_grouped) for rnd in d.rounds for r in rnd if r.poses_needed)
    if noise_mm is not None:
        assert d.explains_data is True


def _cand(**kw):
    base = dict(name="x", source="dictionary", status="ok", rms_mm=0.008, p_value=1e-6, p_grouped=1e-6)
    return CandidateResult(**{**base, **kw})


def test_a_candidate_the_poses_cannot_test_is_undecided_not_named():
    # 0.01 / 100 candidates = 1e-4
    assert selection._fits(_cand(), 0.010, 100)
    assert not selection._fits(_cand(p_grouped=float("nan"), poses_needed=8), 0.010, 100)
    assert selection.undecided(_cand(p_grouped=float("nan"), poses_needed=8), 0.010, 100)
    # the newcomer's best candidate: F-test p = 0.011, not even undecided
    assert not selection.undecided(_cand(p_grouped=float("nan"), poses_needed=8, p_value=0.011), 0.010, 100)


def test_five_poses_with_a_real_effect_say_too_few_poses_and_what_decides():
    from physical_effects import visible_campaign

    robot = load_robot("irb6400")
    c = visible_campaign(robot, "force_bias", np.random.default_rng([5, 1]), 0.06, seed=11, force_N=700.0,
                         noise_mm=0.01, n=20)
    d = diagnose(robot, c.to_campaign(), noise_mm=0.01)
    assert [t["name"] for t in d.terms] == []
    assert d.explains_data is False
    assert d.verdict.startswith("too few poses to decide: force_bias") and "robstiff plan-poses" in d.verdict
    assert any(w.startswith("too few poses to decide") for w in d.warnings)


def test_twelve_poses_with_the_effect_found_do_not_say_too_few_poses():
    # the undecided candidate is judged against the final model, not the first round's six springs (before this
    # check, drift_periodic of round 1 was reported although the planted drift, once added, explains the data).
    # 12 poses: on 10 the calibrated clustered test (CR2, Bell-McCaffrey t) does not decide this drift, and the
    # verdict says "too few poses to decide" (drift_periodic)
    from physical_effects import visible_campaign

    robot = load_robot("irb6400")
    rng = np.random.default_rng([19000, 9])
    c = visible_campaign(robot, "drift", rng, 0.04, seed=19900, force_N=700.0, noise_mm=0.01, n=48)
    d = diagnose(robot, c.to_campaign(), noise_mm=0.01)
    assert [t["name"] for t in d.terms] == ["drift"]
    assert d.explains_data is True and not d.verdict.startswith("too few poses")
