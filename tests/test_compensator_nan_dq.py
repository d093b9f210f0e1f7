"""A deflection that comes out not finite on a joint (a model file or a
pose the arithmetic cannot take) targets no correction on any joint, so
the correction ramps to zero at the rate limit: the saturation's clamp
min(s, max(-s, nan)) would give -s, the full negative saturation, a step
the arm would follow."""

import math

from robstiff_drake.model.compensator import Compensator
from robstiff_drake.model.filters import lowpass_coefficients
from robstiff_drake.model.payload import PayloadCalibration
from robstiff_drake.model.realtime import DeflectionPredictor
from robstiff_drake.model.robot import load_robot


def compensator():
    robot = load_robot()
    tool = robot.tool_point()
    kin = DeflectionPredictor(robot.dh, robot.joint_stiffness_Nm_per_rad, tool)
    cal = PayloadCalibration(mass_kg=40.0, com_mm=[0.0, 0.0, 180.0], force_bias_N=[0.0] * 3,
                             torque_bias_Nm=[0.0] * 3, sensor_mount_rpy_deg=[0.0] * 3)
    return Compensator(predictor=kin, calibration=cal, tool_m=tool, filter_ba=lowpass_coefficients(2.0, 1000.0),
                       max_jump_N=1000.0, saturation_rad=0.0087, rate_limit_rad_per_s=0.087, delay_steps=0,
                       initial_wrench=[10.0, -5.0, -400.0, 1.0, 2.0, 0.5])


def test_a_deflection_not_finite_ramps_the_correction_to_zero():
    comp = compensator()
    q = [0.0, -0.3, 0.4, 0.0, 0.5, 0.0]
    good = list(comp.model.dq(comp.remove_gravity(comp.filtered, q), q))
    for bad in (math.nan, math.inf, -math.inf):
        comp.model.dq = lambda w, q_rad, bad=bad: [bad] + good[1:]
        held = [0.004, -0.003, 0.002, 0.0, 0.001, -0.001]
        comp.correction = list(held)
        out = comp.tick(q, 0.004)
        assert comp.dq == [0.0] * 6, (bad, comp.dq)
        step = [r * 0.004 for r in comp.rate]
        # one rate-limited step towards zero on every joint, none beyond it
        assert out == [x - min(s, max(-s, x)) for x, s in zip(held, step)], (bad, out)
    comp.model.dq = lambda w, q_rad: good
    comp.tick(q, 0.004)
    assert comp.dq == [min(s, max(-s, d)) for d, s in zip(good, comp.saturation)]
