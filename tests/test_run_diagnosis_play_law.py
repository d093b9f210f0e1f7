"""diagnose-run's loop prediction with the model's lost motion uses the
law the run's compensator used (compensator.yaml's model.lost_motion_law,
written from the scenario's model block, hysteretic by default): before,
it used the smooth law b tanh(tau / take-up) for any b while the
compensator had the hysteretic law, so on a pass whose gear torque
reverses within the play's friction the prediction moved the links across
the gap where the compensator (and the plant) kept them on their flank.
Synthetic signals, no simulation."""

import numpy as np

from robstiff_drake.identification.runs import settings as rs
from robstiff_drake.identification.runs.signals import (
    believed_gear_deviation, gear_law_deviation, model_deflection, play_crossing_deviation,
)
from robstiff_drake.model.transmission import fallback_take_up_Nm, gap_friction_Nm

STIFFNESS_NM_PER_RAD = np.array([1.5e6, 1.1e6, 8e5, 3e5, 3e5, 2e5])
C = 1.0 / STIFFNESS_NM_PER_RAD
B = np.array([0.0, 150e-6, 0.0, 0.0, 0.0, 0.0])
PAYLOAD = {"mass_kg": 40.0, "com_mm": [0.0, 0.0, 180.0], "force_bias_N": [0.0] * 3, "torque_bias_Nm": [0.0] * 3,
           "sensor_mount_rpy_deg": [0.0] * 3}


def _settings(**kw):
    return rs.CompensatorSettings(joint_stiffness_Nm_per_rad=STIFFNESS_NM_PER_RAD.tolist(), payload=PAYLOAD,
                                  tool_point_mm=[0.0, 0.0, 350.0], cutter_diameter_mm=75.0,
                                  lost_motion_rad=B.tolist(), **kw)


def _pass():
    """Joint 2's gear carries 5 - 12 cos(2 pi t / 5) N*m (gravity 5 N*m, the process load reversing it):
    within its friction in the play (1.5 % of the rated torque, 18 N*m) both ways."""
    t = np.arange(0.0, 5.0, 0.005)
    n = t.size
    g = np.zeros((n, 6))
    g[:, 1] = 5.0
    tau = np.zeros((n, 6))
    tau[:, 1] = 12.0 * np.cos(2 * np.pi * t / 5.0)
    inertia = np.tile([170.0, 256.0, 85.0, 4.3, 4.7, 0.32], (n, 1))
    return t, g, g[0] - tau[0], np.zeros((n, 6)), tau, inertia


def test_the_prediction_takes_the_runs_law():
    t, g, g0, tau_i, tau, inertia = _pass()
    friction = gap_friction_Nm(STIFFNESS_NM_PER_RAD)
    assert friction[1] > 17.0  # (the pass stays within it)
    hyst = believed_gear_deviation(_settings(), g, g0, tau_i, tau, C, inertia, t)
    # the hysteretic law: the gear stays on the flank it pressed at the touch-off, no crossing
    assert np.allclose(hyst, play_crossing_deviation(g, g0, tau_i, tau, B, friction, inertia, t))
    assert np.max(np.abs(hyst[:, 1])) < 1e-9, np.max(np.abs(hyst[:, 1]))
    smooth = believed_gear_deviation(_settings(lost_motion_law="smooth"), g, g0, tau_i, tau, C, inertia, t)
    assert np.allclose(smooth, gear_law_deviation(g, g0, tau_i, tau, B, 0.0, fallback_take_up_Nm(C)))
    # (before, this was the prediction whatever the law: the link crossing most of its 300 urad gap)
    assert np.max(np.abs(smooth[:, 1])) > 100e-6, np.max(np.abs(smooth[:, 1]))
    # the compensator's own prediction likewise: the gear stays on its flank (C tau, less the elastic twist of
    # the at most 17 N*m the gear carries while off its flank: 15 urad), no crossing of the 300 urad gap
    dq = model_deflection(_settings(), g, tau, C)
    assert np.max(np.abs(dq[:, 1] - C[1] * tau[:, 1])) <= C[1] * 17.0 + 1e-12
    dq_smooth = model_deflection(_settings(lost_motion_law="smooth"), g, tau, C)
    assert np.max(np.abs(dq_smooth[:, 1] - C[1] * tau[:, 1])) > 90e-6  # (the smooth law: 95 urad of play)


def test_the_law_is_logged_and_read(tmp_path):
    s = _settings(lost_motion_law="smooth", lost_motion_take_up_Nm=[1.0, 2.0, 3.0, 4.0, 5.0, 6.0])
    path = tmp_path / "compensator.yaml"
    path.write_text(rs.settings_text(s, "x"), encoding="utf-8")
    text = path.read_text()
    assert "    lost_motion_law: smooth\n" in text and "lost_motion_friction_Nm" not in text, text  # (None: not written)
    _, back = rs.read_settings(path)
    assert back.lost_motion_law == "smooth" and back.lost_motion_take_up_Nm == [1.0, 2.0, 3.0, 4.0, 5.0, 6.0]
    assert back.lost_motion_friction_Nm is None and back.same_as(s)
    # a file written before the law was logged: the compensator's default, hysteretic
    path.write_text(text.replace("    lost_motion_law: smooth\n", ""), encoding="utf-8")
    assert rs.read_settings(path)[1].lost_motion_law == "hysteretic"
