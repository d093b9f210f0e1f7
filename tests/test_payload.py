"""Gravity calibration of the wrist sensor's payload."""

import numpy as np
import pytest

from robstiff_drake.errors import InputError
from robstiff_drake.identification.stiffness import synth
from robstiff_drake.identification.stiffness.campaign import PayloadCampaign
from robstiff_drake.identification.stiffness.payload import calibrate


def as_campaign(c):
    n = len(c.q_deg)
    return PayloadCampaign("payload.csv", c.q_deg, c.force_N, c.torque_Nm, np.arange(n) + 5, [])


@pytest.mark.parametrize("seed", range(8))
def test_payload_within_half_percent_and_3mm(robot, seed):
    c = synth.payload_campaign(robot, n=15, noise_N=1.0, noise_Nm=0.1, seed=seed,
                               mass_kg=40.0, com_m=np.array([0.02, -0.015, 0.18]))
    fit = calibrate(robot, as_campaign(c))
    assert fit.mass_kg == pytest.approx(40.0, rel=0.005)
    assert np.linalg.norm(fit.com_m - c.com_m) < 0.003
    np.testing.assert_allclose(fit.force_bias_N, c.force_bias_N, atol=1.5)
    np.testing.assert_allclose(fit.torque_bias_Nm, c.torque_bias_Nm, atol=0.15)
    assert fit.rms_force_N == pytest.approx(1.0, rel=0.35)


def test_too_few_gravity_directions_is_refused(robot):
    c = synth.payload_campaign(robot, n=10, seed=1)
    c.q_deg[:, 3:] = [0.0, 60.0, 0.0]  # wrist fixed: only axis 1 turns, gravity looks the same to the sensor
    with pytest.raises(InputError, match="only 1 distinct gravity direction"):
        calibrate(robot, as_campaign(c))
    c.q_deg[:5, 4] = 20.0  # two directions: still not enough for the centre of mass
    with pytest.raises(InputError, match="only 2 distinct gravity direction.*at least 3"):
        calibrate(robot, as_campaign(c))


def test_three_directions_suffice(robot):
    c = synth.payload_campaign(robot, n=3, noise_N=0.0, noise_Nm=0.0, seed=4)
    fit = calibrate(robot, as_campaign(c))
    assert fit.mass_kg == pytest.approx(c.mass_kg, rel=1e-9)
    np.testing.assert_allclose(fit.com_m, c.com_m, atol=1e-9)


def test_sensor_mount_rotation(robot):
    from robstiff_drake.model import kinematics as kin

    rpy = np.array([0.0, 0.0, 30.0])
    c = synth.payload_campaign(robot, n=15, noise_N=0.0, noise_Nm=0.0, seed=3)
    R = kin.rpy_to_rotation(np.deg2rad(rpy))
    c.force_N, c.torque_Nm = synth.payload_readings(robot.dh, np.deg2rad(c.q_deg), c.mass_kg, c.com_m,
                                                    c.force_bias_N, c.torque_bias_Nm, R_mount=R)
    fit = calibrate(robot, as_campaign(c), mount_rpy_deg=rpy)
    np.testing.assert_allclose(fit.com_m, c.com_m, atol=1e-9)
    wrong = calibrate(robot, as_campaign(c))  # mounting rotation ignored: a worse fit
    assert wrong.rms_force_N > 1.0
