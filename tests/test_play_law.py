"""The compensator's lost-motion law identified per joint from a play
campaign on the plant (whose gears have a dead zone and friction inside
it, physics the smooth law does not share)."""

import numpy as np
import pytest

from robstiff_drake.diagrams.play_campaign import play_campaign
from robstiff_drake.identification.stiffness.play_law import fit_play_law
from robstiff_drake.model import ik, transmission
from robstiff_drake.model.servo import ServoParameters

SERVO = ServoParameters(60.0, 30.0, 1.0, 0.012)


def test_a_play_campaign_identifies_the_law_that_predicts_the_loaded_twist(robot):
    """Joint 6 with 0.29 mrad of play: the law fitted to the campaign has b
    within 5 % of the plant's, and predicts the twist under 8 N*m within
    5 % of what the plant twists (the gear's elastic twist plus b), where
    the old 50 N*m take-up predicted a quarter of it."""
    b = 2.9e-4
    q = ik.solve_ik(robot.dh, ik.tool_down_pose(robot.workspace.reference_tool_point_m), robot.payload.tool_point_m)
    tau, phi = play_campaign(robot, q, joint=5, play_rad=np.array([0, 0, 0, 0, 0, b]), step_s=5e-4, servo=SERVO)
    c = 1.0 / robot.joint_stiffness_Nm_per_rad[5]
    law = fit_play_law(tau, phi, c)
    assert law.lost_motion_rad == pytest.approx(b, rel=0.05)
    plant = c * 8.0 + b
    fitted = transmission.twist(np.full(6, 8.0), np.full(6, c), np.full(6, law.lost_motion_rad),
                                take_up_Nm=np.full(6, law.take_up_Nm))[5]
    assert fitted == pytest.approx(plant, rel=0.05)
    old = transmission.twist(np.full(6, 8.0), np.full(6, c), np.full(6, b))[5]
    assert old < 0.3 * plant
    # the campaign's torques at and above 4 N*m leave the link on its flank: the law fits those to 5 %
    loaded = np.abs(tau) >= 4.0
    predicted = c * tau + law.lost_motion_rad * np.tanh(tau / law.take_up_Nm)
    np.testing.assert_allclose(predicted[loaded], phi[loaded], rtol=0.05)


def test_the_fit_needs_torques_of_both_signs():
    with pytest.raises(ValueError, match="both signs"):
        fit_play_law([1.0, 2.0, 4.0], [1e-5, 2e-5, 4e-5], 1e-6)


def test_the_fallback_take_up_is_per_joint_from_the_stiffness(robot):
    """Without a campaign: 1.5 % of each gear's rated torque (K * 1.1 mrad):
    3.3 N*m on the IRB 6400's joint 6, 25 N*m on joint 1."""
    tb = transmission.fallback_take_up_Nm(1.0 / robot.joint_stiffness_Nm_per_rad)
    assert tb[5] == pytest.approx(3.3) and tb[0] == pytest.approx(24.75)
