"""The two per-tick compiled calls of the closed loop take their constants
packed (model/tick_kernels.pack_tick_constants,
model/force_step_kernels.pack_force_constants: one float64 and one int64
array, built once; numba's dispatcher costs about 0.05 us per argument
and call): few arguments, and the same arithmetic as before.  The
compensator tick's packed update (compiled and its Python original)
against the block's plain-Python reference update through a guard's
rejections, a NaN and a re-arm, to round-off; the milling force's packed
update against the unpacked averaged_force_step, bit for bit (the same
kernel code on the same values).  And model/jit's kept answer and
``Kernel.compiled`` follow jit.disabled in and out."""

import numpy as np
import pytest

from robstiff_drake.model import force_step_kernels as fk
from robstiff_drake.model import jit
from robstiff_drake.model import tick_kernels as tk
from robstiff_drake.model.compensator import DeflectionModel
from robstiff_drake.model.payload import PayloadCalibration
from robstiff_drake.model.realtime import DeflectionPredictor
from robstiff_drake.systems.compensator_tick import _NONE, CompensatorTick
from robstiff_drake.systems.force_filter import filter_system, steady_state
from kernel_checks import assert_round_off, kernel
from tests.test_force_step_kernels import cell, states  # noqa: F401  (the fixture)

T = 0.004
Q0 = np.deg2rad([5.0, 15.0, 20.0, 10.0, 50.0, -20.0])
W0 = np.array([120.0, -80.0, 400.0, 3.0, -2.0, 1.0])


def test_the_per_tick_kernels_take_their_constants_in_two_arrays():
    # (the state and inputs, then the packed constants: 17 and 19 arguments before)
    assert tk.tick_update.py_func.__code__.co_argcount == 7
    assert fk.averaged_force_update.py_func.__code__.co_argcount == 7


@pytest.mark.parametrize("compiled", [True, False], ids=["compiled", "python original"])
def test_the_packed_tick_update_is_the_blocks_reference(robot, compiled):
    update = kernel(compiled, tk.tick_update)
    tool = robot.payload.tool_point_m
    kin = DeflectionPredictor(robot.dh, robot.joint_stiffness_Nm_per_rad, tool)
    cal = PayloadCalibration(mass_kg=40.0, com_mm=[5.0, -3.0, 180.0], force_bias_N=[2, -1, 3])
    design = filter_system([0.2, 0.2], [1.0, -0.6], 1.0 / T)
    tick = CompensatorTick(period_s=T, calibration=cal, kinematics=kin, deflection=DeflectionModel(kin, tool),
                           saturation_rad=2e-4, delay_steps=2, rate_limit_rad_per_s=0.05,
                           guard=(1.0 / T, 500.0, 0.02), force_filter=design)
    consts, at = tick._fused
    assert consts.dtype == np.float64 and at.dtype == np.int64 and at.shape == (tk.TICK_OFFSETS_SIZE,)
    ctx = tick.CreateDefaultContext()
    tick.hold(ctx, W0)
    tick.set_filter_state(ctx, steady_state(design, W0))
    tick.set_sample(ctx, W0, Q0)
    rng = np.random.default_rng(11)
    rejected = 0
    for k in range(80):
        raw = W0 + rng.normal(0.0, 40.0, 6) + (0.0 if k < 20 else 900.0)  # (from tick 20 a step: rejected, re-armed)
        if k in (5, 6):
            raw[0] += 2000.0  # (a spike)
        if k == 9:
            raw[4] = np.nan
        q = Q0 + 0.01 * np.sin(0.3 * k + np.arange(6))
        tick.GetInputPort("raw_wrench").FixValue(ctx, raw)
        tick.GetInputPort("q").FixValue(ctx, q)
        before = ctx.get_discrete_state(0).value().copy()
        values = tick.AllocateDiscreteVariables()
        values.set_value(0, before)
        with jit.disabled():
            tick._update(ctx, values)
        want = values.get_value(0).copy()
        x = before.copy()
        update(x, raw, _NONE, q, _NONE, consts, at)
        assert_round_off(x, want)
        ctx.SetDiscreteState(0, want)
        rejected = want[tick.part_columns("rejected")][0]
    assert rejected >= 5 and np.all(np.isfinite(want))  # (the spike, the NaN and the step's first were rejected)


@pytest.mark.parametrize("compiled", [True, False], ids=["compiled", "python original"])
def test_the_packed_force_update_is_the_unpacked_step(cell, compiled):  # noqa: F811
    step, update = kernel(compiled, fk.averaged_force_step), kernel(compiled, fk.averaged_force_update)
    src, _kin, q0 = cell
    consts, at = src._packed
    assert consts.dtype == np.float64 and at.dtype == np.int64 and at.shape == (fk.FORCE_OFFSETS_SIZE,)
    checked = 0
    for t, q, process, hist in states(src, q0):
        if np.isnan(hist[-3]):
            continue
        out = np.empty(22 + hist.shape[0])
        step(q, t, hist, process, *src._fused, out)
        held, wrench, spatial = np.concatenate((process, hist)), np.empty(6), np.empty(6)
        update(q, t, held, wrench, spatial, consts, at)
        np.testing.assert_array_equal(wrench, out[:6])
        np.testing.assert_array_equal(spatial, np.r_[out[3:6], out[:3]])
        np.testing.assert_array_equal(held, np.r_[out[6:10], out[22:]])
        checked += np.linalg.norm(out[:3]) > 10.0
    assert checked > 20  # (in the material)


def test_the_packers_refuse_shapes_the_kernels_would_misread():
    with pytest.raises(ValueError, match="wrench"):
        tk.pack_tick_constants(range(12), (1.0, 2.0), *[np.zeros(3)] * 6, np.eye(2), np.zeros((2, 5)),
                               np.zeros((6, 2)), np.eye(6))
    with pytest.raises(ValueError, match="lines"):
        fk.pack_force_constants(np.zeros(45), 0.1, np.zeros((2, 9)), np.zeros(3), 0.5, T, np.zeros(9), np.zeros(3),
                                np.zeros(3), np.zeros((1, 5)), np.ones(2), np.zeros((2, 2)), np.zeros(3), np.zeros(3))


def test_the_kept_answer_and_the_compiled_function_follow_disabled():
    on = jit.available()
    with jit.disabled():
        assert not jit.available()
        assert tk.tick_update.compiled() is tk.tick_update  # (the wrapper: it runs the Python original)
    assert jit.available() == on
    if on:
        assert tk.tick_update.compiled() is tk.tick_update._impl is not tk.tick_update.py_func
    else:
        assert tk.tick_update.compiled() is tk.tick_update
