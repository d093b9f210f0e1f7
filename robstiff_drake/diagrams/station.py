"""The milling station: everything of the cell that is hardware, as one
Drake diagram with its ports exported by name (the shape of Drake's
hardware_sim station and of the manipulation station):

    position_command (6, rad) ---+
    velocity_command (6, rad/s) -+-> robot controller: absolute-accuracy
                                    gravity model theta_ref = q_cmd + C g(q_cmd),
                                    torque feed-forward g(q_cmd)
                                    -> interpolator (dead time)
                                    -> drives (position loop, PI velocity loop:
                                       motor torque) -> motor (rotor inertia) theta
    motor theta <-> gear (stiffness K, play, modal damping) <-> link q
                                    (MultibodyPlant; the gear's torque pushes the
                                    link and, back, the motor: the encoders see the cut)
    spindle <- cutting load (ExternallyAppliedSpatialForce at the tool point)
    flange-spindle weld reaction -> wrist sensor (bias, noise, dropouts, spikes)

    outputs: position_measured (6, rad: what the controller reports, the
             motor angles less its gravity model), motor_position (6, rad:
             the encoders), wrench_measured (6: the sensor, sensor frame),
             tool_pose (12: flange rotation row-major and tool point, m,
             base frame, from the link angles: the truth a real cell does not
             measure), plant_state (12), cutting_wrench (6: the truth, tool
             point, base frame)

The gear carries the total torque: gravity, inertia and the cut.  The
controller compensates the static gravity deflection with its own model (as
a robot with ABB's absolute-accuracy option does, calibrated for the arm);
what its model misses at the start pose (a stiffer or softer gear, play
taken up by the arm's weight) is zeroed by touching off there: a constant joint offset,
set when the station starts (``start``), as a machinist sets the work
offset on the part.  So at rest on the first path point the tool sits
where it was commanded; what the cut adds deflects the arm.
"""

from dataclasses import dataclass

import numpy as np
from pydrake.multibody.plant import AddMultibodyPlant, MultibodyPlant
from pydrake.systems.controllers import InverseDynamics
from pydrake.systems.framework import DiagramBuilder, LeafSystem
from pydrake.systems.primitives import (
    ConstantVectorSource,
    Demultiplexer,
    DiscreteTimeDelay,
    LinearSystem,
    MatrixGain,
    Multiplexer,
    ZeroOrderHold,
)

from robstiff_drake.diagrams.scenario import (
    exact_payload_calibration,
    plant_damping_ratios,
    plant_step_s,
    plant_stiffness,
)
from robstiff_drake.model import joint_dynamics, transmission
from robstiff_drake.model import servo as servo_model
from robstiff_drake.model.payload import payload_wrench
from robstiff_drake.model.realtime import DeflectionPredictor
from robstiff_drake.model.servo import ServoParameters
from robstiff_drake.plant import add_robot, check_plant_matches
from robstiff_drake.systems.gear_transmission import GearPlay
from robstiff_drake.systems.milling_force import MillingForceSource
from robstiff_drake.systems.wrist_sensor import WristForceSensor, add_random_inputs


def modal_frequencies_hz(M, k_Nm_per_rad, G=None):
    """Undamped natural frequencies (Hz) of joint springs k (6,) or a
    stiffness matrix (6, 6) with the mass matrix M (motors held; with G,
    the weight's own stiffness), ascending."""
    K = np.asarray(k_Nm_per_rad, dtype=float)
    return joint_dynamics.held_modes(M, np.diag(K) if K.ndim == 1 else K, G)[0] / (2 * np.pi)


def natural_frequencies(plant, context, q, k_Nm_per_rad):
    """Undamped natural frequencies (Hz) of the joint springs at q (motors
    held), ascending."""
    plant.SetPositions(context, q)
    return modal_frequencies_hz(plant.CalcMassMatrix(context), k_Nm_per_rad)


def motor_inertia(robot, M):
    """The motors' rotor inertias reflected to the joints (6,, kg*m^2): the
    robot file's ``motor_inertia_kgm2``; a file without them: ASSUMPTION,
    each equal to its link's inertia on the joint in M (a load-to-motor
    inertia ratio of 1, inside the 1-5 that servo axes are sized for)."""
    if robot.motor_inertia_kgm2 is not None:
        return np.asarray(robot.motor_inertia_kgm2, dtype=float)
    return np.diag(M).copy()


def joint_model(controller_plant, robot, q_rad, stiffness_matrix, damping_ratios, servo):
    """The linear joints (model/joint_dynamics.JointModel) at pose q: the
    controller model's mass matrix and weight's stiffness, the gears, their
    modal damping (``damping_ratios``, per mode or one for all), the motors
    and drives (velocity loops tuned for the rigid axes at q)."""
    ctx = controller_plant.CreateDefaultContext()
    G = gravity_stiffness(controller_plant, ctx, np.asarray(q_rad, dtype=float))
    controller_plant.SetPositions(ctx, q_rad)
    M = controller_plant.CalcMassMatrix(ctx)
    D = joint_dynamics.modal_damping_matrix(M, stiffness_matrix, G, damping_ratios)
    Jm = motor_inertia(robot, M)
    return joint_dynamics.JointModel(M=M, K=stiffness_matrix, G=G, D=D, motor_inertia_kgm2=Jm, servo=servo,
                                     velocity_gain=servo_model.velocity_gain_Nms(servo, Jm + np.diag(M)))


def unstable_step_message(jm, time_step_s):
    """None when the plant step keeps every mode of the joints ``jm``
    stable, else why not and the step that would do (one line)."""
    if jm.is_stable_step(time_step_s):
        return None
    lam = np.linalg.eigvals(jm.continuous()[0])
    worst = lam[np.argmax(lam.real)]
    if worst.real >= 0.0:  # no step helps: the loop itself grows
        return (f"the joints' loop is unstable whatever the step: its {abs(worst) / (2 * np.pi):.1f} Hz mode grows "
                f"(the drives' loops against too lightly damped gears): raise plant.modal_damping_ratio or "
                f"plant.damping_ratios, or lower servo.velocity_integral_hz")
    f_top = max(jm.closed_loop_modes()[0].max(), joint_dynamics.free_modes_hz(
        jm.M, jm.K, jm.G, jm.motor_inertia_kgm2).max())
    ok = jm.largest_stable_step_s(time_step_s)
    ok_ms = np.floor(ok * 1e4) / 10.0  # rounded down to 0.1 ms
    return (f"a {time_step_s * 1e3:g} ms plant step is unstable for the arm's {f_top:.0f} Hz mode (the gears' "
            f"explicit step needs omega h < 2 in every mode): use at most {ok_ms:g} ms "
            f"(plant_config.time_step: {ok_ms / 1e3:g})")


def servo_parameters(sc):
    s = sc.servo
    return ServoParameters(position_gain_per_s=s.position_gain_per_s, velocity_bandwidth_hz=s.velocity_bandwidth_hz,
                           velocity_feedforward=s.velocity_feedforward,
                           interpolator_delay_s=s.interpolator_delay_ms / 1e3,
                           velocity_integral_hz=s.velocity_integral_hz)


def controller_model(robot):
    """The robot controller's own model of the arm and payload (a
    continuous MultibodyPlant, finalized): its gravity model, and the arm's
    modes.  Keep it alive as long as a diagram that uses it."""
    plant = MultibodyPlant(0.0)
    add_robot(plant, robot)
    plant.Finalize()
    check_plant_matches(plant, robot)
    return plant


def gravity_stiffness(plant, context, q, delta_rad=1e-6):
    """d tau_gravity / dq (6, 6) at q, N*m/rad, by central differences: the
    arm's weight's own stiffness, which the gears carry along with theirs."""
    G = np.empty((6, 6))
    for k in range(6):
        e = np.zeros(6)
        e[k] = delta_rad
        plant.SetPositions(context, q + e)
        plus = plant.CalcGravityGeneralizedForces(context)
        plant.SetPositions(context, q - e)
        G[:, k] = (plus - plant.CalcGravityGeneralizedForces(context)) / (2 * delta_rad)
    return G


def gravity_holding_torque(controller_plant, q):
    """The joint torques (N*m) that hold the arm and payload still at q
    (minus the generalized gravity forces)."""
    ctx = controller_plant.CreateDefaultContext()
    controller_plant.SetPositions(ctx, q)
    return -controller_plant.CalcGravityGeneralizedForces(ctx)


def static_link_angles(controller_plant, theta, compliance, lost_motion_rad=None, coupling_c23=0.0, iterations=50):
    """The link angles q (rad) at which the plant's gears (play of
    half-width ``lost_motion_rad``), their motors held at ``theta``, hold
    the arm still against gravity: q = theta - play_twist(g(q)), by
    fixed-point iteration (the twist is a few mrad, so it converges at
    once)."""
    q = np.array(theta, dtype=float)
    for _ in range(iterations):
        q_new = theta - transmission.play_twist(gravity_holding_torque(controller_plant, q), compliance,
                                                lost_motion_rad, coupling_c23)
        if np.max(np.abs(q_new - q)) < 1e-13:
            return q_new
        q = q_new
    return q


class ToolPose(LeafSystem):
    """Input ``q`` (6, link angles rad); output ``tool_pose`` (12): the
    flange rotation (row-major) and the tool point (m), base frame."""

    def __init__(self, kinematics):
        super().__init__()
        self._kin = kinematics
        q = self.DeclareVectorInputPort("q", 6)
        self.DeclareVectorOutputPort("tool_pose", 12, lambda c, o: o.SetFromVector(self._kin.pose(q.Eval(c))),
                                     prerequisites_of_calc={q.ticket()})


@dataclass
class MillingStation:
    """The station diagram and what a cell needs to run and read it."""

    diagram: object
    plant: object
    controller_plant: object  # the controller's model: kept alive with the diagram
    robot: object
    tool_m: np.ndarray
    servo: ServoParameters
    joints: object  # model/joint_dynamics.JointModel at the start pose (modes, damping, drives)
    plant_step_s: float
    systems: dict
    compliance_model_rad_per_Nm: np.ndarray  # the controller's (absolute-accuracy) gear compliance
    compliance_plant_rad_per_Nm: np.ndarray
    lost_motion_plant_rad: np.ndarray  # the gears' play, half-width (rad)
    coupling_plant: float
    damping_ratios: np.ndarray  # per mode, motors held

    @property
    def natural_frequencies_hz(self):
        """Undamped natural frequencies (Hz) at the start pose, motors held."""
        return joint_dynamics.held_modes(self.joints.M, self.joints.K, self.joints.G)[0] / (2 * np.pi)

    @property
    def natural_frequencies_free_hz(self):
        """... with the motors free (no drive): the nonzero ones."""
        j = self.joints
        return joint_dynamics.free_modes_hz(j.M, j.K, j.G, j.motor_inertia_kgm2)

    @property
    def closed_loop_modes(self):
        """(frequencies Hz, damping ratios) with the drives' loops closed."""
        return self.joints.closed_loop_modes()

    @property
    def command_lag_s(self):
        """Low-frequency lag (s) from a joint command without velocity
        feed-forward to the motor: the interpolator's dead time, the position
        loop's 1 / Kp and the servo's own discrete update (one plant step)."""
        return self.servo.low_frequency_lag_s + self.plant_step_s

    def start(self, q_command):
        """(theta (6), q (6), sensor reading (6), touch-off offset (6)) of the
        station at rest with the controller commanding ``q_command``, touched
        off there: the links at the command, the motors where the true gears
        hold them against gravity, the offset the motors need beyond the
        controller's gravity model, the sensor reading the payload's weight
        and bias."""
        q = np.asarray(q_command, dtype=float)
        hold = gravity_holding_torque(self.controller_plant, q)
        theta = q + transmission.play_twist(hold, self.compliance_plant_rad_per_Nm, self.lost_motion_plant_rad,
                                            self.coupling_plant)
        offset = theta - (q + self.compliance_model_rad_per_Nm * hold)
        return theta, q, self.reading_at_rest(q), offset

    def reading_at_rest(self, q):
        """The sensor's reading (sensor frame) at rest at link angles q: the
        payload's weight and the sensor's bias."""
        R6 = DeflectionPredictor(self.robot.dh, self.robot.joint_stiffness_Nm_per_rad,
                                 self.tool_m).flange_rotation_and_tool_point(q)[0]
        return payload_wrench(R6, self.systems["true_calibration"])

    def set_initial_state(self, root_context, q_command, touch_off=True):
        """Put the station at rest (``start``) in a root context; without
        ``touch_off`` the controller's gravity model alone places the arm."""
        theta, q, wrench, offset = self.start(q_command)
        s = self.systems
        if touch_off:
            s["touch_off"].get_mutable_source_value(s["touch_off"].GetMyMutableContextFromRoot(root_context)) \
                .SetFromVector(offset)
        else:
            theta = theta - offset
            q = static_link_angles(self.controller_plant, theta, self.compliance_plant_rad_per_Nm,
                                   self.lost_motion_plant_rad, self.coupling_plant)
            wrench = self.reading_at_rest(q)
        self.plant.SetPositions(self.plant.GetMyMutableContextFromRoot(root_context), q)
        set_drives_at_rest(s, root_context, theta, q_command)
        s["sensor"].GetMyMutableContextFromRoot(root_context).SetDiscreteState(wrench)
        return theta, q, wrench


def set_drives_at_rest(arm, root_context, theta, q_command=None):
    """Every sample of ``arm``'s interpolator and drives (the systems
    add_compliant_arm returns under "interpolator" and "servo") at rest at
    the motor angles ``theta`` (rad) with the controller commanding
    ``q_command`` (its gravity model's torque fed forward; None: the link
    angles the plant's context holds): the drives' integrals carry what the
    feed-forward leaves of the gears' torque at the plant's link angles
    (set those first)."""
    plant, ctrl = arm["plant"], arm["controller_plant"]
    q = plant.GetPositions(plant.GetMyContextFromRoot(root_context))
    ff = gravity_holding_torque(ctrl, q if q_command is None else np.asarray(q_command, dtype=float))
    gear = arm["gear_torque_at_rest"](theta, q)
    sample = np.concatenate([theta, np.zeros(6), ff])
    for block in arm["interpolator"]:
        ctx = block.GetMyMutableContextFromRoot(root_context)
        ctx.SetDiscreteState(np.tile(sample, ctx.get_discrete_state_vector().size() // sample.size))
    drives = arm["servo"]
    n_delay = (drives.num_states() - 18) // servo_model.DRIVE_REFERENCE_SIZE
    drives.GetMyMutableContextFromRoot(root_context).SetDiscreteState(servo_model.drive_state_at_rest(
        arm["servo_parameters"], arm["joints"].velocity_gain, theta, gear, ff, n_delay))


def add_compliant_arm(builder, *, robot, plant_config, joint_stiffness_Nm_per_rad, damping_ratios, q_modes_rad,
                      servo, interpolator_period_s, lost_motion_rad=None, coupling_c23_rad_per_Nm=0.0,
                      check_stability=True):
    """The arm and its drives: a discrete MultibodyPlant (``plant_config``)
    of the links, each driven through its gear by a motor with its rotor's
    inertia, which a torque-level drive turns (model/servo.py); the robot
    controller's absolute-accuracy gravity model (its reference and its
    torque feed-forward) and the interpolator's dead time (see the module
    docstring).

    Gear j carries tau = K dz(theta - q) + D (theta' - q') onto the link
    and minus that onto its motor: K the gears' stiffness (with the 2-3
    coupling), dz the play's dead zone (``lost_motion_rad``: half-widths;
    none: dz(x) = x), D the modal damping that gives each motors-held mode
    its ratio in ``damping_ratios`` (model/joint_dynamics.py, at
    ``q_modes_rad``).  Without play the torque is one MatrixGain (no Python
    in the step), with play systems/gear_transmission.GearPlay.  The gear's
    torque is explicit over a step (symplectic Euler in the plant, the
    drives exact with it held): stable while omega h < 2 in every mode
    (model/joint_dynamics.py), whatever the damping.

    Returns a dict: plant, controller_plant (the controller's model: keep it
    alive with the diagram), ``position_command`` and ``velocity_command``
    (input ports), ``motor_state`` (output port: theta, theta'),
    ``motor_position``, ``reported_position`` (output port: the motor angles
    less the controller's gravity model), ``gear_torque`` (output port),
    ``servo`` (the drives' LinearSystem), ``interpolator`` (its blocks),
    joints (the JointModel), natural_frequencies_hz (motors held).  Raises
    ValueError, naming the step that would do, if the step is unstable for
    these joints (unless ``check_stability`` is false)."""
    k = np.asarray(joint_stiffness_Nm_per_rad, dtype=float)
    # ASSUMPTION: the absolute-accuracy model is calibrated for this arm (as
    # ABB calibrates each robot with the option): its gravity model uses the
    # gears' true linear stiffness; their play and coupling are not in it
    # (the touch-off absorbs their static part at the start pose).
    k_model = k
    h = float(plant_config.time_step)
    plant, _ = AddMultibodyPlant(plant_config, builder)
    plant.set_name("plant")
    add_robot(plant, robot)
    plant.Finalize()
    ctrl = controller_model(robot)
    Kg = joint_dynamics.stiffness_matrix(k, coupling_c23_rad_per_Nm)
    jm = joint_model(ctrl, robot, q_modes_rad, Kg, damping_ratios, servo)
    why = unstable_step_message(jm, h) if check_stability else None
    if why:
        raise ValueError(why)

    # the robot controller: absolute-accuracy gravity model, interpolator, drives
    cmd_in = builder.AddNamedSystem("position_command_in", Multiplexer([6]))
    vel_in = builder.AddNamedSystem("velocity_command_in", Multiplexer([6]))
    zeros = builder.AddNamedSystem("zero_velocity", ConstantVectorSource(np.zeros(6)))
    # the touch-off offset: a parameter in the Context, set by MillingStation.set_initial_state
    offset = builder.AddNamedSystem("touch_off_offset", ConstantVectorSource(np.zeros(6)))

    def gravity_at(angles, name):
        """The controller model's gravity-holding torque at ``angles``
        (InverseDynamics: C++, no Python per step)."""
        as_state = builder.AddNamedSystem(f"{name}_as_state", Multiplexer([6, 6]))
        builder.Connect(angles, as_state.get_input_port(0))
        builder.Connect(zeros.get_output_port(), as_state.get_input_port(1))
        gravity = builder.AddNamedSystem(f"{name}_gravity", InverseDynamics(
            ctrl, InverseDynamics.InverseDynamicsMode.kGravityCompensation))
        builder.Connect(as_state.get_output_port(), gravity.get_input_port_estimated_state())
        return gravity.get_output_port()

    # the reference (theta_ref = q + C_model g(q) + offset, omega_ref) and the torque fed forward, g(q)
    I, Z, C = np.eye(6), np.zeros((6, 6)), np.diag(1.0 / k_model)
    terms = builder.AddNamedSystem("motor_reference_terms", Multiplexer([6, 6, 6, 6]))
    builder.Connect(cmd_in.get_output_port(), terms.get_input_port(0))
    builder.Connect(vel_in.get_output_port(), terms.get_input_port(1))
    builder.Connect(gravity_at(cmd_in.get_output_port(), "motor_reference"), terms.get_input_port(2))
    builder.Connect(offset.get_output_port(), terms.get_input_port(3))
    ref = builder.AddNamedSystem("motor_reference", MatrixGain(np.block([[I, Z, C, I], [Z, I, Z, Z],
                                                                         [Z, Z, I, Z]])))
    builder.Connect(terms.get_output_port(), ref.get_input_port())
    m = servo_model.DRIVE_REFERENCE_SIZE
    n_i = int(round(servo.interpolator_delay_s / interpolator_period_s))
    last, interp = ref.get_output_port(), []
    n_reg = 0
    if abs(interpolator_period_s - h) < 1e-12:
        # the interpolator runs at the plant's step: its dead time is a shift
        # register inside the drives' LinearSystem (one discrete update, not three)
        # (n + 1 samples: the same dead time as a hold and a delay line of n - 1 in front of it)
        n_reg = n_i + 1 if n_i else 0
        n_i = 0
    if n_i >= 1:  # n periods: a hold adds one, a delay line the rest (same-instant semantics)
        interp.append(builder.AddNamedSystem("interpolator_hold", ZeroOrderHold(interpolator_period_s, m)))
        if n_i >= 2:
            interp.append(builder.AddNamedSystem("interpolator_delay",
                                                 DiscreteTimeDelay(interpolator_period_s, n_i - 1, m)))
        for block in interp:
            builder.Connect(last, block.get_input_port())
            last = block.get_output_port()
    drive_in = builder.AddNamedSystem("drive_inputs", Multiplexer([m, 6]))
    builder.Connect(last, drive_in.get_input_port(0))
    drives = builder.AddNamedSystem("joint_servo", LinearSystem(
        *servo_model.drive_discrete(servo, h, jm.motor_inertia_kgm2, jm.velocity_gain, n_reg), h))
    builder.Connect(drive_in.get_output_port(), drives.get_input_port())
    motor = drives.get_output_port()  # (theta, theta')

    # the gears: K dz(theta - q) + D (theta' - q') on the link, minus that on the motor
    b = np.asarray(lost_motion_rad if lost_motion_rad is not None and len(lost_motion_rad) else np.zeros(6),
                   dtype=float)
    if np.any(b):
        gear = builder.AddNamedSystem("gear_transmission", GearPlay(
            stiffness_Nm_per_rad=Kg, damping_Nms_per_rad=jm.D, play_rad=b))
        builder.Connect(motor, gear.GetInputPort("motor_state"))
        builder.Connect(plant.get_state_output_port(), gear.GetInputPort("link_state"))
    else:
        gear_in = builder.AddNamedSystem("gear_inputs", Multiplexer([12, 12]))
        gear = builder.AddNamedSystem("gear_transmission", MatrixGain(np.hstack([Kg, jm.D, -Kg, -jm.D])))
        builder.Connect(motor, gear_in.get_input_port(0))
        builder.Connect(plant.get_state_output_port(), gear_in.get_input_port(1))
        builder.Connect(gear_in.get_output_port(), gear.get_input_port())
    tau = gear.get_output_port()
    builder.Connect(tau, plant.get_actuation_input_port())
    builder.Connect(tau, drive_in.get_input_port(1))

    # what the controller reports: the encoders less its gravity model (and the touch-off)
    motor_demux = builder.AddNamedSystem("motor_demux", Demultiplexer([6, 6]))
    builder.Connect(motor, motor_demux.get_input_port())
    rep_terms = builder.AddNamedSystem("position_reported_terms", Multiplexer([6, 6, 6]))
    builder.Connect(motor_demux.get_output_port(0), rep_terms.get_input_port(0))
    builder.Connect(gravity_at(motor_demux.get_output_port(0), "position_reported"), rep_terms.get_input_port(1))
    builder.Connect(offset.get_output_port(), rep_terms.get_input_port(2))
    reported = builder.AddNamedSystem("position_reported", MatrixGain(np.hstack([I, -C, -I])))
    builder.Connect(rep_terms.get_output_port(), reported.get_input_port())

    def gear_torque_at_rest(theta, q):
        return transmission.play_torque(np.asarray(theta) - np.asarray(q), Kg, b)

    return {"plant": plant, "controller_plant": ctrl, "position_command": cmd_in.get_input_port(0),
            "velocity_command": vel_in.get_input_port(0), "motor_state": motor,
            "motor_position": motor_demux.get_output_port(0), "reported_position": reported.get_output_port(),
            "gear_torque": tau, "servo": drives, "servo_parameters": servo, "interpolator": interp,
            "touch_off": offset, "joints": jm, "natural_frequencies_hz": modal_frequencies_hz(jm.M, Kg, jm.G),
            "lost_motion_rad": b, "gear_torque_at_rest": gear_torque_at_rest}


# The revolution-averaged cutting force is updated every 4 ms (or every plant step, if longer): it changes
# with the cutter's engagement over millimetres of feed, and the cutter moves 0.08-0.24 mm per update at
# 20-60 mm/s (the time-step study, studies/time_step_convergence.py, compares it with an update every
# plant step).  Tooth-resolved, it is updated every plant step.
AVERAGED_FORCE_PERIOD_S = 0.004


def cutting_force_period_s(mode, plant_step_s):
    """How often the milling force source updates the cutting load (s)."""
    return max(plant_step_s, AVERAGED_FORCE_PERIOD_S) if mode == "averaged" else plant_step_s


def make_milling_station(sc, robot, *, path, force_model, workpiece, q_modes_rad, check_stability=True,
                         name="milling_station"):
    """The station of scenario ``sc`` (see module docstring).  ``path`` (the
    planned path: the cut's feed direction) and ``force_model``/``workpiece``
    (the process), ``q_modes_rad`` the pose whose modes set the damping and
    tune the drives.  Raises ValueError if the plant step is unstable for
    these joints (unless ``check_stability`` is false)."""
    tool = robot.tool_point(where="the closed loop")
    h = plant_step_s(sc)
    k = np.asarray(plant_stiffness(sc, robot), dtype=float)
    servo = servo_parameters(sc)
    builder = DiagramBuilder()
    ratios = plant_damping_ratios(sc)
    arm = add_compliant_arm(builder, robot=robot, plant_config=sc.plant_config, joint_stiffness_Nm_per_rad=k,
                            damping_ratios=ratios, q_modes_rad=q_modes_rad, servo=servo,
                            interpolator_period_s=sc.servo.interpolator_period_ms / 1e3,
                            lost_motion_rad=sc.plant.lost_motion_rad,
                            coupling_c23_rad_per_Nm=sc.plant.coupling_c23_rad_per_Nm,
                            check_stability=check_stability)
    plant = arm["plant"]
    systems = {key: arm[key] for key in ("plant", "controller_plant", "servo", "servo_parameters", "interpolator",
                                         "touch_off", "joints", "gear_torque_at_rest")}

    # the process: the cutting load at the actual tool point, on the spindle
    state_demux = builder.AddNamedSystem("state_demux", Demultiplexer([6, 6]))
    builder.Connect(plant.get_state_output_port(), state_demux.get_input_port())
    q_link = state_demux.get_output_port(0)
    fk = DeflectionPredictor(robot.dh, k, tool)
    milling = builder.AddNamedSystem("milling_force", MillingForceSource(
        force_model=force_model, workpiece=workpiece, path=path, kinematics=fk, tool_point_m=tool,
        period_s=cutting_force_period_s(sc.cutting.mode, h),
        spindle_body_index=plant.GetBodyByName("spindle").index(), mode=sc.cutting.mode,
        samples_per_tooth=sc.cutting.samples_per_tooth, phase_rad=np.deg2rad(sc.cutting.phase_deg),
        sensor_period_s=1.0 / sc.sensor.rate_hz))
    builder.Connect(q_link, milling.get_input_port())
    builder.Connect(milling.GetOutputPort("spatial_force"), plant.get_applied_spatial_force_input_port())

    # the wrist sensor across the flange-spindle weld
    ss = sc.sensor
    sensor = builder.AddNamedSystem("wrist_sensor", WristForceSensor(
        weld_joint_index=plant.GetJointByName("sensor_weld").index(), rate_hz=ss.rate_hz,
        force_bias_N=ss.force_bias_N, torque_bias_Nm=ss.torque_bias_Nm, noise_N=ss.noise_N, noise_Nm=ss.noise_Nm,
        dropout_probability=ss.dropout_probability, spike_probability=ss.spike_probability, spike_N=ss.spike_N,
        tooth_ripple=sc.cutting.mode == "tooth"))
    builder.Connect(plant.get_reaction_forces_output_port(), sensor.GetInputPort("reaction_forces"))
    if sc.cutting.mode == "tooth":
        builder.Connect(milling.GetOutputPort("ripple_sensor"), sensor.GetInputPort("ripple"))
    add_random_inputs(builder, sensor)

    pose = builder.AddNamedSystem("tool_pose", ToolPose(fk))
    builder.Connect(q_link, pose.get_input_port())

    builder.ExportInput(arm["position_command"], "position_command")
    builder.ExportInput(arm["velocity_command"], "velocity_command")
    builder.ExportOutput(arm["reported_position"], "position_measured")
    builder.ExportOutput(arm["motor_position"], "motor_position")
    builder.ExportOutput(sensor.get_output_port(), "wrench_measured")
    builder.ExportOutput(pose.get_output_port(), "tool_pose")
    builder.ExportOutput(plant.get_state_output_port(), "plant_state")
    builder.ExportOutput(milling.GetOutputPort("wrench"), "cutting_wrench")
    diagram = builder.Build()
    diagram.set_name(name)
    systems.update(sensor=sensor, milling=milling, true_calibration=exact_payload_calibration(sc, robot))
    return MillingStation(
        diagram=diagram, plant=plant, controller_plant=arm["controller_plant"], robot=robot, tool_m=tool, servo=servo,
        joints=arm["joints"], plant_step_s=h, systems=systems, compliance_model_rad_per_Nm=1.0 / k,
        compliance_plant_rad_per_Nm=1.0 / k, lost_motion_plant_rad=arm["lost_motion_rad"],
        coupling_plant=float(sc.plant.coupling_c23_rad_per_Nm), damping_ratios=ratios)
