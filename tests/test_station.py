"""The station's physics: gears that carry gravity and the cut, the robot
controller's gravity model and touch-off, the motor-side servo and its lag,
the step's stability, the cutting load through the sensor's weld, lost
motion only where the total torque changes sign, the compensator reading
the motor side, and the sensor's randomness in the Context."""

import copy
import re
from pathlib import Path

import numpy as np
import pytest
from arm_helpers import add_constant_tool_force
from pydrake.systems.analysis import Simulator
from pydrake.common.value import AbstractValue
from pydrake.multibody.math import SpatialForce
from pydrake.multibody.plant import ExternallyAppliedSpatialForce
from pydrake.systems.framework import DiagramBuilder, LeafSystem
from pydrake.systems.primitives import ConstantVectorSource
from scipy import linalg, signal

from robstiff_drake.diagrams.experiment import run_cut
from robstiff_drake.diagrams.loop_prediction import gravity_stiffness
from robstiff_drake.diagrams.milling_cell import build_milling_cell, check_plant_step, make_simulator
from robstiff_drake.diagrams.scenario import load_scenario
from robstiff_drake.diagrams.scenario_models import plant_damping_ratios
from robstiff_drake.diagrams.station import (
    add_compliant_arm,
    gravity_holding_torque,
    servo_parameters,
    set_drives_at_rest,
    static_link_angles,
)
from robstiff_drake.errors import InputError
from robstiff_drake.model import ik, transmission
from robstiff_drake.model import kinematics as kin
from robstiff_drake.model.payload import PayloadCalibration, payload_wrench
from robstiff_drake.model.wrench_frames import to_sensor_frame
from robstiff_drake.systems.gear_transmission import GearPlay
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
                lost_motion_rad=None, force_system=None, damping_on="drives_closed"):
    """(simulator, arm dict) of the compliant arm commanded to ``q_cmd`` (or
    by ``command``, a system), motors and links at rest on it, optionally a
    constant spatial force on the spindle at the tool point (base frame),
    or ``force_system``'s spatial forces."""
    k = robot.joint_stiffness_Nm_per_rad if k is None else np.asarray(k, dtype=float)
    builder = DiagramBuilder()
    arm = add_compliant_arm(builder, robot=robot, plant_config=sc.plant_config, joint_stiffness_Nm_per_rad=k,
                            damping_ratios=plant_damping_ratios(sc) if damping is None else damping,
                            q_modes_rad=q_cmd, servo=servo_parameters(sc),
                            interpolator_period_s=sc.servo.interpolator_period_ms / 1e3,
                            check_stability=check_stability, damping_on=damping_on,
                            lost_motion_rad=None if lost_motion_rad is None else list(lost_motion_rad))
    plant = arm["plant"]
    src = builder.AddSystem(command or ConstantVectorSource(q_cmd))
    vel = builder.AddSystem(ConstantVectorSource(np.zeros(6)))
    builder.Connect(src.get_output_port(), arm["position_command"])
    builder.Connect(vel.get_output_port(), arm["velocity_command"])
    if force is not None:
        add_constant_tool_force(builder, plant, robot, force)
    if force_system is not None:
        builder.Connect(builder.AddSystem(force_system).get_output_port(), plant.get_applied_spatial_force_input_port())
    sim = Simulator(builder.Build())
    root = sim.get_mutable_context()
    ctrl = arm["controller_plant"]
    theta = q_cmd + gravity_holding_torque(ctrl, q_cmd) / k  # the controller's gravity model (calibrated: true k)
    q = static_link_angles(ctrl, theta, 1.0 / k, lost_motion_rad)
    plant.SetPositions(plant.GetMyMutableContextFromRoot(root), q)
    set_drives_at_rest(arm, root, theta, q_cmd)
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
    # heavy damping on the arm's three lowest modes (settled in seconds); 30 % on the 126 Hz wrist mode
    # would make its explicit 2 ms step unstable (omega^2 h^2 < 4 - 4 zeta omega h)
    sim, arm = arm_at_rest(scenario, robot, q0, force=F, damping=[0.3, 0.3, 0.3, 0.05, 0.05, 0.05])
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


def perturbed_deviation(sim, arm, t_end, dq=1e-4):
    """Largest link deviation (rad) from rest after ``t_end`` s, every link
    started ``dq`` off (every mode excited); inf if the run blew up."""
    plant = arm["plant"]
    ctx = plant.GetMyMutableContextFromRoot(sim.get_mutable_context())
    q_rest = plant.GetPositions(ctx).copy()
    plant.SetPositions(ctx, q_rest + dq)
    try:
        sim.AdvanceTo(t_end)
        return float(np.abs(plant.GetPositions(ctx) - q_rest).max())
    except RuntimeError:
        return np.inf


def test_the_step_criterion_is_the_plants(scenario, robot):
    """The joints' step map (model/joint_dynamics.py: the plant's symplectic
    step with the drives exact) says where Drake's plant stays bounded: with
    2 % damping on every mode, so that no damping carries the step, 10 %
    below the largest stable step the arm settles, 10 % above it diverges."""
    q0 = reference_pose(robot)
    _, arm = arm_at_rest(scenario, robot, q0, damping=0.02)
    h_max = arm["joints"].largest_stable_step_s(0.01)
    assert 0.002 < h_max < 0.003  # the 126 Hz wrist mode: omega h = 2 near 2.5 ms
    for factor, stable in ((0.9, True), (1.1, False)):
        sc = copy.deepcopy(scenario)
        sc.plant_config.time_step = factor * h_max
        sim, arm = arm_at_rest(sc, robot, q0, damping=0.02, check_stability=False)
        assert arm["joints"].is_stable_step(factor * h_max) == stable
        dev = perturbed_deviation(sim, arm, 1.0)
        if stable:
            assert dev < 3e-4
        else:
            assert not dev < 1e-2


def test_a_step_too_coarse_is_refused_with_the_step_that_would_do(scenario, robot):
    """4 ms is too coarse for the 126 Hz mode: refused in one line naming the
    scenario's key and the step that would do; that step builds."""
    sc = copy.deepcopy(scenario)
    sc.plant_config.time_step = 0.004
    with pytest.raises(InputError) as e:
        check_plant_step(sc, robot)
    msg = str(e.value)
    assert "\n" not in msg and "plant_config.time_step" in msg and "126 Hz" in msg, msg
    suggested = float(re.search(r"\(plant_config\.time_step: ([0-9.e-]+)\)", msg).group(1))
    assert 0.002 <= suggested < 0.004
    sc.plant_config.time_step = suggested
    check_plant_step(sc, robot)


def test_damping_ratios_per_mode_as_set(scenario, robot):
    """Each arm mode with the drives closed (what a modal test with the
    drives on measures) gets its own stated damping ratio, where the gears
    can give it (a mode the drives alone damp beyond it comes out more
    damped, its gears at their floor); and Drake's plant, drives closed, rings down at its first mode
    at that ratio."""
    q0 = reference_pose(robot)
    ratios = [0.02, 0.03, 0.05, 0.07, 0.09, 0.11]
    _, arm = arm_at_rest(scenario, robot, q0, damping=ratios)
    jm = arm["joints"]
    f_arm, z_arm = jm.arm_modes()
    reached = jm.held_ratios() > 0.25 * np.array(ratios) + 1e-9  # (not at the gears' floor)
    assert reached[[0, 5]].all(), jm.held_ratios()
    np.testing.assert_allclose(z_arm[reached], np.array(ratios)[reached], atol=1.5e-4)
    assert np.all(z_arm[~reached] > np.array(ratios)[~reached])
    # stated on the motors-held modes instead: the links on the gears get exactly those
    held = arm_at_rest(scenario, robot, q0, damping=ratios, damping_on="motors_held")[1]["joints"]
    np.testing.assert_allclose(held.held_ratios(), ratios, rtol=1e-9)
    # Drake: the links started along the first motors-held mode, the motors at rest
    sc = copy.deepcopy(scenario)
    sc.plant_config.time_step = 0.001
    sim, arm = arm_at_rest(sc, robot, q0, damping=ratios)
    phi = transmission_modes(jm)[:, 0]
    plant = arm["plant"]
    ctx = plant.GetMyMutableContextFromRoot(sim.get_mutable_context())
    q_rest = plant.GetPositions(ctx).copy()
    plant.SetPositions(ctx, q_rest + 2e-4 * phi / np.abs(phi).max())
    times = np.arange(0.0, 2.0, 0.001)
    modal = []
    for t in times:
        sim.AdvanceTo(t)
        modal.append(phi @ jm.M @ (plant.GetPositions(ctx) - q_rest))
    modal = np.array(modal)
    peaks = signal.find_peaks(np.abs(modal), distance=int(0.6 / f_arm[0] / 2 / 0.001))[0]
    peaks = peaks[(times[peaks] > 0.3) & (times[peaks] < 1.8)]
    slope = np.polyfit(times[peaks], np.log(np.abs(modal[peaks])), 1)[0]
    f_ring = 0.5 / np.median(np.diff(times[peaks]))
    zeta_drake = -slope / (2 * np.pi * f_ring)
    assert f_ring == pytest.approx(f_arm[0], rel=0.03)
    assert zeta_drake == pytest.approx(ratios[0], rel=0.15)


def transmission_modes(jm):
    """The motors-held modes (columns, mass-normalised) of a JointModel."""
    from robstiff_drake.model.joint_dynamics import held_modes

    return held_modes(jm.M, jm.K, jm.G)[1]


@pytest.mark.parametrize("interpolator_ms", [4.0, 2.0])  # blocks apart; the dead time inside the drives' system
def test_the_drives_move_the_motor_as_the_joints_model_says(scenario, robot, interpolator_ms):
    """A 1 mrad step of the joint command without velocity feed-forward (a
    correction): the motor angles follow the interpolator's dead time, one
    plant step (the drives' discrete update) and the motor-and-link
    dynamics of the linear joints (model/joint_dynamics.py, solved exactly
    here), to 1.5 % of the step; the station reports the rigid axis's lag."""
    q0 = reference_pose(robot)
    sc = copy.deepcopy(scenario)
    sc.servo.interpolator_period_ms = interpolator_ms
    t0, step = 0.1005, np.full(6, 1e-3)  # between ticks: no tie at the step
    sim, arm = arm_at_rest(sc, robot, q0, command=StepCommand(q0, step, t0))
    servo = servo_parameters(sc)
    h, T_i = sc.plant_config.time_step, sc.servo.interpolator_period_ms / 1e3
    ticks = np.arange(0.104, 0.3, h)
    got = []
    for t in ticks + h / 2:  # between ticks: the state holds what the update at the tick computed
        sim.AdvanceTo(t)
        got.append(arm["servo"].get_output_port().Eval(arm["servo"].GetMyContextFromRoot(sim.get_context()))[:6])
    theta0 = q0 + gravity_holding_torque(arm["controller_plant"], q0) / robot.joint_stiffness_Nm_per_rad
    response = (np.array(got) - theta0) / step
    # the command is sampled at the interpolator's ticks (4 ms) and held: the
    # step reaches the drives at the first tick after it plus the dead time
    start = np.ceil(t0 / T_i) * T_i + servo.interpolator_delay_s + h
    tau = ticks - start + h  # the discrete drive's state at a tick is the response one step after its input
    A, B = arm["joints"].continuous()
    dt = 1e-4
    grid = np.arange(0.0, tau.max() + dt, dt)
    Phi = linalg.expm(np.block([[A, B[:, :6]], [np.zeros((6, 36))]]) * dt)
    x, out = np.zeros(30), []
    for _ in grid:
        out.append(x[12:18].copy())
        x = Phi[:30, :30] @ x + Phi[:30, 30:] @ np.ones(6)
    out = np.array(out)
    ref = np.column_stack([np.where(tau > 0, np.interp(tau, grid, out[:, j]), 0.0) for j in range(6)])
    # the gravity model moves with the command too (theta_ref = q + C g(q)): its change is 1e-3 of the step
    np.testing.assert_allclose(response[:, :3], ref[:, :3], atol=0.015)
    assert len(arm["interpolator"]) == (0 if interpolator_ms == 2.0 else 2)
    if interpolator_ms == 4.0:
        cell = build_milling_cell(sc, robot, compensation=True)
        assert cell.station.command_lag_s == pytest.approx(servo.interpolator_delay_s + 1.0 / servo.position_gain_per_s
                                                           + h)


def test_the_sensor_feels_the_cut_through_the_weld(scenario, robot):
    """The cutting load is applied to the spindle; the sensor across the
    flange-spindle weld reads the payload's weight plus that load (sensor
    frame, moment about its origin), at rest, to 1e-6 N."""
    q0 = reference_pose(robot)
    F = np.array([-300.0, 250.0, 50.0])
    builder = DiagramBuilder()
    arm = add_compliant_arm(builder, robot=robot, plant_config=scenario.plant_config,
                            joint_stiffness_Nm_per_rad=robot.joint_stiffness_Nm_per_rad,
                            damping_ratios=[0.3, 0.3, 0.3, 0.05, 0.05, 0.05], q_modes_rad=q0,
                            servo=servo_parameters(scenario), interpolator_period_s=0.004)
    plant = arm["plant"]
    for port, value in ((arm["position_command"], q0), (arm["velocity_command"], np.zeros(6))):
        builder.Connect(builder.AddSystem(ConstantVectorSource(value)).get_output_port(), port)
    add_constant_tool_force(builder, plant, robot, F)
    sensor = builder.AddSystem(WristForceSensor(weld_joint_index=plant.GetJointByName("sensor_weld").index(),
                                                rate_hz=250.0))
    builder.Connect(plant.get_reaction_forces_output_port(), sensor.GetInputPort("reaction_forces"))
    add_random_inputs(builder, sensor)
    sim = Simulator(builder.Build())
    root = sim.get_mutable_context()
    plant.SetPositions(plant.GetMyMutableContextFromRoot(root), q0)
    theta = q0 + gravity_holding_torque(arm["controller_plant"], q0) / robot.joint_stiffness_Nm_per_rad
    set_drives_at_rest(arm, root, theta, q0)
    sim.AdvanceTo(6.0)
    q = plant.GetPositions(plant.GetMyContextFromRoot(sim.get_context()))
    reading = sensor.get_output_port().Eval(sensor.GetMyContextFromRoot(sim.get_context()))
    R6 = kin.frames(robot.dh, q)[6, :3, :3]
    weight = payload_wrench(R6, PayloadCalibration(mass_kg=robot.payload.mass_kg,
                                                   com_mm=list(robot.payload.com_m * 1e3)))
    load = to_sensor_frame(R6.ravel().tolist(), robot.payload.tool_point_m.tolist(), list(F) + [0.0, 0.0, 0.0])
    np.testing.assert_allclose(reading, weight + np.array(load), atol=1e-6)


class SlowlyReversingForce(LeafSystem):
    """A force F(t) along y at the tool (base frame): F0 sin(2 pi f t) for
    ``cycles`` periods (ending on a peak), then a half-period cosine ramp
    to zero, then zero."""

    def __init__(self, plant, robot, F0_N, f_hz, cycles):
        super().__init__()
        self._F0, self._w, self._t1 = F0_N, 2 * np.pi * f_hz, cycles / f_hz
        self._ramp = 0.5 / f_hz
        self._f = ExternallyAppliedSpatialForce()
        self._f.body_index = plant.GetBodyByName("spindle").index()
        self._f.p_BoBq_B = robot.payload.tool_point_m
        self.DeclareAbstractOutputPort("forces", lambda: AbstractValue.Make([self._f]), self._calc)

    def force(self, t):
        if t <= self._t1:
            return self._F0 * np.sin(self._w * t)
        end = np.sin(self._w * self._t1) * self._F0
        u = min((t - self._t1) / self._ramp, 1.0)
        return end * 0.5 * (1.0 + np.cos(np.pi * u))

    def _calc(self, context, output):
        self._f.F_Bq_W = SpatialForce(np.zeros(3), np.array([0.0, self.force(context.get_time()), 0.0]))
        output.set_value([self._f])


class ForceStep(LeafSystem):
    """A constant force (N, base frame) at the tool from ``t_s`` on."""

    def __init__(self, plant, robot, force_N, t_s):
        super().__init__()
        self._F, self._t = np.asarray(force_N, dtype=float), t_s
        self._f = ExternallyAppliedSpatialForce()
        self._f.body_index = plant.GetBodyByName("spindle").index()
        self._f.p_BoBq_B = robot.payload.tool_point_m
        self.DeclareAbstractOutputPort("forces", lambda: AbstractValue.Make([self._f]), self._calc)

    def _calc(self, context, output):
        on = context.get_time() >= self._t
        self._f.F_Bq_W = SpatialForce(np.zeros(3), self._F * on)
        output.set_value([self._f])


def arm_at_rest_with(sc, robot, q0, play, make_forces):
    """The compliant arm at rest on q0 with gear play (half-widths ``play``)
    and the spatial forces of ``make_forces(plant)``: (simulator, arm)."""
    builder = DiagramBuilder()
    k = robot.joint_stiffness_Nm_per_rad
    arm = add_compliant_arm(builder, robot=robot, plant_config=sc.plant_config, joint_stiffness_Nm_per_rad=k,
                            damping_ratios=plant_damping_ratios(sc), q_modes_rad=q0, servo=servo_parameters(sc),
                            interpolator_period_s=sc.servo.interpolator_period_ms / 1e3, lost_motion_rad=list(play))
    plant = arm["plant"]
    for port, value in ((arm["position_command"], q0), (arm["velocity_command"], np.zeros(6))):
        builder.Connect(builder.AddSystem(ConstantVectorSource(value)).get_output_port(), port)
    builder.Connect(builder.AddSystem(make_forces(plant)).get_output_port(),
                    plant.get_applied_spatial_force_input_port())
    sim = Simulator(builder.Build())
    root = sim.get_mutable_context()
    ctrl = arm["controller_plant"]
    theta = q0 + gravity_holding_torque(ctrl, q0) / k
    plant.SetPositions(plant.GetMyMutableContextFromRoot(root), static_link_angles(ctrl, theta, 1.0 / k, play))
    set_drives_at_rest(arm, root, theta, q0)
    sim.Initialize()
    return sim, arm


def test_gear_play_gives_the_hysteresis_loop_of_a_dead_zone(scenario, robot):
    """Joint 1 (a vertical axis: no weight on its gear) with 100 urad of play
    under a torque that reverses slowly (0.1 Hz, about +-2400 N*m), the
    drives holding the motors: its gear's twist theta - q follows the
    analytic loop of a dead zone of width 2b, phi = -tau/k -+ b on its two
    flanks (slopes 1/k to 2 %, the loop's width 2b to 5 %, once the ringing
    of the impact at each reversal has died down); no torque passes while
    the link crosses the gap; and when the torque falls back to zero the
    link stays on the flank it last pressed (the smooth law would bring it
    back to the middle)."""
    b, f = 1e-4, 0.1
    q0 = reference_pose(robot)
    play = np.array([b, 0.0, 0.0, 0.0, 0.0, 0.0])
    holder = {}

    def forces(plant):
        holder["src"] = SlowlyReversingForce(plant, robot, 1500.0, f, 1.25)
        return holder["src"]

    sim, arm = arm_at_rest_with(scenario, robot, q0, play, forces)
    plant, drives = arm["plant"], arm["servo"]
    root = sim.get_context()
    k1 = robot.joint_stiffness_Nm_per_rad[0]
    tool = robot.payload.tool_point_m
    t_end = 1.25 / f + 0.5 / f + 1.0
    rows = []
    for t in np.arange(0.0, t_end, 0.01):
        sim.AdvanceTo(t)
        q = plant.GetPositions(plant.GetMyContextFromRoot(root))
        theta = drives.get_output_port().Eval(drives.GetMyContextFromRoot(root))[:6]
        J = kin.jacobian(robot.dh, q, tool)
        tau_ext = (J.T @ np.r_[0.0, holder["src"].force(t), 0.0, 0.0, 0.0, 0.0])[0]
        rows.append((t, tau_ext, theta[0] - q[0]))
    t, tau, phi = np.array(rows).T
    assert np.abs(tau).max() > 2000.0
    # on the flanks, 1.5 s after each reversal's impact: phi = -tau / k - b sign(tau) (the gear holds it back)
    since_reversal = t - np.floor(t * 2 * f) / (2 * f)
    loaded = (np.abs(tau) > 300.0) & (t < 1.25 / f) & (since_reversal > 1.5)
    for side in (1.0, -1.0):
        m = loaded & (np.sign(tau) == side)
        slope, intercept = np.polyfit(tau[m], phi[m], 1)
        assert slope == pytest.approx(-1.0 / k1, rel=0.02)
        assert intercept == pytest.approx(-side * b, rel=0.05)
    # no torque through the gear while the link is inside the gap
    gear = GearPlay(stiffness_Nm_per_rad=arm["joints"].K, damping_Nms_per_rad=arm["joints"].D, play_rad=play)
    inside = phi[np.abs(phi) < 0.9 * b]
    assert inside.size >= 2  # the link crossed the gap
    for p in inside:
        assert gear.torque(np.r_[p, np.zeros(5), 1e-3, np.zeros(5)], np.zeros(12))[0] == 0.0
    # the torque is back to zero: the link stays on the flank the last (positive) torque pressed
    rest = t > t_end - 0.5
    assert np.all(np.abs(tau[rest]) < 1e-9)
    np.testing.assert_allclose(phi[rest], -b, atol=0.1 * b)


def test_the_encoders_see_the_cut(scenario, robot):
    """A 300 N force step down at the tool, the drives holding: the motors
    give way (joints 2 and 3 by tens of microradians, as the linear joints
    predict to 10 %) and the drives' integral action brings them back."""
    q0 = reference_pose(robot)
    t_step = 0.2
    sim, arm = arm_at_rest_with(scenario, robot, q0, np.zeros(6),
                                lambda plant: ForceStep(plant, robot, [0.0, 0.0, -300.0], t_step))
    drives = arm["servo"]
    times = np.arange(0.0, 2.0, 0.002)
    theta = []
    for t in times:
        sim.AdvanceTo(t)
        theta.append(drives.get_output_port().Eval(drives.GetMyContextFromRoot(sim.get_context()))[:6])
    moved = np.array(theta) - theta[0]
    # the linear joints' prediction of the motors under the same torque step
    A, B = arm["joints"].continuous()
    tau = kin.jacobian(robot.dh, q0, robot.payload.tool_point_m).T @ np.r_[0.0, 0.0, -300.0, 0.0, 0.0, 0.0]
    dt = 1e-4
    Phi = linalg.expm(np.block([[A, B[:, 18:24]], [np.zeros((6, 36))]]) * dt)
    x, model = np.zeros(30), []
    for _ in np.arange(0.0, times[-1] - t_step + dt, dt):
        model.append(x[12:18].copy())
        x = Phi[:30, :30] @ x + Phi[:30, 30:] @ tau
    model = np.array(model)
    for j in (1, 2):
        peak = np.abs(moved[:, j]).max()
        assert peak > 5e-6, (j, peak)  # tens of microradians: an encoder resolves 0.1 urad at the joint
        assert peak == pytest.approx(np.abs(model[:, j]).max(), rel=0.1)
        assert np.abs(moved[-1, j]) < 0.2 * peak  # the integral brings the motor back
        assert moved[-1, j] == pytest.approx(model[-1, j], abs=0.05 * peak)


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
    # (the motors are not held: the corrections of the sensor's noise move them by tens of nanoradians)
    np.testing.assert_allclose(twist, transmission.twist(hold, 1.0 / robot.joint_stiffness_Nm_per_rad), atol=5e-8)


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
