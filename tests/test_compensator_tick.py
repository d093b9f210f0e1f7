"""The compensator's tick block (systems/compensator_tick.py) against the
separate blocks it replaces (two ZeroOrderHolds, GravityRemoval,
DeflectionPrediction, Saturation, the transport delay, RateLimitedCorrection)
in one simulation: the same outputs, bit for bit, for every delay, with NaN
and saturated deflections on the way."""

import contextlib

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder, LeafSystem
from pydrake.systems.primitives import DiscreteTimeDelay, Saturation, ZeroOrderHold

from robstiff_drake.model import jit
from robstiff_drake.model.compensator import DeflectionModel
from robstiff_drake.model.payload import PayloadCalibration
from robstiff_drake.model.realtime import DeflectionPredictor
from robstiff_drake.systems.compensator_tick import CompensatorTick
from robstiff_drake.systems.deflection_prediction import DeflectionPrediction
from robstiff_drake.systems.gravity_removal import GravityRemoval
from robstiff_drake.systems.reference_correction import RateLimitedCorrection

T = 0.004
Q0 = np.deg2rad([5.0, 15.0, 20.0, 10.0, 50.0, -20.0])


class Signals(LeafSystem):
    """Time-varying wrench and joint angles (changing between ticks too); the
    wrench is NaN on one stretch (a fault that reaches the correction) and
    large on another (the saturation acts)."""

    def __init__(self):
        super().__init__()
        self.DeclareVectorOutputPort("wrench", 6, self._w)
        self.DeclareVectorOutputPort("q", 6, lambda c, o: o.SetFromVector(
            Q0 + 0.01 * np.sin(37.0 * c.get_time() + np.arange(6))))

    def _w(self, context, out):
        t = context.get_time()
        w = np.array([300.0, -250.0, 60.0, 5.0, -3.0, 20.0]) * np.sin(11.0 * t + np.arange(6))
        if 0.05 <= t < 0.06:
            w[:] = np.nan
        if 0.1 <= t < 0.12:
            w *= 400.0
        out.SetFromVector(w)


@pytest.mark.parametrize("compiled", [True, False], ids=["compiled update", "reference update"])
@pytest.mark.parametrize("delay_steps", [0, 1, 3])
def test_the_tick_is_the_separate_blocks_exactly(robot, delay_steps, compiled):
    """With numba (model/tick_kernels.py) and without (model/jit.disabled):
    the compiled update is the reference's arithmetic, bit for bit here."""
    if compiled and not jit.available():
        pytest.skip("numba is not installed: the tick runs its reference update (tested here too)")
    with contextlib.nullcontext() if compiled else jit.disabled():
        _tick_against_separate_blocks(robot, delay_steps)


def _tick_against_separate_blocks(robot, delay_steps):
    tool = robot.payload.tool_point_m
    cal = PayloadCalibration(mass_kg=40.0, com_mm=[5.0, -3.0, 180.0], force_bias_N=[2, -1, 3],
                             torque_bias_Nm=[0.1, 0.0, -0.2])
    kin = DeflectionPredictor(robot.dh, robot.joint_stiffness_Nm_per_rad * 1.1, tool)
    sat, rate = 2e-4, 0.05
    b = DiagramBuilder()
    src = b.AddSystem(Signals())
    w, q = src.GetOutputPort("wrench"), src.GetOutputPort("q")
    # the separate blocks
    zw, zq = b.AddSystem(ZeroOrderHold(T, 6)), b.AddSystem(ZeroOrderHold(T, 6))
    b.Connect(w, zw.get_input_port())
    b.Connect(q, zq.get_input_port())
    grav = b.AddSystem(GravityRemoval(calibration=cal, kinematics=kin))
    b.Connect(zw.get_output_port(), grav.GetInputPort("wrench"))
    b.Connect(zq.get_output_port(), grav.GetInputPort("q"))
    pred = b.AddSystem(DeflectionPrediction(predictor=kin, tool_m=tool))
    b.Connect(grav.get_output_port(), pred.GetInputPort("process_wrench"))
    b.Connect(zq.get_output_port(), pred.GetInputPort("q"))
    satb = b.AddSystem(Saturation(-sat * np.ones(6), sat * np.ones(6)))
    b.Connect(pred.GetOutputPort("dq"), satb.get_input_port())
    last = satb.get_output_port()
    if delay_steps:
        delay = b.AddSystem(ZeroOrderHold(T, 6) if delay_steps == 1 else DiscreteTimeDelay(T, delay_steps - 1, 6))
        b.Connect(last, delay.get_input_port())
        last = delay.get_output_port()
    corr = b.AddSystem(RateLimitedCorrection(period_s=T, rate_limit_rad_per_s=rate))
    b.Connect(last, corr.get_input_port())
    # the tick
    tick = b.AddSystem(CompensatorTick(period_s=T, calibration=cal, kinematics=kin,
                                       deflection=DeflectionModel(kin, tool), saturation_rad=sat,
                                       delay_steps=delay_steps, rate_limit_rad_per_s=rate))
    b.Connect(w, tick.GetInputPort("wrench"))
    b.Connect(q, tick.GetInputPort("q"))
    out = tick.add_outputs(b)
    diagram = b.Build()
    sim = Simulator(diagram)
    ctx = sim.get_mutable_context()
    moved = nan_held = 0
    for k in range(1, 60):
        sim.AdvanceTo(k * T + 0.3 * T)
        pairs = [(zw.get_output_port(), out["wrench_sampled"]),
                 (zq.get_output_port(), out["q_sampled"]),
                 (grav.get_output_port(), out["process_wrench"]),
                 (pred.GetOutputPort("dq"), out["dq"]),
                 (corr.get_output_port(), out["correction"])]
        for a, b_ in pairs:
            x = a.Eval(a.get_system().GetMyContextFromRoot(ctx))
            y = b_.Eval(b_.get_system().GetMyContextFromRoot(ctx))
            np.testing.assert_array_equal(x, y)  # bit for bit, NaN where NaN
        c = tick.held(tick.GetMyContextFromRoot(ctx), "correction")
        moved += bool(np.any(c != 0))
        dq = tick.held(tick.GetMyContextFromRoot(ctx), "dq")
        nan_held += bool(np.isnan(dq).any())
    assert moved > 30 and nan_held >= 2  # the correction moved, and NaN went through (and was held off)
    # the correction saturates: it never passes the saturation
    assert np.all(np.abs(tick.held(tick.GetMyContextFromRoot(ctx), "correction")) <= sat)


def test_set_sample_is_what_the_holds_would_give(robot):
    tool = robot.payload.tool_point_m
    cal = PayloadCalibration(mass_kg=40.0, com_mm=[5.0, -3.0, 180.0])
    kin = DeflectionPredictor(robot.dh, robot.joint_stiffness_Nm_per_rad, tool)
    tick = CompensatorTick(period_s=T, calibration=cal, kinematics=kin, deflection=DeflectionModel(kin, tool),
                           saturation_rad=1e-3, delay_steps=1, rate_limit_rad_per_s=0.1)
    grav = GravityRemoval(calibration=cal, kinematics=kin)
    pred = DeflectionPrediction(predictor=kin, tool_m=tool)
    w = np.array([100.0, -50.0, 400.0, 3.0, -2.0, 1.0])
    ctx = tick.CreateDefaultContext()
    tick.set_sample(ctx, w, Q0)
    gc, pc = grav.CreateDefaultContext(), pred.CreateDefaultContext()
    grav.GetInputPort("wrench").FixValue(gc, w)
    grav.GetInputPort("q").FixValue(gc, Q0)
    p = grav.get_output_port().Eval(gc)
    pred.GetInputPort("process_wrench").FixValue(pc, p)
    pred.GetInputPort("q").FixValue(pc, Q0)
    np.testing.assert_array_equal(tick.held(ctx, "process_wrench"), p)
    np.testing.assert_array_equal(tick.held(ctx, "dq"), pred.GetOutputPort("dq").Eval(pc))


def test_the_hysteretic_play_law_keeps_each_gears_place_in_its_gap_in_the_context(robot):
    """DeflectionPrediction with the hysteretic law (play b on joint 2, the
    fallback friction, 18 N*m): at the touch-off the gear carries -5 N*m
    (on the - flank); under a process load, a gear torque of +10 N*m (a
    reversal below the friction) leaves the prediction on that flank; +30
    N*m carries it across (2b more); back at +10 N*m it stays across.  The
    place in the gap is the context's state: a second context, never
    loaded across, is unmoved."""
    tool = robot.payload.tool_point_m
    kin = DeflectionPredictor(robot.dh, robot.joint_stiffness_Nm_per_rad, tool)
    b2, c2 = 1e-4, 1.0 / robot.joint_stiffness_Nm_per_rad[1]
    pred = DeflectionPrediction(predictor=kin, tool_m=tool, lost_motion_rad=[0.0, b2, 0.0, 0.0, 0.0, 0.0],
                                law="hysteretic", period_s=T)
    assert pred.model.friction[1] == pytest.approx(0.015 * robot.joint_stiffness_Nm_per_rad[1] * 1.1e-3)
    w = np.array([200.0, -100.0, 300.0, 5.0, -3.0, 2.0])
    tau_p = np.asarray(pred.model.process_torque(w, Q0))

    def run(sim, process, carried2, until):
        """Joint 2's dq at ``until`` s with the process wrench ``process`` and
        the static torque set so that the gear carries ``carried2`` (N*m)."""
        ctx = sim.get_mutable_context()
        tp = tau_p if process is w else np.zeros(6)
        static = tp.copy()
        static[1] += carried2
        pred.GetInputPort("process_wrench").FixValue(ctx, process)
        pred.GetInputPort("static_torque").FixValue(ctx, static)
        sim.AdvanceTo(until)
        return pred.GetOutputPort("dq").Eval(ctx)[1]

    def expected(carried2, across):
        """held twist + the touch-off's place (-b) - the twist now (on the +
        flank across: b + c tau; still on the - flank, not pressed: -b)."""
        return c2 * (tau_p[1] + carried2) - b2 - ((b2 + c2 * carried2) if across else -b2)

    sims = []
    for _ in range(2):
        ctx = pred.CreateDefaultContext()
        pred.GetInputPort("q").FixValue(ctx, Q0)
        sim = Simulator(pred, ctx)
        assert run(sim, np.zeros(6), -5.0, 2 * T) == pytest.approx(0.0, abs=1e-15)  # the touch-off
        sims.append(sim)
    a, other = sims
    assert run(a, w, 10.0, 4 * T) == pytest.approx(expected(10.0, False), abs=1e-12)
    assert run(a, w, 30.0, 6 * T) == pytest.approx(expected(30.0, True), abs=1e-12)
    assert run(a, w, 10.0, 8 * T) == pytest.approx(expected(10.0, True), abs=1e-12)
    assert expected(10.0, False) - expected(10.0, True) == pytest.approx(2 * b2 + c2 * 10.0)
    assert run(other, w, 10.0, 8 * T) == pytest.approx(expected(10.0, False), abs=1e-12)
