"""Each block of the closed loop alone: fixed inputs, CalcOutput / one
discrete update, assert on values (the drake_pip system-test style)."""

import numpy as np
import pytest
from pydrake.common.value import AbstractValue
from pydrake.multibody.math import SpatialForce
from pydrake.multibody.tree import BodyIndex

from robstiff_drake.model import kinematics as kin
from robstiff_drake.model import stiffness as st
from robstiff_drake.model.milling import Cutter, CuttingCoefficients, MillingForceModel, Workpiece
from robstiff_drake.model.path import PlannedPath
from robstiff_drake.model.payload import PayloadCalibration, payload_wrench
from robstiff_drake.model.realtime import DeflectionPredictor
from robstiff_drake.model.wrench_frames import sensor_to_tool_base
from robstiff_drake.systems.deflection_prediction import DeflectionPrediction
from robstiff_drake.systems.force_filter import (
    filter_system,
    group_delay_s,
    lowpass_coefficients,
    revolution_average_coefficients,
    steady_state,
)
from robstiff_drake.systems.gravity_removal import GravityRemoval
from robstiff_drake.systems.milling_force import MillingForceSource
from robstiff_drake.systems.reference_correction import RateLimitedCorrection
from robstiff_drake.systems.wrist_sensor import WrenchGuard, WristForceSensor, add_random_inputs

Q = np.deg2rad([5.0, 15.0, 20.0, 10.0, 50.0, -20.0])


def update(system, context):
    """Run the system's periodic discrete update once; return its new discrete state(s)."""
    state = system.EvalUniquePeriodicDiscreteUpdate(context)
    return [state.get_vector(i).CopyToVector() for i in range(state.num_groups())]


def test_milling_force_source_outputs(robot):
    """Averaged and tooth-resolved: the held wrench is the model's, the spatial
    force is that wrench on the spindle at the tool point, and in tooth mode
    the sensor's ripple is the instantaneous minus the held wrench (sensor
    frame)."""
    from pydrake.systems.analysis import Simulator

    tool = robot.payload.tool_point_m
    cutter = Cutter(0.075, 6, 3600)
    model = MillingForceModel(cutter, CuttingCoefficients(631, 99, 273, 13, 10, 2.8), 0.02)
    kinematics = DeflectionPredictor(robot.dh, robot.joint_stiffness_Nm_per_rad, tool)
    R, p = kinematics.flange_rotation_and_tool_point(Q)
    wp = Workpiece.from_boxes([[p[0] - 0.05, p[0] + 0.1, p[1] - 0.02, p[1] + 0.03, p[2] + 0.003]])
    path = PlannedPath([p - [0.1, 0, 0], p + [0.1, 0, 0]], 0.02)
    for mode in ("averaged", "tooth"):
        src = MillingForceSource(force_model=model, workpiece=wp, path=path, kinematics=kinematics, tool_point_m=tool,
                                 period_s=0.002, spindle_body_index=BodyIndex(7), mode=mode)
        sim = Simulator(src)
        ctx = sim.get_mutable_context()
        src.get_input_port().FixValue(ctx, Q)
        # the tool came along the path at 0.02 m/s: its history (time, arc length) before t = 0
        n = src._n_hist
        back = 0.002 * np.arange(n, 0, -1)
        src.set_progress(ctx, [1.0, 0.0, 0.02, 0.0], np.c_[-back, 0.1 - 0.02 * back, np.zeros(n)].ravel())  # its feed
        sim.AdvanceTo(1e-4)  # the update at t = 0 has run
        held = ctx.get_discrete_state(int(src._w)).CopyToVector()  # the period's wrench
        expected = (model.average_wrench(p, [1, 0], wp) if mode == "averaged" else
                    model.tooth_wrench(0.002 * np.arange(len(src._sub_t)) / len(src._sub_t), p, [1, 0], wp).reshape(-1)
                    / len(src._sub_t))
        np.testing.assert_allclose(held, expected, rtol=1e-12, atol=1e-9)
        assert np.linalg.norm(held[:3]) > 100  # the cutter is in the material
        (force,) = src.GetOutputPort("spatial_force").Eval(ctx)
        assert int(force.body_index) == 7
        np.testing.assert_allclose(force.p_BoBq_B, tool)
        np.testing.assert_allclose(np.concatenate([force.F_Bq_W.translational(), force.F_Bq_W.rotational()]), held)
        w = src.GetOutputPort("wrench").Eval(ctx)
        if mode == "averaged":
            np.testing.assert_array_equal(w, held)
        else:
            np.testing.assert_allclose(w, model.tooth_wrench(1e-4, p, [1, 0], wp), rtol=1e-12, atol=1e-9)
            ripple = src.GetOutputPort("ripple_sensor").Eval(ctx)
            np.testing.assert_allclose(sensor_to_tool_base(ripple, R, tool), w - held, atol=1e-9)


def _sensor(**kw):
    sensor = WristForceSensor(**kw)
    ctx = sensor.CreateDefaultContext()
    return sensor, ctx


def test_wrist_sensor_reads_the_weld_plus_bias():
    sensor, ctx = _sensor(weld_joint_index=2, rate_hz=1000, force_bias_N=[1, 2, 3], torque_bias_Nm=[0.1, 0.2, 0.3])
    zero = SpatialForce(np.zeros(3), np.zeros(3))
    reactions = [zero, zero, SpatialForce([1.0, -2.0, 0.5], [10.0, 20.0, -392.0])]
    sensor.GetInputPort("reaction_forces").FixValue(ctx, AbstractValue.Make(reactions))
    assert not sensor.HasInputPort("gaussian") and not sensor.HasInputPort("uniform")  # no noise: no random inputs
    (w,) = update(sensor, ctx)
    # what the payload (with the load on it) exerts on the sensor: minus what the flange exerts on it
    np.testing.assert_allclose(w, [-10 + 1, -20 + 2, 392 + 3, -1 + 0.1, 2 + 0.2, -0.5 + 0.3])


def test_wrist_sensor_noise_dropouts_and_spikes_come_from_its_random_inputs():
    sensor, ctx = _sensor(weld_joint_index=0, rate_hz=1000, noise_N=2.0, noise_Nm=0.2, dropout_probability=0.3,
                          spike_probability=0.5, spike_N=1000.0)
    sensor.GetInputPort("reaction_forces").FixValue(ctx, AbstractValue.Make([SpatialForce(np.zeros(3), np.zeros(3))]))
    g = np.array([1.0, -1.0, 0.5, 2.0, -2.0, 0.0])
    sensor.GetInputPort("gaussian").FixValue(ctx, g)
    sensor.GetInputPort("uniform").FixValue(ctx, [0.5, 0.9, 0.0])  # no dropout (0.5 > 0.3), no spike
    np.testing.assert_allclose(update(sensor, ctx)[0], g * [2, 2, 2, 0.2, 0.2, 0.2])
    sensor.GetInputPort("uniform").FixValue(ctx, [0.1, 0.9, 0.0])  # a dropout
    assert np.all(np.isnan(update(sensor, ctx)[0]))
    sensor.GetInputPort("uniform").FixValue(ctx, [0.5, 0.1, 0.7])  # a spike on force axis 1 (0.7 * 6 = 4: -y)
    np.testing.assert_allclose(update(sensor, ctx)[0], g * [2, 2, 2, 0.2, 0.2, 0.2] + [0, -1000.0, 0, 0, 0, 0])


def test_wrist_sensor_noise_statistics_in_a_simulation():
    """Through Drake's RandomSources, seeded by the context's generator: the
    noise has the set sigma and the dropouts their rate."""
    from pydrake.common import RandomGenerator
    from pydrake.systems.analysis import Simulator
    from pydrake.systems.framework import DiagramBuilder
    from pydrake.systems.primitives import ConstantValueSource, LogVectorOutput

    builder = DiagramBuilder()
    sensor = builder.AddSystem(WristForceSensor(weld_joint_index=0, rate_hz=1000, noise_N=2.0, noise_Nm=0.2,
                                                dropout_probability=0.3))
    src = builder.AddSystem(ConstantValueSource(AbstractValue.Make([SpatialForce(np.zeros(3), np.zeros(3))])))
    builder.Connect(src.get_output_port(), sensor.GetInputPort("reaction_forces"))
    add_random_inputs(builder, sensor)
    log = LogVectorOutput(sensor.get_output_port(), builder, 1e-3)
    diagram = builder.Build()
    sim = Simulator(diagram)
    diagram.SetRandomContext(sim.get_mutable_context(), RandomGenerator(4))
    sim.AdvanceTo(3.0)
    samples = log.FindLog(sim.get_context()).data().T[2:]
    dropped = np.isnan(samples).all(axis=1)
    assert 0.25 < dropped.mean() < 0.35
    np.testing.assert_allclose(samples[~dropped].std(axis=0), [2, 2, 2, 0.2, 0.2, 0.2], rtol=0.1)


def test_guard_holds_last_good_value():
    guard = WrenchGuard(rate_hz=1000, max_jump_N=500, initial_wrench=np.ones(6))
    ctx = guard.CreateDefaultContext()
    for bad in ([np.nan] * 6, [np.inf, 0, 0, 0, 0, 0], [1 + 800.0, 1, 1, 1, 1, 1]):
        guard.get_input_port().FixValue(ctx, bad)
        held, count, _ = update(guard, ctx)
        np.testing.assert_array_equal(held, np.ones(6))
        ctx.SetDiscreteState(1, count)
    assert ctx.get_discrete_state(1).value()[0] == 3
    guard.get_input_port().FixValue(ctx, [50.0, 1, 1, 1, 1, 1])
    held, _, _ = update(guard, ctx)
    np.testing.assert_array_equal(held, [50.0, 1, 1, 1, 1, 1])


def test_guard_rearms_after_a_genuine_step():
    """A step of the force beyond max_jump_N that stays: the guard takes it
    after rejecting every sample for 20 ms, as the compensator process does
    (it latched forever before); a one-sample spike is still rejected."""
    guard = WrenchGuard(rate_hz=1000, max_jump_N=500, initial_wrench=np.zeros(6))
    ctx = guard.CreateDefaultContext()
    step = [800.0, 0, 0, 0, 0, 0]
    held_seen = []
    for k in range(40):
        guard.get_input_port().FixValue(ctx, step if k != 0 else [5000.0, 0, 0, 0, 0, 0])
        for i, v in enumerate(update(guard, ctx)):
            ctx.SetDiscreteState(i, v)
        held_seen.append(ctx.get_discrete_state(0).value()[0])
    assert held_seen[0] == 0.0 and held_seen[19] == 0.0  # the spike and the first 20 ms of the step: held
    assert held_seen[-1] == 800.0  # then the new level


@pytest.mark.parametrize("kind", ["lowpass", "average"])
def test_force_filter(kind):
    rate = 1000.0
    b, a = lowpass_coefficients(10.0, rate) if kind == "lowpass" else revolution_average_coefficients(3600, rate)
    filt = filter_system(b, a, rate)
    ctx = filt.CreateDefaultContext()
    u = np.array([100.0, -50, 20, 1, 2, 3])
    ctx.SetDiscreteState(steady_state(filt, u))
    filt.get_input_port().FixValue(ctx, u)
    np.testing.assert_allclose(filt.get_output_port().Eval(ctx), u, rtol=1e-9)  # unit DC gain, settled
    # a sine at the tooth-pass frequency (360 Hz): the 10 Hz low-pass attenuates it by
    # more than 50 dB; the revolution average (17 samples at 1 kHz for a 16.7 ms
    # revolution: not a whole number of samples) leaves a few per cent
    ctx.SetDiscreteState(np.zeros(filt.A().shape[0]))
    out = []
    for k in range(2000):
        filt.get_input_port().FixValue(ctx, np.full(6, np.sin(2 * np.pi * 360.0 * k / rate)))
        out.append(filt.get_output_port().Eval(ctx)[0])
        ctx.SetDiscreteState(update(filt, ctx)[0])
    assert np.max(np.abs(out[1000:])) < (3e-3 if kind == "lowpass" else 0.03)
    assert group_delay_s(b, a, rate) > 0


def test_gravity_removal_cancels_the_payload(robot, rng):
    cal = PayloadCalibration(mass_kg=40.0, com_mm=[5.0, -3.0, 180.0], force_bias_N=[2, -1, 3],
                             torque_bias_Nm=[0.1, 0.0, -0.2])
    kinematics = DeflectionPredictor(robot.dh, robot.joint_stiffness_Nm_per_rad)
    sys_ = GravityRemoval(calibration=cal, kinematics=kinematics)
    ctx = sys_.CreateDefaultContext()
    for q in rng.uniform(robot.q_lower_rad, robot.q_upper_rad, size=(10, 6)):
        R = kin.frames(robot.dh, q)[6, :3, :3]
        process = np.array([120.0, -40.0, 10.0, 1.0, -2.0, 3.0])
        reading = payload_wrench(R, cal) + process
        assert np.linalg.norm(payload_wrench(R, cal)[:3] - [2, -1, 3]) == pytest.approx(40 * 9.81, rel=1e-12)
        f = 40.0 * R.T @ [0.0, 0.0, -9.81]  # the weight in the sensor frame, by hand
        np.testing.assert_allclose(payload_wrench(R, cal), np.concatenate(
            [f + [2, -1, 3], np.cross([0.005, -0.003, 0.18], f) + [0.1, 0.0, -0.2]]), atol=1e-9)
        sys_.GetInputPort("wrench").FixValue(ctx, reading)
        sys_.GetInputPort("q").FixValue(ctx, q)
        np.testing.assert_allclose(sys_.get_output_port().Eval(ctx), process, atol=1e-9)


def test_deflection_prediction_matches_the_model(robot):
    tool = robot.payload.tool_point_m
    k_model = robot.joint_stiffness_Nm_per_rad * 1.1  # the predictor's own model
    pred = DeflectionPredictor(robot.dh, k_model, tool)
    sys_ = DeflectionPrediction(predictor=pred, tool_m=tool)
    ctx = sys_.CreateDefaultContext()
    w_tool = np.array([-300.0, 250.0, 50.0, 1.0, -2.0, 15.0])  # at the tool, base frame
    R = kin.frames(robot.dh, Q)[6, :3, :3]
    f_s = R.T @ w_tool[:3]
    w_sensor = np.concatenate([f_s, R.T @ w_tool[3:] + np.cross(tool, f_s)])
    sys_.GetInputPort("process_wrench").FixValue(ctx, w_sensor)
    sys_.GetInputPort("q").FixValue(ctx, Q)
    np.testing.assert_allclose(sys_.GetOutputPort("tool_wrench").Eval(ctx), w_tool, atol=1e-9)
    dq_ref, _ = st.deflection_conventional(kin.jacobian(robot.dh, Q, tool), k_model, w_tool)
    np.testing.assert_allclose(sys_.GetOutputPort("dq").Eval(ctx), dq_ref, rtol=1e-10)


def test_correction_rate_limit_and_nan():
    corr = RateLimitedCorrection(period_s=0.004, rate_limit_rad_per_s=0.1)
    ctx = corr.CreateDefaultContext()
    corr.get_input_port().FixValue(ctx, [1e-3, -1e-3, 1e-5, 0, 0, 0])
    (x,) = update(corr, ctx)
    np.testing.assert_allclose(x, [-4e-4, 4e-4, -1e-5, 0, 0, 0])  # 0.1 rad/s * 4 ms = 0.4 mrad per step
    ctx.SetDiscreteState(x)
    corr.get_input_port().FixValue(ctx, [np.nan] * 6)
    (y,) = update(corr, ctx)
    np.testing.assert_array_equal(y, x)


def test_the_sensor_reads_the_tooth_ripple_from_the_sources_table_as_its_port_gives_it(robot):
    """Tooth mode: at every 1 kHz sensor instant the milling source's held
    table (instant_table, instant_times: no call into Python) gives the
    ripple_sensor port's value exactly; at an instant it did not tabulate,
    None (the sensor then reads the port)."""
    from pydrake.systems.analysis import Simulator

    tool = robot.payload.tool_point_m
    model = MillingForceModel(Cutter(0.075, 6, 3600), CuttingCoefficients(631, 99, 273, 13, 10, 2.8), 0.02)
    kinematics = DeflectionPredictor(robot.dh, robot.joint_stiffness_Nm_per_rad, tool)
    _, p = kinematics.flange_rotation_and_tool_point(Q)
    wp = Workpiece.from_boxes([[p[0] - 0.05, p[0] + 0.1, p[1] - 0.02, p[1] + 0.03, p[2] + 0.003]])
    path = PlannedPath([p - [0.1, 0, 0], p + [0.1, 0, 0]], 0.02)
    src = MillingForceSource(force_model=model, workpiece=wp, path=path, kinematics=kinematics, tool_point_m=tool,
                             period_s=0.002, spindle_body_index=BodyIndex(7), mode="tooth", sensor_period_s=0.001)
    sim = Simulator(src)
    ctx = sim.get_mutable_context()
    src.get_input_port().FixValue(ctx, Q)
    n = src._n_hist  # the tool came along the path at 0.02 m/s (its feed makes the chip)
    back = 0.002 * np.arange(n, 0, -1)
    src.set_progress(ctx, [1.0, 0.0, 0.02, 0.0], np.c_[-back, 0.1 - 0.02 * back, np.zeros(n)].ravel())
    hits = 0
    for k in range(1, 12):
        sim.AdvanceTo(k * 0.001)
        table = src.GetOutputPort("instant_table").Eval(ctx).tolist()
        times = src.GetOutputPort("instant_times").Eval(ctx).tolist()
        got = MillingForceSource.ripple_from_table(ctx.get_time(), table, times)
        want = src.GetOutputPort("ripple_sensor").Eval(ctx).tolist()
        assert got == want  # (the same numbers, bit for bit)
        hits += any(v != 0.0 for v in got)
        assert MillingForceSource.ripple_from_table(ctx.get_time() + 0.0005, table, times) is None
    assert hits >= 8  # (the cutter is in the material: a ripple to read)
