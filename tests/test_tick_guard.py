"""The wrench guard carried by the compensator tick (systems/compensator_tick.py,
``guard``; diagrams/compensator.make_compensator does it where the sensor is
read once per controller period) against the separate WrenchGuard block
before the same filter and tick: the same guarded wrench, rejected count,
filtered wrench and correction, bit for bit, through a spike, a dropout and
a step of the force that the guard takes after re-arming."""

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder, LeafSystem

from robstiff_drake.diagrams.compensator import make_compensator
from robstiff_drake.model.compensator import DeflectionModel
from robstiff_drake.model.filters import lowpass_coefficients
from robstiff_drake.model.payload import PayloadCalibration
from robstiff_drake.model.realtime import DeflectionPredictor
from robstiff_drake.systems.compensator_tick import CompensatorTick
from robstiff_drake.systems.force_filter import filter_system
from robstiff_drake.systems.wrist_sensor import WrenchGuard

T = 0.004
Q0 = np.deg2rad([5.0, 15.0, 20.0, 10.0, 50.0, -20.0])


class RawSamples(LeafSystem):
    """A wrench sampled every T (held state, as the wrist sensor's): a
    slow wave with a one-sample spike, a dropout (NaN) and a step of 900 N
    that stays; and joint angles that change between ticks too."""

    def __init__(self):
        super().__init__()
        self._w = self.DeclareDiscreteState(6)
        self.DeclarePeriodicDiscreteUpdateEvent(T, 0.0, self._sample)
        self.DeclareStateOutputPort("wrench", self._w)
        self.DeclareVectorOutputPort("q", 6, lambda c, o: o.SetFromVector(
            Q0 + 0.01 * np.sin(37.0 * c.get_time() + np.arange(6))))

    def _sample(self, context, discrete_state):
        t = context.get_time()
        w = np.array([300.0, -250.0, 60.0, 5.0, -3.0, 20.0]) * np.sin(11.0 * t + np.arange(6))
        k = round(t / T)
        if k == 10:
            w[1] += 2000.0  # a spike
        if 20 <= k < 23:
            w[:] = np.nan  # a dropout
        if k >= 40:
            w[0] += 900.0  # a step the guard takes after GUARD_REARM_S
        discrete_state.set_value(0, w)


def _run(robot, carried):
    tool = robot.payload.tool_point_m
    cal = PayloadCalibration(mass_kg=40.0, com_mm=[5.0, -3.0, 180.0], force_bias_N=[2, -1, 3])
    kin = DeflectionPredictor(robot.dh, robot.joint_stiffness_Nm_per_rad, tool)
    b = DiagramBuilder()
    src = b.AddSystem(RawSamples())
    filt = b.AddSystem(filter_system(*lowpass_coefficients(20.0, 1.0 / T), 1.0 / T))
    tick = b.AddSystem(CompensatorTick(period_s=T, calibration=cal, kinematics=kin, deflection=DeflectionModel(kin, tool),
                                       saturation_rad=2e-4, delay_steps=1, rate_limit_rad_per_s=0.05,
                                       guard=(1.0 / T, 500.0) if carried else None))
    parts = tick.add_outputs(b)  # (the state split by a C++ Demultiplexer)
    if carried:
        g_in, g_out, rejected = tick.GetInputPort("raw_wrench"), parts["guarded_wrench"], parts["rejected"]
    else:
        guard = b.AddSystem(WrenchGuard(rate_hz=1.0 / T, max_jump_N=500.0))
        g_in, g_out, rejected = guard.GetInputPort("wrench"), guard.GetOutputPort("wrench"), guard.GetOutputPort("rejected")
    b.Connect(src.GetOutputPort("wrench"), g_in)
    b.Connect(g_out, filt.get_input_port())
    b.Connect(filt.get_output_port(), tick.GetInputPort("wrench"))
    b.Connect(src.GetOutputPort("q"), tick.GetInputPort("q"))
    sim = Simulator(b.Build())
    ctx = sim.get_mutable_context()
    out = []
    for k in range(1, 80):
        sim.AdvanceTo(k * T + 0.3 * T)
        row = []
        for port in (g_out, rejected, filt.get_output_port(), parts["process_wrench"], parts["correction"]):
            row.extend(port.Eval(port.get_system().GetMyContextFromRoot(ctx)))
        out.append(row)
    return np.array(out)


def test_the_carried_guard_is_the_separate_guard_exactly(robot):
    separate, carried = _run(robot, False), _run(robot, True)
    np.testing.assert_array_equal(carried, separate)  # bit for bit
    rejected = separate[:, 6]
    assert rejected[-1] >= 4  # the spike, the dropout and the step's first samples were rejected
    assert separate[-1, 0] > 700.0  # and the step was taken after re-arming
    assert np.any(separate[:, 19:25] != 0)  # the correction moved


def test_a_carried_guard_samples_at_the_ticks_period(robot):
    kin = DeflectionPredictor(robot.dh, robot.joint_stiffness_Nm_per_rad, robot.payload.tool_point_m)
    with pytest.raises(ValueError, match="rate_hz"):
        CompensatorTick(period_s=T, calibration=PayloadCalibration(mass_kg=1.0), kinematics=kin, deflection=None,
                        saturation_rad=1e-3, delay_steps=1, rate_limit_rad_per_s=0.1, guard=(1000.0, 500.0))


@pytest.mark.parametrize("rate_hz, carried", [(250.0, True), (1000.0, False)])
def test_make_compensator_carries_the_guard_where_the_rates_agree(robot, rate_hz, carried):
    kin_args = dict(model_dh=robot.dh, model_stiffness_Nm_per_rad=robot.joint_stiffness_Nm_per_rad,
                    tool_m=robot.payload.tool_point_m)
    comp = make_compensator(rate_hz=rate_hz, filter_ba=lowpass_coefficients(2.0, rate_hz), max_jump_N=500.0,
                            period_s=T, delay_steps=1, saturation_rad=1e-3, rate_limit_rad_per_s=0.1,
                            calibration=PayloadCalibration(mass_kg=1.0), **kin_args)
    names = [s.get_name() for s in comp.diagram.GetSystems()]
    assert ("wrench_guard" not in names) == carried
    assert (comp.systems["guard"] is comp.systems["tick"]) == carried
