"""The station's physics: gears that carry gravity and the cut, the robot
controller's gravity model and touch-off, the motor-side servo and its lag,
the step's stability, the cutting load through the sensor's weld, lost
motion only where the total torque changes sign, the compensator reading
the motor side, and the sensor's randomness in the Context."""

import copy
from pathlib import Path

import numpy as np
import pytest
from arm_helpers import add_constant_tool_force
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder, LeafSystem
from pydrake.systems.primitives import ConstantVectorSource
from scipy import signal

from robstiff_drake.diagrams.experiment import run_cut
from robstiff_drake.diagrams.loop_prediction import gravity_stiffness
from robstiff_drake.diagrams.milling_cell import build_milling_cell, make_simulator
from robstiff_drake.diagrams.scenario import load_scenario
from robstiff_drake.diagrams.station import (
    add_compliant_arm,
    gravity_holding_torque,
    servo_parameters,
    set_drives_at_rest,
    spring_step_is_stable,
    static_link_angles,
)
from robstiff_drake.model import ik, transmission
from robstiff_drake.model import kinematics as kin
from robstiff_drake.model.payload import PayloadCalibration, payload_wrench
from robstiff_drake.model.wrench_frames import to_sensor_frame
from robstiff_drake.systems.wrist_sensor import WristForceSensor, add_random_inputs

DATA = Path(__file__).parent / "data"
SHORT = DATA / "short_block.yaml"


@pytest.fixture(scope="module")
def scenario():
    return load_scenario(SHORT)


def reference_pose(robot):
    return ik.solve_ik(robot.dh, ik.tool_down_pose(robot.workspace.reference_tool_point_m), robot.payload.tool_point_m)


class StepCommand(LeafSystem):
    """q0 before t0, q0 + step from t0 on."""

    def __init__(self, q0, step, t0):
        super().__init__()
        self.DeclareVectorOutputPort("q", 6, lambda c, o: o.SetFromVector(q0 + (c.get_time() >= t0) * step))


def arm_at_rest(sc, robot, q_cmd, *, k=None, force=None, command=None, damping=None, check_stability=True,
                lost_motion_rad=None):
    """(simulator, arm dict) of the compliant arm commanded to ``q_cmd`` (or
    by ``command``, a system), motors and links at rest on it, optionally a
    constant spatial force on the spindle at the tool point (base frame)."""
    k = robot.joint_stiffness_Nm_per_rad if k is None else np.asarray(k, dtype=float)
    builder = DiagramBuilder()
    arm = add_compliant_arm(builder, robot=robot, plant_config=sc.plant_config, joint_stiffness_Nm_per_rad=k,
                            damping_ratio=sc.plant.damping_ratio if damping is None else damping, q_modes_rad=q_cmd,
                            servo=servo_parameters(sc), interpolator_period_s=sc.servo.interpolator_period_ms / 1e3,
                            check_stability=check_stability,
                            lost_motion_rad=None if lost_motion_rad is None else list(lost_motion_rad))
    plant = arm["plant"]
    src = builder.AddSystem(command or ConstantVectorSource(q_cmd))
    vel = builder.AddSystem(ConstantVectorSource(np.zeros(6)))
    builder.Connect(src.get_output_port(), arm["position_command"])
    builder.Connect(vel.get_output_port(), arm["velocity_command"])
    if force is not None:
        add_constant_tool_force(builder, plant, robot, force)
    sim = Simulator(builder.Build())
    root = sim.get_mutable_context()
    ctrl = arm["controller_plant"]
    theta = q_cmd + gravity_holding_torque(ctrl, q_cmd) / k  # the controller's gravity model (calibrated: true k)
    q = static_link_angles(ctrl, theta, 1.0 / k, lost_motion_rad)
    plant.SetPositions(plant.GetMyMutableContextFromRoot(root), q)
    set_drives_at_rest(arm, root, theta)
    sim.Initialize()
    return sim, arm


def test_the_gears_carry_gravity_and_the_controller_puts_the_tool_back(scenario, robot):
    """At rest under gravity alone the gears twist by K^-1 tau_g (the arm's
    weight loads them), and the controller's gravity model puts the tool
    where it was commanded: within 0.01 mm, against several millimetres of
    sag without it."""
    q0 = reference_pose(robot)
    sim, arm = arm_at_rest(scenario, robot, q0)
    sim.AdvanceTo(1.0)
    root = sim.get_context()
    plant = arm["plant"]
    q = plant.GetPositions(plant.GetMyContextFromRoot(root))
    theta = arm["servo"].get_output_port().Eval(arm["servo"].GetMyContextFromRoot(root))[:6]
    hold = gravity_holding_torque(arm["controller_plant"], q)
    np.testing.assert_allclose(theta - q, hold / robot.joint_stiffness_Nm_per_rad, atol=1e-9)
    assert abs(hold[1]) > 1000.0  # joint 2 holds kN*m: the gear spring carries the arm
    tool = robot.payload.tool_point_m
    error = np.linalg.norm(kin.tool_position(robot.dh, q, tool) - kin.tool_position(robot.dh, q0, tool))
    assert error < 1e-5
    sag = np.linalg.norm(kin.tool_position(robot.dh, q0 - hold / robot.joint_stiffness_Nm_per_rad, tool)
                         - kin.tool_position(robot.dh, q0, tool))
    assert sag > 2e-3  # without the gravity model the tool would sit millimetres low


def test_static_deflection_under_a_tool_force(scenario, robot):
    """A constant force at the tool point: the arm settles where the gears
    and the weight's own stiffness put it, dq = (K - G)^-1 J^T F (G = d
    tau_gravity / dq), to 1e-7 m; the conventional model J C J^T F is within
    the few-tenths-of-a-percent the weight adds."""
    q0 = reference_pose(robot)
    F = np.array([-300.0, 250.0, 50.0])
    sim, arm = arm_at_rest(scenario, robot, q0, force=F, damping=0.3)
    sim.AdvanceTo(6.0)
    plant = arm["plant"]
    q = plant.GetPositions(plant.GetMyContextFromRoot(sim.get_context()))
    tool = robot.payload.tool_point_m
    dp = kin.tool_position(robot.dh, q, tool) - kin.tool_position(robot.dh, q0, tool)
    ctrl = arm["controller_plant"]
    G = gravity_stiffness(ctrl, ctrl.CreateDefaultContext(), q0)
    J = kin.jacobian(robot.dh, q0, tool)
    dq = np.linalg.solve(np.diag(robot.joint_stiffness_Nm_per_rad) - G, J.T @ np.concatenate([F, np.zeros(3)]))
    assert np.linalg.norm(dp) > 5e-4  # about a millimetre
    np.testing.assert_allclose(dp, J[:3] @ dq, atol=2e-6)  # the first-order prediction (fk nonlinearity ~1 um)
    conventional = J[:3] @ (J.T @ np.concatenate([F, np.zeros(3)]) / robot.joint_stiffness_Nm_per_rad)
    assert np.linalg.norm(dp - conventional) < 0.01 * np.linalg.norm(dp)


def test_step_stability_criterion_is_the_recursion(rng):
    """spring_step_is_stable against the step it describes, iterated: symplectic
    Euler for the spring, implicit stiffness-proportional damping."""
    for _ in range(300):
        w = rng.uniform(10.0, 2000.0)  # rad/s
        h = rng.uniform(1e-4, 1e-2)
        beta = rng.uniform(0.0, 0.01)
        q, v, peak = 1.0, 0.0, 0.0
        for k in range(3000):
            v = (v - h * w * w * q) / (1.0 + beta * w * w * h)
            q += h * v
            if not abs(q) < 1e6:
                peak = np.inf
                break
            if k > 2000:
                peak = max(peak, abs(q))
        criterion = spring_step_is_stable([w / (2 * np.pi)], beta, h)
        margin = h * h * w * w - (4.0 + 2.0 * beta * w * w * h)
        if abs(margin) > 0.05:
            assert criterion == (peak < 1.0), (w, h, beta, peak)


@pytest.mark.parametrize("zeta, stable", [(0.01, False), (0.025, True)])
def test_plant_step_is_stable_where_the_criterion_says(scenario, robot, zeta, stable):
    """The criterion is the Drake plant's: at a 4 ms step its joint damping is
    implicit (or the 2.5 % case would diverge too) and its gear spring
    explicit (or the 1 % case would not)."""
    sc = copy.deepcopy(scenario)
    sc.plant_config.time_step = 0.004
    q0 = reference_pose(robot)
    sim, arm = arm_at_rest(sc, robot, q0, damping=zeta, check_stability=False)
    h = 0.004
    assert spring_step_is_stable(arm["natural_frequencies_hz"], arm["beta_s"], h) == stable
    assert arm["beta_s"] < h / 2
    plant = arm["plant"]
    ctx = plant.GetMyMutableContextFromRoot(sim.get_mutable_context())
    q_rest = plant.GetPositions(ctx).copy()
    plant.SetPositions(ctx, q_rest + 1e-4)  # every joint off by 0.1 mrad: all modes excited
    try:
        sim.AdvanceTo(1.0)
        dev = np.abs(plant.GetPositions(ctx) - q_rest).max()
    except RuntimeError:
        dev = np.inf
    if stable:
        assert dev < 1e-4
    else:
        assert not dev < 1e-2


@pytest.mark.parametrize("step_s", [0.002, 0.004])  # blocks apart; the dead time inside the servo's system
def test_the_servo_delays_a_correction_as_its_model_says(scenario, robot, step_s):
    """A 1 mrad step of the joint command without velocity feed-forward (a
    correction): the motor follows the interpolator's dead time, one plant
    step (the servo's own discrete update) and the position loop's
    second-order response, to 1 % of the step, against the continuous
    transfer function (scipy); the station reports that lag."""
    q0 = reference_pose(robot)
    scenario = copy.deepcopy(scenario)
    scenario.plant_config.time_step = step_s
    t0, step = 0.1005, np.full(6, 1e-3)  # between ticks: no tie at the step
    sim, arm = arm_at_rest(scenario, robot, q0, command=StepCommand(q0, step, t0))
    servo = servo_parameters(scenario)
    h, T_i = scenario.plant_config.time_step, scenario.servo.interpolator_period_ms / 1e3
    ticks = np.arange(0.104, 0.3, h)
    ts = ticks + h / 2  # between ticks: the state holds what the update at the tick computed
    got = []
    for t in ts:
        sim.AdvanceTo(t)
        got.append(arm["servo"].get_output_port().Eval(arm["servo"].GetMyContextFromRoot(sim.get_context()))[1])
    base = q0[1] + gravity_holding_torque(arm["controller_plant"], q0)[1] / robot.joint_stiffness_Nm_per_rad[1]
    response = (np.array(got) - base) / step[1]
    wv, kp = servo.omega_v, servo.position_gain_per_s
    # the command is sampled at the interpolator's ticks (4 ms) and held: the
    # step reaches the drives at the first tick after it plus the dead time
    start = np.ceil(t0 / T_i) * T_i + servo.interpolator_delay_s + h  # first servo update that sees the step
    tau = ticks - start + h  # the discrete servo's state at a tick is the response one step after its input
    grid = np.linspace(0.0, tau.max(), 4001)
    _, unit = signal.step(([wv * kp], [1.0, wv, wv * kp]), T=grid)
    ref = np.where(tau > 0, np.interp(tau, grid, unit), 0.0)
    # the gravity model moves with the command too (theta_ref = q + C g(q)): its change is 1e-3 of the step
    np.testing.assert_allclose(response, ref, atol=0.01)
    cell = build_milling_cell(scenario, robot, compensation=True)
    assert cell.station.command_lag_s == pytest.approx(servo.interpolator_delay_s + 1.0 / kp + h)


def test_the_sensor_feels_the_cut_through_the_weld(scenario, robot):
    """The cutting load is applied to the spindle; the sensor across the
    flange-spindle weld reads the payload's weight plus that load (sensor
    frame, moment about its origin), at rest, to 1e-6 N."""
    q0 = reference_pose(robot)
    F = np.array([-300.0, 250.0, 50.0])
    builder = DiagramBuilder()
    arm = add_compliant_arm(builder, robot=robot, plant_config=scenario.plant_config,
                            joint_stiffness_Nm_per_rad=robot.joint_stiffness_Nm_per_rad, damping_ratio=0.3,
                            q_modes_rad=q0, servo=servo_parameters(scenario), interpolator_period_s=0.004)
    plant = arm["plant"]
    for port, value in ((arm["position_command"], q0), (arm["velocity_command"], np.zeros(6))):
        builder.Connect(builder.AddSystem(ConstantVectorSource(value)).get_output_port(), port)
    add_constant_tool_force(builder, plant, robot, F)
    sensor = builder.AddSystem(WristForceSensor(weld_joint_index=plant.GetJointByName("sensor_weld").index(),
                                                rate_hz=250.0))
    builder.Connect(plant.get_reaction_forces_output_port(), sensor.GetInputPort("reaction_forces"))
    add_random_inputs(builder, sensor)
    sim = Simulator(builder.Build())
    plant.SetPositions(plant.GetMyMutableContextFromRoot(sim.get_mutable_context()), q0)
    sim.AdvanceTo(6.0)
    q = plant.GetPositions(plant.GetMyContextFromRoot(sim.get_context()))
    reading = sensor.get_output_port().Eval(sensor.GetMyContextFromRoot(sim.get_context()))
    R6 = kin.frames(robot.dh, q)[6, :3, :3]
    weight = payload_wrench(R6, PayloadCalibration(mass_kg=robot.payload.mass_kg,
                                                   com_mm=list(robot.payload.com_m * 1e3)))
    load = to_sensor_frame(R6.ravel().tolist(), robot.payload.tool_point_m.tolist(), list(F) + [0.0, 0.0, 0.0])
    np.testing.assert_allclose(reading, weight + np.array(load), atol=1e-6)


def test_the_compensators_lost_motion_law_is_the_gears(scenario, robot):
    """With lost motion (40 urad) in joint 2 at a pose where its gear holds
    about +155 N*m of the arm's weight, a tool force of -300 N and +300 N
    along z moves joint 2 by different amounts (the play is taken up one way
    only); the compensator's model (model/compensator.DeflectionModel's law,
    transmission.static_deflection with the gravity-holding torque) predicts
    what Drake's plant does, to 2 %."""
    b = np.array([0.0, 4e-5, 0.0, 0.0, 0.0, 0.0])
    sc = copy.deepcopy(scenario)
    sc.plant.lost_motion_rad = list(b)
    tool = robot.payload.tool_point_m
    q0 = ik.solve_ik(robot.dh, ik.tool_down_pose(np.array([1.075, 0.0, 0.7]), 0.0), tool)
    J = kin.jacobian(robot.dh, q0, tool)
    c = 1.0 / robot.joint_stiffness_Nm_per_rad
    moved = {}
    for fz in (0.0, -300.0, 300.0):
        sim, arm = arm_at_rest(sc, robot, q0, force=[0.0, 0.0, fz], damping=0.5, lost_motion_rad=b)
        sim.AdvanceTo(4.0)
        plant = arm["plant"]
        moved[fz] = plant.GetPositions(plant.GetMyContextFromRoot(sim.get_context()))
    hold = gravity_holding_torque(arm["controller_plant"], q0)
    assert 100.0 < hold[1] < 250.0, hold
    for fz in (-300.0, 300.0):
        tau = J.T @ np.r_[0.0, 0.0, fz, 0.0, 0.0, 0.0]
        station = (moved[fz] - moved[0.0])[1]
        model = transmission.static_deflection(hold, tau, c, b)[1]
        assert abs(model - station) < 0.02 * abs(station), (fz, station, model)
    # the play shows: the two directions differ by about 2 b
    up, down = (moved[-300.0] - moved[0.0])[1], (moved[300.0] - moved[0.0])[1]
    assert abs(up + down) > b[1]


def test_lost_motion_acts_only_where_the_total_torque_changes_sign(scenario, robot):
    """Lost motion of 40 urad in joints 2 and 3, whose gears carry the arm's
    weight (kN*m of one sign against a few hundred N*m of cut: they never
    leave their loaded flank), moves the machined surface by less than 2 um;
    the same play in joint 1, whose total torque the cut takes from zero
    (the axis is vertical: no weight on it), is taken up at the entry and
    moves the tool sideways by the play times its reach, b1 r."""
    base = run_cut(scenario, robot, compensation=False)

    def with_lost(b):
        sc = copy.deepcopy(scenario)
        sc.plant.lost_motion_rad = b
        return run_cut(sc, robot, compensation=False)

    loaded = with_lost([0.0, 4e-5, 4e-5, 0.0, 0.0, 0.0])
    assert abs(loaded.surface_error_mm["mean"] - base.surface_error_mm["mean"]) < 2e-3
    assert abs(loaded.surface_error_mm["pv"] - base.surface_error_mm["pv"]) < 2e-3
    # why: the total torque on joints 2 and 3 keeps its sign over the whole pass
    t, w = base.logs["cutting_wrench"]
    ts, x = base.logs["state"]
    q = x[np.clip(np.searchsorted(ts, t), 0, len(ts) - 1), :6]
    tau_cut = np.einsum("nrj,nr->nj", kin.jacobian(robot.dh, q, robot.payload.tool_point_m), w)
    hold = np.array([gravity_holding_torque(base.cell.station.controller_plant, qi) for qi in q[::25]])
    total = hold - tau_cut[::25]  # the gear balances gravity and holds back the cut
    for j in (1, 2):
        assert np.all(np.sign(total[:, j]) == np.sign(total[0, j])) and np.abs(total[:, j]).min() > 500.0
    # joint 1: no weight, so the cut's torque takes up the play
    b1 = 4e-5
    swung = with_lost([b1, 0.0, 0.0, 0.0, 0.0, 0.0])
    tool = robot.payload.tool_point_m
    y0 = kin.tool_position(robot.dh, base.logs["state"][1][:, :6], tool)[:, 1]
    y1 = kin.tool_position(robot.dh, swung.logs["state"][1][:, :6], tool)[:, 1]
    mid = len(y0) // 2
    reach = np.hypot(*kin.tool_position(robot.dh, q[len(q) // 2], tool)[:2])
    assert abs(y1[0] - y0[0]) < 1e-7  # at rest, before the cut: no torque, no play taken up
    assert abs(abs(y1[mid] - y0[mid]) - b1 * reach) < 0.1 * b1 * reach


def test_the_compensator_reads_the_motor_side(scenario, robot):
    """What the compensator samples is the controller's report of the motor
    angles (encoders less its gravity model), not the link angles: at rest
    it equals the command to second order (the controller evaluates its
    gravity model at the motor angles, not at the links': 2e-5 rad), while
    the links sag away from the motors by the gears' twist (mrad)."""
    cell = build_milling_cell(scenario, robot, compensation=True)
    sim = make_simulator(cell)
    sim.AdvanceTo(0.1)
    logs = {name: sig.read(sim.get_context()) for name, sig in cell.loggers.items()}
    _, q_sampled = logs["q_sampled"]
    _, motor = logs["motor"]
    _, state = logs["state"]
    np.testing.assert_allclose(q_sampled[-1], cell.q_ref[0], atol=2e-5)
    twist = motor[-1] - state[-1, :6]
    assert np.abs(twist).max() > 1e-3  # mrad of gear twist under the arm's weight
    hold = gravity_holding_torque(cell.station.controller_plant, state[-1, :6])
    np.testing.assert_allclose(twist, transmission.twist(hold, 1.0 / robot.joint_stiffness_Nm_per_rad), atol=1e-8)


def test_the_sensor_noise_lives_in_the_context(scenario, robot):
    """Two simulations of one diagram from the same random generator seed give
    the same readings; another seed gives other noise (the object holds no
    random state)."""
    cell = build_milling_cell(scenario, robot, compensation=True)

    def readings(seed):
        sc_seed = cell.scenario.sensor.seed
        cell.scenario.sensor.seed = seed
        try:
            sim = make_simulator(cell)
        finally:
            cell.scenario.sensor.seed = sc_seed
        sim.AdvanceTo(0.05)
        return cell.loggers["raw_wrench"].read(sim.get_context())[1]

    a, b, c = readings(1), readings(1), readings(2)
    np.testing.assert_array_equal(a, b)
    assert np.abs(a - c).max() > 0.1  # N: the noise differs
    assert np.std(a[:, 0] - c[:, 0]) == pytest.approx(np.sqrt(2) * scenario.sensor.noise_N, rel=0.3)
