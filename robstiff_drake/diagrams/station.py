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
             measure; only in a station built with ``tool_pose=True``, as the
             user's measurements build it: a Python system that nothing of the
             closed loop reads costs every plant step), plant_state (12),
             cutting_wrench (6: the truth, tool point, base frame)

(The error budget's "force filter lag removed" builds the station with a
LagFreeCuttingSensor in the wrist sensor's place: its samples are the true
cutting wrench and the payload's weight, with the sensor's bias and noise,
and none of the payload's inertia; diagrams/budget.py.)

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
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import Demultiplexer

from robstiff_drake.diagrams.plant_step import NOT_GIVEN
from robstiff_drake.diagrams.scenario_step import scenario_step_s, step_choice
from robstiff_drake.diagrams.scenario_models import (  # noqa: F401 (servo_parameters re-exported)
    exact_payload_calibration, plant_damping_ratios, plant_stiffness, servo_parameters)
from robstiff_drake.diagrams.compliant_arm import (  # noqa: F401  (the arm's helpers, imported from here too)
    add_compliant_arm,
    arm_joints,
    controller_model,
    gravity_holding_torque,
    gravity_stiffness,
    joint_model,
    mass_and_weight_stiffness,
    modal_frequencies_hz,
    motor_inertia,
    natural_frequencies,
    path_poses,
    set_drives_at_rest,
    static_link_angles,
    unresolved_tooth_message,
    unstable_step_message,
)
from robstiff_drake.model import joint_dynamics, tick_kernels, transmission
from robstiff_drake.model import servo as servo_model
from robstiff_drake.model.payload import payload_wrench
from robstiff_drake.model.realtime import DeflectionPredictor
from robstiff_drake.model.servo import ServoParameters
from robstiff_drake.systems.leaf_system import LeafSystem
from robstiff_drake.systems.milling_force import MillingForceSource
from robstiff_drake.systems.regenerative_force import RegenerativeForceSource
from robstiff_drake.systems.wrist_sensor import LagFreeCuttingSensor, WristForceSensor, add_random_inputs


def resolve_integral_corner(sc, robot, q_rad):
    """Write the drives' integral corner the station chooses at pose q
    (its first pose: servo.velocity_integral "antiresonance",
    model/servo.integral_corner_hz) into ``sc.servo.velocity_integral_hz``
    before a station is built (a stated corner is left as it is); returns
    it (Hz)."""
    if sc.servo.velocity_integral == "antiresonance":
        M, G = mass_and_weight_stiffness(controller_model(robot), q_rad)
        K = joint_dynamics.stiffness_matrix(plant_stiffness(sc, robot), sc.plant.coupling_c23_rad_per_Nm)
        f_ar = joint_dynamics.held_modes(M, K, G)[0][0] / (2 * np.pi)
        sc.servo.velocity_integral_hz = float(servo_model.with_integral_corner(servo_parameters(sc), f_ar)
                                              .velocity_integral_hz)
    return float(sc.servo.velocity_integral_hz)


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
    joints: object  # model/joint_dynamics.JointModel at the start pose (modes, damping: fitted along the path, drives)
    plant_step_s: float
    systems: dict
    compliance_model_rad_per_Nm: np.ndarray  # the controller's (absolute-accuracy) gear compliance
    compliance_plant_rad_per_Nm: np.ndarray
    lost_motion_plant_rad: np.ndarray  # the gears' play, half-width (rad)
    coupling_plant: float
    damping_ratios: np.ndarray  # per mode, as stated (on the drives-closed arm modes unless plant.damping_on)

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


# The revolution-averaged cutting force is updated every 4 ms (or every plant step, if longer): it changes
# with the cutter's engagement over millimetres of feed, and the cutter moves 0.08-0.24 mm per update at
# 20-60 mm/s (the time-step study, studies/time_step_convergence.py, compares it with an update every
# plant step).  Tooth-resolved, it is updated every plant step.
AVERAGED_FORCE_PERIOD_S = 0.004


def cutting_force_period_s(mode, plant_step_s):
    """How often the milling force source updates the cutting load (s)."""
    return max(plant_step_s, AVERAGED_FORCE_PERIOD_S) if mode == "averaged" else plant_step_s


def make_milling_station(sc, robot, *, path, force_model, workpiece, q_modes_rad, check_stability=True,
                         name="milling_station", tool_pose=False):
    """The station of scenario ``sc`` (see module docstring).  ``path`` (the
    planned path: the cut's feed direction) and ``force_model``/``workpiece``
    (the process), ``q_modes_rad`` the pose (or the path's poses,
    compliant_arm.path_poses, the first first) whose modes set the damping
    and tune the drives (and choose their integral corner: scenario
    servo.velocity_integral, which the chosen corner is written back to).
    The plant step: the scenario's plant_config.time_step, or when it gives
    none the step chosen for this arm (diagrams/scenario_step.scenario_step_s,
    written into the scenario).  Raises ValueError if the plant step is
    unstable for these joints (unless ``check_stability`` is false).
    ``tool_pose``: export the output ``tool_pose`` (see the module docstring)."""
    tool = robot.tool_point(where="the closed loop")
    if step_choice(sc) is not None:  # a step chosen, not given: chosen again for this arm and its physics
        sc.plant_config.time_step = NOT_GIVEN
    h = scenario_step_s(sc, robot, q_modes_rad)
    k = np.asarray(plant_stiffness(sc, robot), dtype=float)
    servo = servo_parameters(sc)
    builder = DiagramBuilder()
    ratios = plant_damping_ratios(sc)
    arm = add_compliant_arm(builder, robot=robot, plant_config=sc.plant_config, joint_stiffness_Nm_per_rad=k,
                            damping_ratios=ratios, q_modes_rad=q_modes_rad, servo=servo,
                            interpolator_period_s=sc.servo.interpolator_period_ms / 1e3,
                            lost_motion_rad=sc.plant.lost_motion_rad,
                            coupling_c23_rad_per_Nm=sc.plant.coupling_c23_rad_per_Nm,
                            check_stability=check_stability, damping_on=sc.plant.damping_on,
                            gap_friction_Nm=sc.plant.gap_friction_Nm or None)
    servo = arm["servo_parameters"]  # the drives' own, their integral corner chosen
    # the corner the drives got, where the run's settings and the compensator's servo model read it
    sc.servo.velocity_integral_hz = float(servo.velocity_integral_hz)
    plant = arm["plant"]
    # the regenerative chip (cutting.chip; tooth-resolved only: a twin that averages the force keeps the program's)
    regenerative = sc.cutting.chip == "regenerative" and sc.cutting.mode == "tooth"
    why = unresolved_tooth_message(arm["joints"], force_model.cutter.tooth_pass_hz, h, regenerative) \
        if sc.cutting.mode == "tooth" and check_stability else None
    if why:
        raise ValueError(why)
    systems = {key: arm[key] for key in ("plant", "controller_plant", "servo", "servo_parameters", "interpolator",
                                         "touch_off", "joints", "gear_torque_at_rest")}

    # the process: the cutting load at the actual tool point and from its actual motion, on the spindle
    lag_free = bool(getattr(sc, "_lag_free_cutting_sensor", False))  # (the error budget's; LagFreeCuttingSensor)
    q_link = None
    if tool_pose or lag_free:  # (the link angles split off for the tool's pose; the milling force reads the state)
        state_demux = builder.AddNamedSystem("state_demux", Demultiplexer([6, 6]))
        builder.Connect(plant.get_state_output_port(), state_demux.get_input_port())
        q_link = state_demux.get_output_port(0)
    fk = DeflectionPredictor(robot.dh, k, tool)
    tick_kernels.warm_up(fk.chain_constants())  # (the milling force's compiled kernels loaded now, not in a timed run)
    source = RegenerativeForceSource if regenerative and hasattr(force_model, "chip_forces") else MillingForceSource
    milling = builder.AddNamedSystem("milling_force", source(
        force_model=force_model, workpiece=workpiece, path=path, kinematics=fk, tool_point_m=tool,
        period_s=cutting_force_period_s(sc.cutting.mode, h),
        spindle_body_index=plant.GetBodyByName("spindle").index(), mode=sc.cutting.mode,
        samples_per_tooth=sc.cutting.samples_per_tooth, phase_rad=np.deg2rad(sc.cutting.phase_deg),
        sensor_period_s=1.0 / sc.sensor.rate_hz, link_state=True))
    builder.Connect(plant.get_state_output_port(), milling.get_input_port())
    builder.Connect(milling.GetOutputPort("spatial_force"), plant.get_applied_spatial_force_input_port())

    # the wrist sensor across the flange-spindle weld
    ss = sc.sensor
    common = dict(weld_joint_index=plant.GetJointByName("sensor_weld").index(), rate_hz=ss.rate_hz,
                  force_bias_N=ss.force_bias_N, torque_bias_Nm=ss.torque_bias_Nm, noise_N=ss.noise_N,
                  noise_Nm=ss.noise_Nm, dropout_probability=ss.dropout_probability,
                  spike_probability=ss.spike_probability, spike_N=ss.spike_N)
    if lag_free:
        sensor = builder.AddNamedSystem("wrist_sensor", LagFreeCuttingSensor(
            tool_m=tool, payload=exact_payload_calibration(sc, robot), **common))
    else:
        sensor = builder.AddNamedSystem("wrist_sensor", WristForceSensor(
            tooth_ripple=sc.cutting.mode == "tooth", **common))
        builder.Connect(plant.get_reaction_forces_output_port(), sensor.GetInputPort("reaction_forces"))
    if sc.cutting.mode == "tooth" and not lag_free:
        builder.Connect(milling.GetOutputPort("ripple_sensor"), sensor.GetInputPort("ripple"))
        for port in ("instant_table", "instant_times"):  # (the table the sensor reads first: no Python call)
            builder.Connect(milling.GetOutputPort(port), sensor.GetInputPort(port))
    add_random_inputs(builder, sensor)

    pose = None
    if tool_pose or lag_free:
        pose = builder.AddNamedSystem("tool_pose", ToolPose(fk))
        builder.Connect(q_link, pose.get_input_port())
    if lag_free:
        builder.Connect(milling.GetOutputPort("wrench"), sensor.GetInputPort("cutting_wrench"))
        builder.Connect(pose.get_output_port(), sensor.GetInputPort("tool_pose"))

    builder.ExportInput(arm["position_command"], "position_command")
    builder.ExportInput(arm["velocity_command"], "velocity_command")
    builder.ExportOutput(arm["reported_position"], "position_measured")
    builder.ExportOutput(arm["motor_position"], "motor_position")
    builder.ExportOutput(sensor.get_output_port(), "wrench_measured")
    if tool_pose:
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
