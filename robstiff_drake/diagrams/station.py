"""The milling station: everything of the cell that is hardware, as one
Drake diagram with its ports exported by name (the shape of Drake's
hardware_sim station and of the manipulation station):

    position_command (6, rad) ---+
    velocity_command (6, rad/s) -+-> robot controller: absolute-accuracy
                                    gravity model theta_ref = q_cmd + C g(q_cmd)
                                    -> interpolator (dead time)
                                    -> servo (position / velocity loop) -> motor theta
    motor theta -> gear (spring K, damping, lost motion) -> link q   (MultibodyPlant)
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
what its model misses at the start pose (a stiffer or softer gear, lost motion taken up by the
arm's weight) is zeroed by touching off there: a constant joint offset,
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

from robstiff_drake.diagrams.scenario import exact_payload_calibration, plant_step_s, plant_stiffness
from robstiff_drake.model import transmission
from robstiff_drake.model.payload import payload_wrench
from robstiff_drake.model.realtime import DeflectionPredictor
from robstiff_drake.model.servo import ServoParameters
from robstiff_drake.plant import JOINT_NAMES, add_robot, check_plant_matches
from robstiff_drake.systems.gear_transmission import GearTransmission
from robstiff_drake.systems.milling_force import MillingForceSource
from robstiff_drake.systems.wrist_sensor import WristForceSensor, add_random_inputs


def modal_frequencies_hz(M, k_Nm_per_rad):
    """Undamped natural frequencies (Hz) of joint springs k with the mass
    matrix M (motors held), ascending."""
    w2 = np.linalg.eigvals(np.linalg.solve(M, np.diag(k_Nm_per_rad))).real
    return np.sort(np.sqrt(np.maximum(w2, 0.0))) / (2 * np.pi)


def natural_frequencies(plant, context, q, k_Nm_per_rad):
    """Undamped natural frequencies (Hz) of the joint springs at q (motors
    held), ascending."""
    plant.SetPositions(context, q)
    return modal_frequencies_hz(plant.CalcMassMatrix(context), k_Nm_per_rad)


def stiffness_proportional_beta_s(freqs_hz, damping_ratio):
    """beta (s) of the damping D = beta K that gives the first mode
    ``damping_ratio``: beta = 2 zeta / omega_1 (the higher modes get more)."""
    return 2.0 * damping_ratio / (2.0 * np.pi * float(freqs_hz[0]))


def spring_step_is_stable(freqs_hz, beta_s, time_step_s):
    """Whether every joint-spring mode is stable in the plant's discrete step.

    The step is symplectic Euler for the spring (explicit: the gear torque
    is computed from the state at the start of the step) with the joint
    damping implicit (the discrete solver's).  For a mode of frequency w with
    stiffness-proportional damping 2 zeta w = beta w^2, the step's amplification
    matrix has determinant a = 1 / (1 + beta w^2 h) and trace
    1 + a - a h^2 w^2, so it is stable iff h^2 w^2 < 4 + 2 beta w^2 h:
    for every mode when beta >= h / 2, otherwise while w^2 (h^2 - 2 beta h) < 4."""
    w2 = (2 * np.pi * np.asarray(freqs_hz, dtype=float)) ** 2
    h = float(time_step_s)
    return bool(np.all(h * h * w2 < 4.0 + 2.0 * beta_s * w2 * h))


def unstable_step_message(freqs_hz, beta_s, time_step_s, damping_ratio):
    """None when the plant step is stable for every joint mode, else why not
    (one line)."""
    if spring_step_is_stable(freqs_hz, beta_s, time_step_s):
        return None
    w2 = (2 * np.pi * np.asarray(freqs_hz)) ** 2
    h = time_step_s
    worst = float(np.asarray(freqs_hz)[np.argmax(h * h * w2 - 2.0 * beta_s * w2 * h)])
    return (f"a {h * 1e3:g} ms plant step is unstable for the {worst:.0f} Hz joint mode at damping ratio "
            f"{damping_ratio:g}: shorten the step or raise the damping (every mode is stable when "
            f"beta = 2 zeta / omega_1 >= step / 2; here beta = {beta_s * 1e3:.2f} ms)")


def servo_parameters(sc):
    s = sc.servo
    return ServoParameters(position_gain_per_s=s.position_gain_per_s, velocity_bandwidth_hz=s.velocity_bandwidth_hz,
                           velocity_feedforward=s.velocity_feedforward,
                           interpolator_delay_s=s.interpolator_delay_ms / 1e3)


def controller_model(robot):
    """The robot controller's own model of the arm and payload (a
    continuous MultibodyPlant, finalized): its gravity model, and the arm's
    modes.  Keep it alive as long as a diagram that uses it."""
    plant = MultibodyPlant(0.0)
    add_robot(plant, robot)
    plant.Finalize()
    check_plant_matches(plant, robot)
    return plant


def gravity_holding_torque(controller_plant, q):
    """The joint torques (N*m) that hold the arm and payload still at q
    (minus the generalized gravity forces)."""
    ctx = controller_plant.CreateDefaultContext()
    controller_plant.SetPositions(ctx, q)
    return -controller_plant.CalcGravityGeneralizedForces(ctx)


def static_link_angles(controller_plant, theta, compliance, lost_motion_rad=None, coupling_c23=0.0, iterations=50):
    """The link angles q (rad) at which gears with this transmission law,
    their motors held at ``theta``, hold the arm still against gravity:
    q = theta - twist(g(q)), by fixed-point iteration (the twist is a few
    mrad, so it converges at once)."""
    q = np.array(theta, dtype=float)
    for _ in range(iterations):
        q_new = theta - transmission.twist(gravity_holding_torque(controller_plant, q), compliance, lost_motion_rad,
                                           coupling_c23)
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
    natural_frequencies_hz: np.ndarray
    damping_beta_s: float
    plant_step_s: float
    systems: dict
    compliance_model_rad_per_Nm: np.ndarray  # the controller's (absolute-accuracy) gear compliance
    compliance_plant_rad_per_Nm: np.ndarray
    lost_motion_plant_rad: np.ndarray
    coupling_plant: float

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
        theta = q + transmission.twist(hold, self.compliance_plant_rad_per_Nm, self.lost_motion_plant_rad,
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
        set_drives_at_rest(s, root_context, theta)
        s["sensor"].GetMyMutableContextFromRoot(root_context).SetDiscreteState(wrench)
        return theta, q, wrench


def set_drives_at_rest(arm, root_context, theta):
    """Every sample of ``arm``'s interpolator and servo (the systems
    add_compliant_arm returns under "interpolator" and "servo") at rest at
    the motor angles ``theta`` (rad)."""
    ref = np.concatenate([theta, np.zeros(6)])
    for block in [arm["servo"]] + list(arm["interpolator"]):
        ctx = block.GetMyMutableContextFromRoot(root_context)
        ctx.SetDiscreteState(np.tile(ref, ctx.get_discrete_state_vector().size() // 12))


def add_compliant_arm(builder, *, robot, plant_config, joint_stiffness_Nm_per_rad, damping_ratio, q_modes_rad,
                      servo, interpolator_period_s, lost_motion_rad=None, coupling_c23_rad_per_Nm=0.0,
                      check_stability=True):
    """The arm and its drives: a discrete MultibodyPlant (``plant_config``)
    whose joints are gears between the motor angle and the link angle, the
    robot controller's absolute-accuracy gravity model, the interpolator's
    dead time and the motor-side servo (see the module docstring).

    Gear j carries tau_j = K_j (theta_j - q_j) + beta K_j (theta'_j - q'_j)
    (with lost motion or coupling: the law of model/transmission.py).  The
    spring and the damping's beta K theta' come from the "gear_spring"
    block (a MatrixGain: no Python in the plant step) and are explicit over
    a step; beta K q' is the joints' own damping, which the discrete solver
    treats implicitly.  That step (symplectic Euler with implicit damping)
    adds no numerical damping to the spring and is stable for every mode
    when beta >= h / 2 (``spring_step_is_stable``); a higher mode's
    frequency comes out 2 / h asin(w h / 2) instead of w.

    beta = 2 zeta / omega_1 with omega_1 the first natural frequency at
    ``q_modes_rad`` (motors held).  Returns a dict: plant, controller_plant
    (the controller's model: keep it alive with the diagram),
    ``position_command`` and ``velocity_command`` (input ports),
    ``motor_state`` (output port: theta, theta'), ``reported_position``
    (output port: the motor angles less the controller's gravity model),
    ``servo`` (the LinearSystem), ``interpolator`` (its blocks),
    natural_frequencies_hz, beta_s.  Raises ValueError if the step is
    unstable for these joints and damping (unless ``check_stability`` is
    false: the test that the criterion is the plant's own)."""
    k = np.asarray(joint_stiffness_Nm_per_rad, dtype=float)
    # ASSUMPTION: the absolute-accuracy model is calibrated for this arm (as
    # ABB calibrates each robot with the option): its gravity model uses the
    # gears' true linear stiffness; their lost motion and coupling are not in
    # it (the touch-off absorbs their static part at the start pose).
    k_model = k
    h = float(plant_config.time_step)
    plant, _ = AddMultibodyPlant(plant_config, builder)
    plant.set_name("plant")
    instance = add_robot(plant, robot)
    ctrl = controller_model(robot)
    freqs = natural_frequencies(ctrl, ctrl.CreateDefaultContext(), q_modes_rad, k)
    beta = stiffness_proportional_beta_s(freqs, damping_ratio)
    why = unstable_step_message(freqs, beta, h, damping_ratio) if check_stability else None
    if why:
        raise ValueError(why)
    for i, jname in enumerate(JOINT_NAMES):
        plant.GetMutableJointByName(jname, instance).set_default_damping(beta * k[i])
    plant.Finalize()

    # the robot controller: absolute-accuracy gravity model, interpolator, servo
    cmd_in = builder.AddNamedSystem("position_command_in", Multiplexer([6]))
    vel_in = builder.AddNamedSystem("velocity_command_in", Multiplexer([6]))
    zeros = builder.AddNamedSystem("zero_velocity", ConstantVectorSource(np.zeros(6)))
    # the touch-off offset: a parameter in the Context, set by MillingStation.set_initial_state
    offset = builder.AddNamedSystem("touch_off_offset", ConstantVectorSource(np.zeros(6)))

    def gravity_twist(angles, name, sign):
        """sign * C_model g(angles): the controller's model of the gears'
        twist under gravity (InverseDynamics: C++, no Python per step)."""
        as_state = builder.AddNamedSystem(f"{name}_as_state", Multiplexer([6, 6]))
        builder.Connect(angles, as_state.get_input_port(0))
        builder.Connect(zeros.get_output_port(), as_state.get_input_port(1))
        gravity = builder.AddNamedSystem(f"{name}_gravity", InverseDynamics(
            ctrl, InverseDynamics.InverseDynamicsMode.kGravityCompensation))
        builder.Connect(as_state.get_output_port(), gravity.get_input_port_estimated_state())
        terms = builder.AddNamedSystem(f"{name}_terms", Multiplexer([6, 6, 6]))
        builder.Connect(angles, terms.get_input_port(0))
        builder.Connect(gravity.get_output_port(), terms.get_input_port(1))
        builder.Connect(offset.get_output_port(), terms.get_input_port(2))
        # angles + sign (C_model g + offset), one gain
        total = builder.AddNamedSystem(name, MatrixGain(np.hstack([np.eye(6), sign * np.diag(1.0 / k_model),
                                                                   sign * np.eye(6)])))
        builder.Connect(terms.get_output_port(), total.get_input_port())
        return total.get_output_port()

    theta_ref = gravity_twist(cmd_in.get_output_port(), "motor_reference", 1.0)
    ref = builder.AddNamedSystem("servo_reference", Multiplexer([6, 6]))
    builder.Connect(theta_ref, ref.get_input_port(0))
    builder.Connect(vel_in.get_output_port(), ref.get_input_port(1))
    n_i = int(round(servo.interpolator_delay_s / interpolator_period_s))
    last, interp = ref.get_output_port(), []
    if abs(interpolator_period_s - h) < 1e-12:
        # the interpolator runs at the plant's step: its dead time is a shift
        # register inside the servo's LinearSystem (one discrete update, not three)
        # (n + 1 samples: the same dead time as a hold and a delay line of n - 1 in front of it)
        A, B, C, D = servo.discrete_with_delay(h, n_i + 1 if n_i else 0)
        n_i = 0
    else:
        A, B, C, D = servo.discrete(h)
    if n_i >= 1:  # n periods: a hold adds one, a delay line the rest (same-instant semantics)
        interp.append(builder.AddNamedSystem("interpolator_hold", ZeroOrderHold(interpolator_period_s, 12)))
        if n_i >= 2:
            interp.append(builder.AddNamedSystem("interpolator_delay",
                                                 DiscreteTimeDelay(interpolator_period_s, n_i - 1, 12)))
        for block in interp:
            builder.Connect(last, block.get_input_port())
            last = block.get_output_port()
    servo_sys = builder.AddNamedSystem("joint_servo", LinearSystem(A, B, C, D, h))
    builder.Connect(last, servo_sys.get_input_port())
    motor = servo_sys.get_output_port()  # (theta, theta')

    # the gears: K (theta_eff - q) + beta K theta' (and -beta K q', the joints' own damping)
    b = np.asarray(lost_motion_rad if lost_motion_rad is not None and len(lost_motion_rad) else np.zeros(6),
                   dtype=float)
    if np.any(b) or coupling_c23_rad_per_Nm:
        gear = builder.AddNamedSystem("gear_transmission", GearTransmission(
            joint_stiffness_Nm_per_rad=k, lost_motion_rad=list(b), coupling_c23_rad_per_Nm=coupling_c23_rad_per_Nm))
        builder.Connect(motor, gear.GetInputPort("motor_state"))
        builder.Connect(plant.get_state_output_port(), gear.GetInputPort("link_state"))
        motor_eff = gear.get_output_port()
    else:
        motor_eff = motor
    K = np.diag(k)
    Z = np.zeros((6, 6))
    spring_in = builder.AddNamedSystem("gear_inputs", Multiplexer([12, 12]))
    spring = builder.AddNamedSystem("gear_spring", MatrixGain(np.hstack([K, beta * K, -K, Z])))
    builder.Connect(motor_eff, spring_in.get_input_port(0))
    builder.Connect(plant.get_state_output_port(), spring_in.get_input_port(1))
    builder.Connect(spring_in.get_output_port(), spring.get_input_port())
    builder.Connect(spring.get_output_port(), plant.get_actuation_input_port())

    # what the controller reports: the encoders less its gravity model
    motor_demux = builder.AddNamedSystem("motor_demux", Demultiplexer([6, 6]))
    builder.Connect(motor, motor_demux.get_input_port())
    reported = gravity_twist(motor_demux.get_output_port(0), "position_reported", -1.0)
    return {"plant": plant, "controller_plant": ctrl, "position_command": cmd_in.get_input_port(0),
            "velocity_command": vel_in.get_input_port(0), "motor_state": motor,
            "motor_position": motor_demux.get_output_port(0), "reported_position": reported, "servo": servo_sys,
            "interpolator": interp, "touch_off": offset, "natural_frequencies_hz": freqs, "beta_s": beta,
            "lost_motion_rad": b}


def make_milling_station(sc, robot, *, path, force_model, workpiece, q_modes_rad, check_stability=True,
                         name="milling_station"):
    """The station of scenario ``sc`` (see module docstring).  ``path`` (the
    planned path: the cut's feed direction) and ``force_model``/``workpiece``
    (the process), ``q_modes_rad`` the pose whose modes set the damping.
    Raises ValueError if the plant step is unstable for these joints and
    damping (unless ``check_stability`` is false)."""
    tool = robot.tool_point(where="the closed loop")
    h = plant_step_s(sc)
    k = np.asarray(plant_stiffness(sc, robot), dtype=float)
    servo = servo_parameters(sc)
    builder = DiagramBuilder()
    arm = add_compliant_arm(builder, robot=robot, plant_config=sc.plant_config, joint_stiffness_Nm_per_rad=k,
                            damping_ratio=sc.plant.damping_ratio, q_modes_rad=q_modes_rad, servo=servo,
                            interpolator_period_s=sc.servo.interpolator_period_ms / 1e3,
                            lost_motion_rad=sc.plant.lost_motion_rad,
                            coupling_c23_rad_per_Nm=sc.plant.coupling_c23_rad_per_Nm,
                            check_stability=check_stability)
    plant = arm["plant"]
    systems = {"servo": arm["servo"], "interpolator": arm["interpolator"], "touch_off": arm["touch_off"]}

    # the process: the cutting load at the actual tool point, on the spindle
    state_demux = builder.AddNamedSystem("state_demux", Demultiplexer([6, 6]))
    builder.Connect(plant.get_state_output_port(), state_demux.get_input_port())
    q_link = state_demux.get_output_port(0)
    fk = DeflectionPredictor(robot.dh, k, tool)
    milling = builder.AddNamedSystem("milling_force", MillingForceSource(
        force_model=force_model, workpiece=workpiece, path=path, kinematics=fk, tool_point_m=tool, period_s=h,
        spindle_body_index=plant.GetBodyByName("spindle").index(), mode=sc.cutting.mode,
        samples_per_tooth=sc.cutting.samples_per_tooth, phase_rad=np.deg2rad(sc.cutting.phase_deg)))
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
        natural_frequencies_hz=arm["natural_frequencies_hz"], damping_beta_s=arm["beta_s"], plant_step_s=h,
        systems=systems, compliance_model_rad_per_Nm=1.0 / k,
        compliance_plant_rad_per_Nm=1.0 / k, lost_motion_plant_rad=arm["lost_motion_rad"],
        coupling_plant=float(sc.plant.coupling_c23_rad_per_Nm))
