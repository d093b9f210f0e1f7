"""The force filter carried by the compensator tick (systems/compensator_tick.py,
``force_filter``; diagrams/compensator.make_compensator does it where the
sensor is read once per controller period, with the guard) against the
separate LinearSystem between the guard and the tick: the same guarded
wrench, filtered wrench, process wrench and correction at every instant,
bit for bit, compiled (model/tick_kernels.tick_update) and with the
plain-Python reference (jit.disabled), through tests/test_tick_guard.py's
spike, dropout and re-armed step, from a settled (nonzero) filter state."""

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder

from robstiff_drake.diagrams.compensator import make_compensator
from robstiff_drake.model import jit
from robstiff_drake.model.compensator import DeflectionModel
from robstiff_drake.model.filters import lowpass_coefficients
from robstiff_drake.model.payload import PayloadCalibration
from robstiff_drake.model.realtime import DeflectionPredictor
from robstiff_drake.systems.compensator_tick import CompensatorTick
from robstiff_drake.systems.force_filter import filter_system, steady_state
from tests.test_tick_guard import Q0, T, RawSamples

W0 = np.array([120.0, -80.0, 400.0, 3.0, -2.0, 1.0])  # (the reading the chain is settled on)


def _run(robot, filter_ba, carried_filter):
    tool = robot.payload.tool_point_m
    cal = PayloadCalibration(mass_kg=40.0, com_mm=[5.0, -3.0, 180.0], force_bias_N=[2, -1, 3])
    kin = DeflectionPredictor(robot.dh, robot.joint_stiffness_Nm_per_rad, tool)
    b = DiagramBuilder()
    src = b.AddSystem(RawSamples())
    design = filter_system(*filter_ba, 1.0 / T)
    tick = b.AddSystem(CompensatorTick(period_s=T, calibration=cal, kinematics=kin,
                                       deflection=DeflectionModel(kin, tool), saturation_rad=2e-4, delay_steps=1,
                                       rate_limit_rad_per_s=0.05,
                                       guard=(1.0 / T, 500.0), force_filter=design if carried_filter else None))
    parts = tick.add_outputs(b)
    if carried_filter:
        filtered = parts["filtered_wrench"]
    else:
        filt = b.AddSystem(design)
        b.Connect(parts["guarded_wrench"], filt.get_input_port())
        filtered = filt.get_output_port()
        b.Connect(filtered, tick.GetInputPort("wrench"))
    b.Connect(src.GetOutputPort("wrench"), tick.GetInputPort("raw_wrench"))
    b.Connect(src.GetOutputPort("q"), tick.GetInputPort("q"))
    sim = Simulator(b.Build())
    ctx = sim.get_mutable_context()
    tick_ctx = tick.GetMyMutableContextFromRoot(ctx)
    tick.hold(tick_ctx, W0)  # (the compensator's set_initial_state: guard, filter, sample)
    if carried_filter:
        tick.set_filter_state(tick_ctx, steady_state(design, W0))
    else:
        filt.GetMyMutableContextFromRoot(ctx).SetDiscreteState(steady_state(design, W0))
    tick.set_sample(tick_ctx, W0, Q0)
    out = []
    for k in range(0, 160):
        # (between the ticks and on them: what a logger reads after the updates)
        sim.AdvanceTo(k * T / 2)
        row = []
        for port in (parts["guarded_wrench"], parts["rejected"], filtered, parts["process_wrench"], parts["dq"],
                     parts["correction"]):
            row.extend(port.Eval(port.get_system().GetMyContextFromRoot(ctx)))
        out.append(row)
    return np.array(out)


@pytest.mark.parametrize("compiled", [True, False])
def test_the_carried_filter_is_the_separate_filter_exactly(robot, compiled):
    ba = lowpass_coefficients(20.0, 1.0 / T)  # (second order: the block pass's kind)
    with jit.disabled() if not compiled else jit_enabled():
        separate, carried = _run(robot, ba, False), _run(robot, ba, True)
    np.testing.assert_array_equal(carried, separate)  # bit for bit
    assert separate[-1, 6] >= 4  # the spike, the dropout and the step's first samples were rejected
    assert np.ptp(separate[:, 7:13], axis=0).min() > 1.0  # the filtered wrench moved on every axis
    assert np.any(separate[:, 25:31] != 0)  # and the correction moved


def test_a_higher_order_filter_carried_is_the_separate_one(robot):
    ba = lowpass_coefficients(20.0, 1.0 / T, order=4)
    separate, carried = _run(robot, ba, False), _run(robot, ba, True)
    np.testing.assert_array_equal(carried, separate)


def test_a_carried_filter_needs_the_guard_and_the_ticks_period(robot):
    kin = DeflectionPredictor(robot.dh, robot.joint_stiffness_Nm_per_rad, robot.payload.tool_point_m)
    args = dict(period_s=T, calibration=PayloadCalibration(mass_kg=1.0), kinematics=kin, deflection=None,
                saturation_rad=1e-3, delay_steps=1, rate_limit_rad_per_s=0.1)
    with pytest.raises(ValueError, match="filter"):
        CompensatorTick(**args, force_filter=filter_system(*lowpass_coefficients(2.0, 1.0 / T), 1.0 / T))
    with pytest.raises(ValueError, match="filter"):
        CompensatorTick(**args, guard=(1.0 / T, 500.0), force_filter=filter_system(*lowpass_coefficients(2.0, 1000.0),
                                                                                     1e-3))


@pytest.mark.parametrize("rate_hz, carried", [(250.0, True), (1000.0, False)])
def test_make_compensator_carries_the_filter_where_the_rates_agree(robot, rate_hz, carried):
    comp = make_compensator(rate_hz=rate_hz, filter_ba=lowpass_coefficients(2.0, rate_hz), max_jump_N=500.0,
                            period_s=T, delay_steps=1, saturation_rad=1e-3, rate_limit_rad_per_s=0.1,
                            calibration=PayloadCalibration(mass_kg=1.0), model_dh=robot.dh,
                            model_stiffness_Nm_per_rad=robot.joint_stiffness_Nm_per_rad,
                            tool_m=robot.payload.tool_point_m)
    names = [s.get_name() for s in comp.diagram.GetSystems()]
    assert ("force_filter" not in names) == carried
    assert (comp.systems["filter"] is comp.systems["tick"]) == carried
    assert ("filtered_wrench" in comp.tick_parts) == carried


class jit_enabled:
    """(a no-op context: the kernels as the installation has them)"""

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False
