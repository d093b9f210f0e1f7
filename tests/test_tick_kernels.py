"""The compiled per-tick kernels (model/tick_kernels.py) against the
plain-Python arithmetic they replace: the tool's pose
(DeflectionPredictor._forward), the process wrench (GravityRemover), the
predicted deflection (DeflectionModel.dq, with a rotated sensor mount too)
and the correction's saturation, delay line and rate limit
(compensator_tick.saturate, model/compensator.rate_limited_step), through
NaN, to round-off.  The kernels' Python originals are checked with or
without numba; the compiled ones where numba is installed."""

import math

import numpy as np
import pytest

from robstiff_drake.model import jit
from robstiff_drake.model import tick_kernels as tk
from robstiff_drake.model.compensator import DeflectionModel, GravityRemover, rate_limited_step
from robstiff_drake.model.payload import _GRAVITY, PayloadCalibration
from robstiff_drake.model.realtime import DeflectionPredictor
from robstiff_drake.model.wrench_frames import to_sensor_frame
from robstiff_drake.systems.compensator_tick import saturate
from kernel_checks import assert_round_off

CAL = PayloadCalibration(mass_kg=40.0, com_mm=[5.0, -3.0, 180.0], force_bias_N=[2, -1, 3],
                         torque_bias_Nm=[0.1, 0.0, -0.2], sensor_mount_rpy_deg=[0.0, 0.0, 30.0])


def kernels(compiled):
    if compiled and not jit.available():
        pytest.skip("numba is not installed: the callers run the plain-Python references (tested here too)")
    return ((tk.pose_and_deflection, tk.correction_step) if compiled
            else (tk.pose_and_deflection.py_func, tk.correction_step.py_func))


@pytest.mark.parametrize("compiled", [True, False], ids=["compiled", "python original"])
@pytest.mark.parametrize("mount_rpy_deg", [(0.0, 0.0, 0.0), (10.0, -20.0, 30.0)], ids=["mount", "rotated mount"])
def test_pose_process_wrench_and_deflection_are_the_references(robot, compiled, mount_rpy_deg):
    pose_and_deflection, _ = kernels(compiled)
    tool = robot.payload.tool_point_m
    kin = DeflectionPredictor(robot.dh, robot.joint_stiffness_Nm_per_rad * 1.1, tool)
    remover = GravityRemover(CAL, kin)
    model = DeflectionModel(kin, tool, mount_rpy_deg)
    chain, gravity = tk.chain_constants(kin), tk.gravity_constants(remover, _GRAVITY)
    consts = tk.model_constants(model)
    rng = np.random.default_rng(4)
    for _ in range(50):
        q = rng.uniform(-2.0, 2.0, 6)
        w = rng.normal(0.0, 200.0, 6)
        out = np.empty(24)
        pose_and_deflection(q, chain, w, gravity, consts, out)
        p = remover(w.tolist(), q)
        assert_round_off(out[:12], kin._forward(tuple(q.tolist()), None))
        assert_round_off(out[12:18], p)
        assert_round_off(out[18:], model.dq(p, q))
        short = np.empty(18)  # (pose and process wrench only: a tick with a separate predictor)
        pose_and_deflection(q, chain, w, gravity, np.empty(0), short)
        np.testing.assert_array_equal(short, out[:18])
        assert_round_off(kin.pose_only(q), out[:12])  # (compiled with numba, else the reference)


@pytest.mark.parametrize("compiled", [True, False], ids=["compiled", "python original"])
@pytest.mark.parametrize("delay_steps", [0, 1, 3])
def test_the_correction_step_is_the_reference(compiled, delay_steps):
    _, correction_step = kernels(compiled)
    lo, hi, step = -2e-4 * np.ones(6), 2e-4 * np.ones(6), np.array([1e-5, 2e-5, 1e-5, 3e-5, 1e-5, 1e-5])
    rng = np.random.default_rng(5)
    line, c = np.zeros(6 * delay_steps), np.zeros(6)
    ref_line, ref_c = [0.0] * (6 * delay_steps), [0.0] * 6
    held = 0
    for k in range(80):
        dq = rng.normal(0.0, 3e-4, 6)
        if 20 <= k < 23:
            dq[k % 6] = math.nan  # (a fault: the correction is held while it passes the line)
        out = np.empty(6 * delay_steps + 6)
        correction_step(dq, line, c, lo, hi, step, out)
        s = [saturate(v, a, b) for v, a, b in zip(dq.tolist(), lo.tolist(), hi.tolist())]
        if delay_steps:
            d, ref_line = ref_line[:6], ref_line[6:] + s
        else:
            d = s
        if math.isfinite(sum(d)):
            ref_c = rate_limited_step(ref_c, d, step.tolist())
        else:
            held += 1
        np.testing.assert_array_equal(out[:6 * delay_steps], ref_line)
        np.testing.assert_array_equal(out[6 * delay_steps:], ref_c)  # bit for bit
        line, c = out[:6 * delay_steps], out[6 * delay_steps:]
    assert held == 3 and np.any(c != 0)


@pytest.mark.parametrize("compiled", [True, False], ids=["compiled", "python original"])
def test_the_sensor_ripples_are_to_sensor_frame(robot, compiled):
    if compiled and not jit.available():
        pytest.skip("numba is not installed: the milling force runs the plain-Python loop (tested here too)")
    fn = tk.sensor_ripples if compiled else tk.sensor_ripples.py_func
    kin = DeflectionPredictor(robot.dh, robot.joint_stiffness_Nm_per_rad, robot.payload.tool_point_m)
    rng = np.random.default_rng(6)
    tool = np.array(robot.payload.tool_point_m, dtype=float)
    for k in (1, 5, 8):
        pose = np.array(kin._forward(tuple(rng.uniform(-2.0, 2.0, 6).tolist()), None))
        inst, w = rng.normal(0.0, 300.0, (k, 6)), rng.normal(0.0, 300.0, 6)
        values = np.zeros((8, 12))
        fn(inst, w, pose, tool, values)
        for i, d in enumerate((inst - w).tolist()):
            np.testing.assert_array_equal(values[i, 6:], to_sensor_frame(pose[:9].tolist(), tool.tolist(), d))
        assert not values[k:].any() and not values[:, :6].any()
