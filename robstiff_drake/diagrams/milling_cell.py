"""The robotic milling cell as one Drake diagram: the compliant-joint
IRB6400, the path source, the milling force source, the wrist sensor and the
real-time compensation chain of the seed's Fig. 5.

    path (TrajectorySource: q_ref, v_ref) ----------------------------+
                                                                      v
    joint_servo: K_q (q_cmd - q) + beta K_q v_cmd <-- desired state = q_ref + correction
      |  + gravity feed-forward (InverseDynamics)                     ^
      v                                                               |
    plant (discrete MultibodyPlant, joint damping beta K_q)           |
      |  +-- cutting wrench <-- MillingForceSource(q)                 |
      +-- reaction at the flange-spindle weld --> WristForceSensor    |
            --> WrenchGuard --> force filter (LinearSystem)           |
            --> ZOH(T) --> GravityRemoval(q) --> DeflectionPrediction(q)
            --> Saturation --> DiscreteTimeDelay(T, n) --> RateLimitedCorrection(T)

Sample-and-hold timing (Drake's same-instant semantics: a discrete block
updated at the same tick as its source sees the source's previous value):
a change of the true wrench reaches the correction after one sensor sample
(sensor), one more (guard), the filter's own lag, one controller period
(ZOH), ``delay_steps`` periods (the delay block) and one more period (the
correction's own update).  ``transport_delay_s`` adds these up.
"""

from dataclasses import dataclass

import numpy as np
from pydrake.multibody.plant import AddMultibodyPlant, MultibodyPlant, MultibodyPlantConfig
from pydrake.systems.analysis import Simulator
from pydrake.systems.controllers import InverseDynamics
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import (
    Adder,
    Demultiplexer,
    DiscreteTimeDelay,
    LogVectorOutput,
    MatrixGain,
    Multiplexer,
    Saturation,
    TrajectorySource,
    ZeroOrderHold,
)
from pydrake.trajectories import PiecewisePolynomial

from robstiff_drake.diagrams.scenario import (
    exact_payload_calibration,
    model_stiffness,
    payload_calibration,
    plant_stiffness,
)
from robstiff_drake.diagrams.scenario import planned_path as scenario_path
from robstiff_drake.errors import InputError
from robstiff_drake.model.filters import filter_coefficients as model_filter_coefficients
from robstiff_drake.model.milling import Cutter, CuttingCoefficients, MillingForceModel, Workpiece
from robstiff_drake.model.path import PathError, PlannedPath
from robstiff_drake.model.realtime import DeflectionPredictor
from robstiff_drake.plant import JOINT_NAMES, add_irb6400
from robstiff_drake.systems.deflection_prediction import DeflectionPrediction
from robstiff_drake.systems.force_filter import filter_system, group_delay_s, steady_state
from robstiff_drake.systems.gravity_removal import GravityRemoval, payload_wrench
from robstiff_drake.systems.joint_effects import JointEffects
from robstiff_drake.systems.milling_force import MillingForceSource
from robstiff_drake.systems.predictive_wrench import PredictiveWrench
from robstiff_drake.systems.reference_correction import RateLimitedCorrection
from robstiff_drake.systems.wrist_sensor import WrenchGuard, WristForceSensor


@dataclass
class MillingCell:
    """A built diagram and what is needed to run and read it."""

    diagram: object
    plant: object
    scenario: object
    robot: object
    path: PlannedPath
    q_ref_times: np.ndarray
    q_ref: np.ndarray
    force_model: MillingForceModel
    workpiece: Workpiece
    tool_m: np.ndarray
    compensation: bool
    loggers: dict
    systems: dict
    initial: dict
    plant_time_step_s: float
    transport_delay_s: float
    damping_beta_s: float
    natural_frequencies_hz: np.ndarray


def cutting_setup(sc, scale=1.0):
    """(cutter, force model, workpiece); ``scale`` multiplies every
    coefficient (a compensator's model that is off by that factor)."""
    cutter = Cutter(sc.cutter.diameter_mm / 1e3, int(sc.cutter.n_teeth), sc.cutter.spindle_rpm)
    c = sc.cutting
    s, sa = c.tangential_radial_scale * scale, c.axial_scale * scale
    coeffs = CuttingCoefficients(c.Ktc_N_per_mm2 * s, c.Krc_N_per_mm2 * s, c.Kac_N_per_mm2 * sa,
                                 c.Kte_N_per_mm * s, c.Kre_N_per_mm * s, c.Kae_N_per_mm * sa)
    model = MillingForceModel(cutter, coeffs, sc.path.feed_mm_per_s / 1e3)
    workpiece = Workpiece.from_boxes(np.asarray(sc.workpiece.boxes_mm, dtype=float) / 1e3)
    return cutter, model, workpiece


def natural_frequencies(plant, context, q, k_Nm_per_rad):
    """Undamped natural frequencies (Hz) of the joint springs at q, ascending."""
    plant.SetPositions(context, q)
    M = plant.CalcMassMatrix(context)
    w2 = np.linalg.eigvals(np.linalg.solve(M, np.diag(k_Nm_per_rad))).real
    return np.sort(np.sqrt(np.maximum(w2, 0.0))) / (2 * np.pi)


_REFERENCES = {}  # IK along a path, reused by the runs of a sweep in one process


def planned_path(sc, robot, tool):
    """(PlannedPath, times, joint references) of the scenario's path; the IK
    is done once per process for a given path, robot file and tool."""
    p = sc.path
    try:
        path = scenario_path(sc)
        key = (path.signature(), p.reference_period_ms, robot.source, tuple(np.round(tool, 12)),
               robot.q_lower_rad.tobytes(), robot.q_upper_rad.tobytes())
        if key not in _REFERENCES:
            _REFERENCES[key] = path.joint_references(robot, tool, p.reference_period_ms / 1e3)
    except PathError as e:
        raise InputError(f"{sc.source}: path: {e}") from None
    t_ref, q_ref = _REFERENCES[key]
    return path, t_ref, q_ref


def stiffness_proportional_beta_s(freqs_hz, damping_ratio):
    """beta (s) of the damping D = beta K that gives the first mode
    ``damping_ratio``: beta = 2 zeta / omega_1 (the higher modes get more)."""
    return 2.0 * damping_ratio / (2.0 * np.pi * float(freqs_hz[0]))


def spring_step_is_stable(freqs_hz, beta_s, time_step_s):
    """Whether every joint-spring mode is stable in the plant's discrete step.

    The step is symplectic Euler for the spring (explicit: the servo torque
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


def check_plant_step(sc, robot):
    """Refuse, before anything runs, a scenario whose plant step is unstable
    for its joint modes at the path's first pose (InputError, one line)."""
    _, _, q_ref = planned_path(sc, robot, robot.payload.tool_point_m)
    plant = MultibodyPlant(0.0)
    add_irb6400(plant)
    plant.Finalize()
    freqs = natural_frequencies(plant, plant.CreateDefaultContext(), q_ref[0], plant_stiffness(sc, robot))
    beta = stiffness_proportional_beta_s(freqs, sc.plant.damping_ratio)
    why = unstable_step_message(freqs, beta, sc.plant.time_step_ms / 1e3, sc.plant.damping_ratio)
    if why:
        raise InputError(f"{sc.source}: plant.time_step_ms: {why}")


def add_compliant_irb6400(builder, *, time_step_s, joint_stiffness_Nm_per_rad, damping_ratio, q_modes_rad,
                          check_stability=True):
    """The compliant-joint IRB6400: a discrete MultibodyPlant whose joints
    are servo springs between the commanded and the link angle, plus the
    controller's gravity feed-forward (InverseDynamics on an exact model of
    the arm and payload), so that at rest only process loads deflect the arm.

    Joint j carries tau_j = K_j (q_cmd_j - q_j) + beta K_j (v_cmd_j - v_j)
    + g_j(q).  The spring and the damping's feed-forward beta K v_cmd come
    from the "joint_servo" block (a LinearSystem, so no Python in the plant
    step) and are explicit over a step; the damping beta K_j v_j is the
    joint's own damping, which the discrete solver treats implicitly.  That
    step (symplectic Euler with implicit damping) adds no numerical damping
    to the spring and is stable for every mode when beta >= h / 2 (see
    ``spring_step_is_stable``); a higher mode's frequency comes out
    2 / h asin(w h / 2) instead of w (+0.9 % at 37 Hz, 2 ms).  It is also
    three times cheaper than PD actuators held as solver constraints.

    beta = 2 zeta / omega_1 with omega_1 the first natural frequency at
    ``q_modes_rad``: stiffness-proportional damping, the first mode at
    ``damping_ratio`` and the higher modes more.  Returns a dict with the
    plant, its model instance, ``desired_state`` (the servo's input port:
    q_cmd, v_cmd, 12), the controller's plant (keep it alive with the
    diagram: InverseDynamics holds only a reference), the natural
    frequencies (Hz) and beta (s).  Raises ValueError if the step is
    unstable for these stiffnesses and damping (unless ``check_stability``
    is false: the test that the criterion is the plant's own)."""
    k = np.asarray(joint_stiffness_Nm_per_rad, dtype=float)
    plant, _ = AddMultibodyPlant(MultibodyPlantConfig(time_step=time_step_s, discrete_contact_approximation="sap"),
                                 builder)
    plant.set_name("plant")
    instance = add_irb6400(plant)
    controller_plant = MultibodyPlant(0.0)
    add_irb6400(controller_plant)
    controller_plant.Finalize()
    freqs = natural_frequencies(controller_plant, controller_plant.CreateDefaultContext(), q_modes_rad, k)
    beta = stiffness_proportional_beta_s(freqs, damping_ratio)
    why = unstable_step_message(freqs, beta, time_step_s, damping_ratio) if check_stability else None
    if why:
        raise ValueError(why)
    for i, name in enumerate(JOINT_NAMES):
        plant.GetMutableJointByName(name, instance).set_default_damping(beta * k[i])
    plant.Finalize()
    # servo: [q_cmd, v_cmd, q, v] -> K (q_cmd - q) + beta K v_cmd
    K = np.diag(k)
    Z = np.zeros((6, 6))
    inputs = builder.AddNamedSystem("servo_inputs", Multiplexer([12, 12]))
    servo = builder.AddNamedSystem("joint_servo", MatrixGain(np.hstack([K, beta * K, -K, Z])))
    builder.Connect(plant.get_state_output_port(), inputs.get_input_port(1))
    builder.Connect(inputs.get_output_port(), servo.get_input_port())
    gravity = builder.AddNamedSystem("gravity_feedforward", InverseDynamics(
        controller_plant, InverseDynamics.InverseDynamicsMode.kGravityCompensation))
    builder.Connect(plant.get_state_output_port(), gravity.get_input_port_estimated_state())
    torque = builder.AddNamedSystem("joint_torque", Adder(2, 6))
    builder.Connect(servo.get_output_port(), torque.get_input_port(0))
    builder.Connect(gravity.get_output_port(), torque.get_input_port(1))
    builder.Connect(torque.get_output_port(), plant.get_actuation_input_port())
    return {"plant": plant, "instance": instance, "desired_state": inputs.get_input_port(0),
            "controller_plant": controller_plant, "natural_frequencies_hz": freqs, "beta_s": beta}


def filter_coefficients(filter_config, rate_hz, spindle_rpm):
    fc = filter_config
    return model_filter_coefficients(fc.kind, fc.cutoff_hz, fc.order, rate_hz, spindle_rpm)


def add_compensation_chain(builder, *, rate_hz, filter_ba, max_jump_N, period_s, delay_steps, saturation_rad,
                           rate_limit_rad_per_s, calibration, predictor, tool_m, initial_wrench, predictive=None,
                           lost_motion_rad=None, coupling_c23_rad_per_Nm=0.0):
    """The compensation chain of the seed's Fig. 5, from the sensor's raw
    wrench to the joint-reference correction:

      WrenchGuard -> force filter (LinearSystem) -> ZOH(T) -> GravityRemoval
      -> DeflectionPrediction -> Saturation -> DiscreteTimeDelay(T, n)
      -> RateLimitedCorrection(T)

    (the measured joint angles enter through their own ZOH(T)).  With
    ``predictive`` (a PredictiveWrench), it sits between GravityRemoval and
    DeflectionPrediction.  Returns the systems by name; inputs: guard
    "wrench" and zoh_q; output: correction."""
    b, a = filter_ba
    T = period_s
    s = {}
    s["guard"] = builder.AddNamedSystem("wrench_guard", WrenchGuard(rate_hz=rate_hz, max_jump_N=max_jump_N,
                                                                    initial_wrench=initial_wrench))
    s["filter"] = builder.AddNamedSystem("force_filter", filter_system(b, a, rate_hz))
    builder.Connect(s["guard"].GetOutputPort("wrench"), s["filter"].get_input_port())
    s["zoh_w"] = builder.AddNamedSystem("sample_wrench", ZeroOrderHold(T, 6))
    s["zoh_q"] = builder.AddNamedSystem("sample_q", ZeroOrderHold(T, 6))
    builder.Connect(s["filter"].get_output_port(), s["zoh_w"].get_input_port())
    s["gravity_removal"] = builder.AddNamedSystem("gravity_removal", GravityRemoval(calibration=calibration,
                                                                                     kinematics=predictor))
    builder.Connect(s["zoh_w"].get_output_port(), s["gravity_removal"].GetInputPort("wrench"))
    builder.Connect(s["zoh_q"].get_output_port(), s["gravity_removal"].GetInputPort("q"))
    s["prediction"] = builder.AddNamedSystem("deflection_prediction", DeflectionPrediction(
        predictor=predictor, tool_m=tool_m, mount_rpy_deg=calibration.sensor_mount_rpy_deg or (0.0, 0.0, 0.0),
        lost_motion_rad=lost_motion_rad, coupling_c23_rad_per_Nm=coupling_c23_rad_per_Nm))
    process = s["gravity_removal"].get_output_port()
    if predictive is not None:
        s["predictive"] = builder.AddNamedSystem("predictive_wrench", predictive)
        builder.Connect(process, predictive.GetInputPort("process_wrench"))
        builder.Connect(s["zoh_q"].get_output_port(), predictive.GetInputPort("q"))
        process = predictive.GetOutputPort("process_wrench")
    builder.Connect(process, s["prediction"].GetInputPort("process_wrench"))
    builder.Connect(s["zoh_q"].get_output_port(), s["prediction"].GetInputPort("q"))
    sat = saturation_rad * np.ones(6)
    s["saturation"] = builder.AddNamedSystem("saturation", Saturation(-sat, sat))
    builder.Connect(s["prediction"].GetOutputPort("dq"), s["saturation"].get_input_port())
    last = s["saturation"].get_output_port()
    # n extra controller periods, exactly: a discrete block adds one period by
    # its own update (same-instant semantics), so n = 1 is a ZeroOrderHold and
    # n >= 2 a DiscreteTimeDelay of n - 1 samples (tested).
    if delay_steps == 1:
        s["delay"] = builder.AddNamedSystem("transport_delay", ZeroOrderHold(T, 6))
    elif delay_steps >= 2:
        s["delay"] = builder.AddNamedSystem("transport_delay", DiscreteTimeDelay(T, delay_steps - 1, 6))
    if "delay" in s:
        builder.Connect(last, s["delay"].get_input_port())
        last = s["delay"].get_output_port()
    s["correction"] = builder.AddNamedSystem("reference_correction", RateLimitedCorrection(
        period_s=T, rate_limit_rad_per_s=rate_limit_rad_per_s))
    builder.Connect(last, s["correction"].get_input_port())
    return s


def chain_transport_delay_s(rate_hz, filter_ba, period_s, delay_steps):
    """How long a change of the true wrench takes to reach the correction:
    sensor sample + guard sample + the filter's group delay + the ZOH's
    period + the delay block + the correction's own update (upper bound; a
    change between controller ticks waits less for the ZOH)."""
    b, a = filter_ba
    return 2.0 / rate_hz + group_delay_s(b, a, rate_hz) + (2 + delay_steps) * period_s


def build_milling_cell(sc, robot, *, compensation=True, log_period_s=None):
    """Build the closed-loop diagram of scenario ``sc``."""
    tool = robot.payload.tool_point_m
    cutter, fmodel, workpiece = cutting_setup(sc)
    T = sc.controller.period_ms / 1e3
    dt = sc.plant.time_step_ms / 1e3
    path, t_ref, q_ref = planned_path(sc, robot, tool)

    builder = DiagramBuilder()
    k_plant = plant_stiffness(sc, robot)
    try:
        arm = add_compliant_irb6400(builder, time_step_s=dt, joint_stiffness_Nm_per_rad=k_plant,
                                    damping_ratio=sc.plant.damping_ratio, q_modes_rad=q_ref[0])
    except ValueError as e:
        raise InputError(f"{sc.source}: plant.time_step_ms: {e}") from None
    plant = arm["plant"]

    # path: q_ref and its derivative from a piecewise-linear trajectory
    traj = PiecewisePolynomial.FirstOrderHold(t_ref, q_ref.T)
    path_src = builder.AddNamedSystem("path", TrajectorySource(traj, output_derivative_order=1))
    path_demux = builder.AddNamedSystem("path_demux", Demultiplexer([6, 6]))
    builder.Connect(path_src.get_output_port(), path_demux.get_input_port())
    state_demux = builder.AddNamedSystem("state_demux", Demultiplexer([6, 6]))
    builder.Connect(plant.get_state_output_port(), state_demux.get_input_port())
    q_meas = state_demux.get_output_port(0)

    # the process: cutting force from the actual tool position (true
    # kinematics), sampled at the plant step
    fk = DeflectionPredictor(robot.dh, k_plant, tool)
    milling = builder.AddNamedSystem("milling_force", MillingForceSource(
        force_model=fmodel, workpiece=workpiece, path=path, kinematics=fk, tool_point_m=tool, period_s=dt,
        mode=sc.cutting.mode, samples_per_tooth=sc.cutting.samples_per_tooth,
        phase_rad=np.deg2rad(sc.cutting.phase_deg)))
    builder.Connect(q_meas, milling.get_input_port())
    builder.Connect(milling.GetOutputPort("generalized_force"), plant.get_applied_generalized_force_input_port())

    # the wrist sensor
    ss = sc.sensor
    R6_0, _ = fk.flange_rotation_and_tool_point(q_ref[0])
    w0 = payload_wrench(R6_0, exact_payload_calibration(sc, robot))  # the reading at rest, before the cut
    sensor = builder.AddNamedSystem("wrist_sensor", WristForceSensor(
        weld_joint_index=plant.GetJointByName("sensor_weld").index(), rate_hz=ss.rate_hz,
        force_bias_N=ss.force_bias_N, torque_bias_Nm=ss.torque_bias_Nm, noise_N=ss.noise_N, noise_Nm=ss.noise_Nm,
        dropout_probability=ss.dropout_probability, spike_probability=ss.spike_probability, spike_N=ss.spike_N,
        seed=ss.seed, initial_wrench=w0))
    builder.Connect(plant.get_reaction_forces_output_port(), sensor.GetInputPort("reaction_forces"))
    builder.Connect(milling.GetOutputPort("wrench_sensor"), sensor.GetInputPort("process_wrench"))

    # the compensator: its own stiffness model and payload calibration
    kin = DeflectionPredictor(robot.dh, model_stiffness(sc, robot), tool)
    ba = filter_coefficients(sc.controller.filter, ss.rate_hz, cutter.spindle_rpm)
    predictive = None
    if sc.controller.mode == "predictive":
        _, model_forces, _ = cutting_setup(sc, scale=sc.model.force_model_scale)
        predictive = PredictiveWrench(
            force_model=model_forces, workpiece=workpiece, path=path, kinematics=kin, tool_m=tool,
            lead_s=(sc.controller.delay_steps + 1.5) * T, filter_ba=ba, rate_hz=ss.rate_hz, period_s=T)
    chain = add_compensation_chain(
        builder, rate_hz=ss.rate_hz, filter_ba=ba, max_jump_N=ss.max_jump_N, period_s=T,
        delay_steps=sc.controller.delay_steps, saturation_rad=np.deg2rad(sc.controller.saturation_deg),
        rate_limit_rad_per_s=np.deg2rad(sc.controller.rate_limit_deg_per_s), calibration=payload_calibration(sc, robot),
        predictor=kin, tool_m=tool, initial_wrench=w0, predictive=predictive,
        lost_motion_rad=sc.model.lost_motion_rad or None, coupling_c23_rad_per_Nm=sc.model.coupling_c23_rad_per_Nm)
    builder.Connect(sensor.get_output_port(), chain["guard"].GetInputPort("wrench"))
    builder.Connect(q_meas, chain["zoh_q"].get_input_port())
    correction = chain["correction"]

    # commanded joints: q_ref (+ correction), with the path's velocity
    mux = builder.AddNamedSystem("desired_state", Multiplexer([6, 6]))
    if compensation:
        adder = builder.AddNamedSystem("q_command", Adder(2, 6))
        builder.Connect(path_demux.get_output_port(0), adder.get_input_port(0))
        builder.Connect(correction.get_output_port(), adder.get_input_port(1))
        builder.Connect(adder.get_output_port(), mux.get_input_port(0))
    else:
        builder.Connect(path_demux.get_output_port(0), mux.get_input_port(0))
    builder.Connect(path_demux.get_output_port(1), mux.get_input_port(1))
    desired = mux.get_output_port()
    if sc.plant.lost_motion_rad or sc.plant.coupling_c23_rad_per_Nm:
        effects = builder.AddNamedSystem("plant_joint_effects", JointEffects(
            lost_motion_rad=sc.plant.lost_motion_rad or np.zeros(6),
            coupling_c23_rad_per_Nm=sc.plant.coupling_c23_rad_per_Nm))
        builder.Connect(desired, effects.GetInputPort("desired_state"))
        builder.Connect(milling.GetOutputPort("generalized_force"), effects.GetInputPort("joint_torque"))
        desired = effects.get_output_port()
    builder.Connect(desired, arm["desired_state"])

    log_dt = log_period_s or dt
    loggers = log_signals(builder, {
        "state": (plant.get_state_output_port(), log_dt),
        "cutting_wrench": (milling.GetOutputPort("wrench"), log_dt),
        "raw_wrench": (chain["guard"].GetOutputPort("wrench"), 1.0 / ss.rate_hz),
        "filtered_wrench": (chain["filter"].get_output_port(), T),
        # what the prediction reads (its tool_wrench output is derived from
        # these after the run: tool_wrench_log, no Python call per tick)
        "process_wrench": ((chain["predictive"].GetOutputPort("process_wrench") if "predictive" in chain
                            else chain["gravity_removal"].get_output_port()), T),
        "q_sampled": (chain["zoh_q"].get_output_port(), T),
        "dq": (chain["prediction"].GetOutputPort("dq"), T),
        "correction": (correction.get_output_port(), T),
        "rejected": (chain["guard"].GetOutputPort("rejected"), T),
    })
    diagram = builder.Build()
    diagram.set_name(f"milling_cell_{'compensated' if compensation else 'uncompensated'}")

    systems = dict(chain, sensor=sensor, milling=milling, controller_plant=arm["controller_plant"])
    return MillingCell(
        diagram=diagram, plant=plant, scenario=sc, robot=robot, path=path, q_ref_times=t_ref, q_ref=q_ref,
        force_model=fmodel, workpiece=workpiece, tool_m=tool, compensation=compensation, loggers=loggers,
        systems=systems, initial={"q": q_ref[0], "wrench": w0}, plant_time_step_s=dt,
        transport_delay_s=chain_transport_delay_s(ss.rate_hz, ba, T, sc.controller.delay_steps),
        damping_beta_s=arm["beta_s"], natural_frequencies_hz=arm["natural_frequencies_hz"])


def tool_wrench_log(cell, logs):
    """(times, (N, 6)): the wrench the prediction used, at the tool point in
    the base frame (its ``tool_wrench`` output), from the logged sensor-frame
    process wrench and the sampled joint angles."""
    t, w = logs["process_wrench"]
    _, q = logs["q_sampled"]
    pred = cell.systems["prediction"]
    return t, np.array([pred.tool_wrench_of(wk, qk) for wk, qk in zip(w, q)]).reshape(-1, 6)


@dataclass
class SignalLog:
    """One logged signal: its columns in a (shared) VectorLogSink."""

    logger: object
    columns: slice

    def read(self, root_context):
        """(sample times s, samples (N, size)) from a simulation's root context."""
        log = self.logger.FindLog(root_context)
        return log.sample_times().copy(), log.data()[self.columns].T.copy()


def log_signals(builder, signals):
    """Log named vector ports, ``{name: (port, period_s)}`` -> ``{name:
    SignalLog}``.  Signals of the same period share one Multiplexer and one
    VectorLogSink: one logging event per period, not one per signal."""
    groups = {}
    for name, (port, period) in signals.items():
        groups.setdefault(round(period, 12), []).append((name, port))
    out = {}
    for period, items in groups.items():
        sizes = [port.size() for _, port in items]
        mux = builder.AddNamedSystem(f"log_every_{period * 1e3:g}_ms_mux", Multiplexer(sizes))
        for i, (_, port) in enumerate(items):
            builder.Connect(port, mux.get_input_port(i))
        logger = LogVectorOutput(mux.get_output_port(), builder, period)
        logger.set_name(f"log_every_{period * 1e3:g}_ms")
        start = 0
        for (name, _), n in zip(items, sizes):
            out[name] = SignalLog(logger, slice(start, start + n))
            start += n
    return out


def make_simulator(cell):
    """A Simulator with the cell at rest on the path's first point: plant at
    q_ref(0), the sensor chain settled on the payload's static reading."""
    sim = Simulator(cell.diagram)
    root = sim.get_mutable_context()
    plant_ctx = cell.plant.GetMyMutableContextFromRoot(root)
    cell.plant.SetPositions(plant_ctx, cell.initial["q"])
    filt = cell.systems["filter"]
    filt.GetMyMutableContextFromRoot(root).SetDiscreteState(steady_state(filt, cell.initial["wrench"]))
    cell.systems["zoh_w"].GetMyMutableContextFromRoot(root).SetDiscreteState(cell.initial["wrench"])
    cell.systems["zoh_q"].GetMyMutableContextFromRoot(root).SetDiscreteState(cell.initial["q"])
    sim.Initialize()
    return sim
