"""The compliant arm of the station (diagrams/station.py): a discrete
MultibodyPlant of the links, each driven through its gear (stiffness,
play, modal damping) by a motor with its rotor's inertia that a
torque-level drive turns, the robot controller's absolute-accuracy gravity
model (its reference and its torque feed-forward) and the interpolator's
dead time; the joints' linear model (model/joint_dynamics.py) at a pose.
The checks of the plant's step (its modes stable, the play and a
tooth-resolved force resolved) are diagrams/plant_step.py's."""

import numpy as np
from pydrake.multibody.plant import AddMultibodyPlant, MultibodyPlant
from pydrake.systems.controllers import InverseDynamics
from pydrake.systems.primitives import (
    ConstantVectorSource,
    Demultiplexer,
    DiscreteTimeDelay,
    LinearSystem,
    MatrixGain,
    Multiplexer,
    ZeroOrderHold,
)

from robstiff_drake.model import joint_dynamics, transmission
from robstiff_drake.model import servo as servo_model
from robstiff_drake.diagrams.plant_step import (  # noqa: F401  (the step's checks, imported from here too)
    RESOLVED_OMEGA_H,
    TOOTH_STEPS_PER_PASS,
    StepError,
    contact_frequencies_hz,
    resolving_step_s,
    step_on_grid_s,
    tooth_resolving_step_s,
    twist_inertia_kgm2,
    under_resolved_play_message,
    unresolved_tooth_message,
    unstable_step_message,
    unstable_step_refusal,
)
from robstiff_drake.plant import add_robot, check_plant_matches
from robstiff_drake.systems.gear_transmission import GearPlay


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
    """The motors' rotor inertias reflected to the joints (6,, kg*m^2):
    model/joint_dynamics.motor_inertia (the robot file's, or the rule there)."""
    return joint_dynamics.motor_inertia(robot, M)


def joint_model(controller_plant, robot, q_rad, stiffness_matrix, damping_ratios, servo, damping_on="drives_closed"):
    """The linear joints (model/joint_dynamics.JointModel) at pose q: the
    controller model's mass matrix and weight's stiffness, the gears, their
    modal damping (``damping_ratios``, per mode or one for all, on the
    modes ``damping_on`` names: drives_closed or motors_held), the motors
    and drives (velocity loops tuned for the rigid axes at q, the integral
    corner chosen there when the servo's rule says so)."""
    M, G = mass_and_weight_stiffness(controller_plant, q_rad)
    return joint_dynamics.linear_joints(M, G, stiffness_matrix, damping_ratios, servo, motor_inertia(robot, M),
                                        stated_on=damping_on)


# The poses along a path the gears' damping is fitted over (diagrams/compliant_arm.path_poses): this many, evenly
# spaced in the path's time (studies/damping_along_path.py measures the fit's damping at 64).
PATH_DAMPING_SAMPLES = 16


def path_poses(q_ref_rad, n=PATH_DAMPING_SAMPLES):
    """(n, 6) rows of a path's joint references (N, 6) evenly spaced, the
    first row first: the poses ``arm_joints`` fits the damping over."""
    q = np.atleast_2d(np.asarray(q_ref_rad, dtype=float))
    return q[np.unique(np.linspace(0, len(q) - 1, min(n, len(q))).round().astype(int))]


def mass_and_weight_stiffness(controller_plant, q_rad):
    """(M (6, 6) kg*m^2, G (6, 6) N*m/rad) of the controller's model at q."""
    ctx = controller_plant.CreateDefaultContext()
    q = np.asarray(q_rad, dtype=float)
    G = gravity_stiffness(controller_plant, ctx, q)
    controller_plant.SetPositions(ctx, q)
    return controller_plant.CalcMassMatrix(ctx), G


def arm_joints(controller_plant, robot, q_modes_rad, stiffness_matrix, damping_ratios, servo,
               damping_on="drives_closed"):
    """The JointModel the station builds: ``joint_model`` at the first pose
    of ``q_modes_rad`` (one pose (6,), or the poses a path visits (n, 6):
    ``path_poses``), which tunes the drives and chooses their integral
    corner; with several poses and the damping stated on the drives-closed
    modes, one gears' damping fitted over them all
    (model/joint_dynamics.fit_path_damping)."""
    q = np.atleast_2d(np.asarray(q_modes_rad, dtype=float))
    # (the key: the arm as the controller's model has it at the poses, its mass matrices and weight, not its name)
    ctx = controller_plant.CreateDefaultContext()
    arm = []
    for qi in q:
        controller_plant.SetPositions(ctx, qi)
        arm += [controller_plant.CalcMassMatrix(ctx).tobytes(),
                controller_plant.CalcGravityGeneralizedForces(ctx).tobytes()]
    key = (tuple(arm), q.tobytes(), np.asarray(motor_inertia(robot, np.eye(6)), dtype=float).tobytes(),
           np.asarray(stiffness_matrix, dtype=float).tobytes(), np.asarray(damping_ratios, dtype=float).tobytes(),
           servo, damping_on)
    if key in _ARM_JOINTS:
        return _ARM_JOINTS[key]
    jm = joint_model(controller_plant, robot, q[0], stiffness_matrix, damping_ratios, servo, damping_on)
    if len(q) > 1 and damping_on == "drives_closed":
        jm = joint_dynamics.fit_path_damping(jm, [(jm.M, jm.G)] + [mass_and_weight_stiffness(controller_plant, qi)
                                                                   for qi in q[1:]], damping_ratios)
    if len(_ARM_JOINTS) >= 16:
        del _ARM_JOINTS[next(iter(_ARM_JOINTS))]
    _ARM_JOINTS[key] = jm
    return jm


_ARM_JOINTS = {}  # arm_joints' results per setup (a cell's runs build the same station several times)


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
                      check_stability=True, damping_on="drives_closed", gap_friction_Nm=None,
                      check_resolution=True):
    """The arm and its drives: a discrete MultibodyPlant (``plant_config``)
    of the links, each driven through its gear by a motor with its rotor's
    inertia, which a torque-level drive turns (model/servo.py); the robot
    controller's absolute-accuracy gravity model (its reference and its
    torque feed-forward) and the interpolator's dead time (see the module
    docstring).

    Gear j carries tau = K dz(theta - q) + D (theta' - q') onto the link
    and minus that onto its motor: K the gears' stiffness (with the 2-3
    coupling), dz the play's dead zone (``lost_motion_rad``: half-widths;
    none: dz(x) = x), D the modal damping that gives each drives-closed arm
    mode (``damping_on`` "motors_held": each motors-held mode) its ratio in
    ``damping_ratios`` (model/joint_dynamics.py, at ``q_modes_rad``: a pose,
    or the poses a path visits, the first tuning the drives, one D fitted
    over them all: ``arm_joints``; the drives' integral corner chosen at
    the first when the servo's rule says so: the drives are built with
    ``joints.servo``).  Without play the torque is one MatrixGain (no Python
    in the step), with play systems/gear_transmission.GearPlay.  The gear's
    torque is explicit over a step (symplectic Euler in the plant, the
    drives exact with it held): the links' side alone would be stable
    while omega h < 2, but the motors' side, stepped with the torque held,
    feeds a mode that moves a motor, so such a mode holds only to a
    smaller omega h set by its damping (model/joint_dynamics.py; checked
    on the step map: diagrams/plant_step.unstable_step_refusal).

    Returns a dict: plant, controller_plant (the controller's model: keep it
    alive with the diagram), ``position_command`` and ``velocity_command``
    (input ports), ``motor_state`` (output port: theta, theta'),
    ``motor_position``, ``reported_position`` (output port: the motor angles
    less the controller's gravity model), ``gear_torque`` (output port),
    ``servo`` (the drives' LinearSystem), ``interpolator`` (its blocks),
    joints (the JointModel), natural_frequencies_hz (motors held).  Raises
    ValueError, naming the step that would do, if the step is unstable for
    these joints (unless ``check_stability`` is false) or does not resolve
    a gear with play's flank impacts (``under_resolved_play_message``;
    unless ``check_resolution`` is false).  ``gap_friction_Nm``: the
    Coulomb torque inside each play (N*m; None or empty: the plant's,
    model/transmission.gap_friction_Nm; zeros: none)."""
    k = np.asarray(joint_stiffness_Nm_per_rad, dtype=float)
    # ASSUMPTION: the absolute-accuracy model is calibrated for this arm (as
    # ABB calibrates each robot with the option): its gravity model uses the
    # gears' true linear stiffness; their play and coupling are not in it
    # (the touch-off absorbs their static part at the start pose).
    k_model = k
    h = float(plant_config.time_step)
    if not h > 0:  # (a scenario's step not given: diagrams/scenario_step.scenario_step_s chooses it first)
        raise ValueError(f"the plant step must be given here (got {h:g} s)")
    plant, _ = AddMultibodyPlant(plant_config, builder)
    plant.set_name("plant")
    add_robot(plant, robot)
    plant.Finalize()
    ctrl = controller_model(robot)
    Kg = joint_dynamics.stiffness_matrix(k, coupling_c23_rad_per_Nm)
    jm = arm_joints(ctrl, robot, q_modes_rad, Kg, damping_ratios, servo, damping_on)
    servo = jm.servo  # (its integral corner chosen)
    refusal = (unstable_step_refusal(jm, h, assumed_motor_inertia=robot.motor_inertia_kgm2 is None)
               if check_stability else None)
    if refusal:
        raise StepError(refusal)  # (its line the error, its detail the why: diagrams/plant_step.py)

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
        why = under_resolved_play_message(jm, b, h) if check_resolution else None
        if why:
            raise ValueError(why)
        friction = (transmission.gap_friction_Nm(Kg) if gap_friction_Nm is None or not len(gap_friction_Nm)
                    else np.asarray(gap_friction_Nm, dtype=float))
        gear = builder.AddNamedSystem("gear_transmission", GearPlay(
            stiffness_Nm_per_rad=Kg, damping_Nms_per_rad=jm.D, play_rad=b,
            gap_friction_Nm=friction if np.any(friction) else None, gap_inertia_kgm2=twist_inertia_kgm2(jm),
            step_s=h))
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
