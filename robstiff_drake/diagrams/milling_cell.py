"""The robotic milling cell: the station (diagrams/station.py: robot and
its controller's drives, spindle, workpiece, wrist sensor), the path the
robot controller follows, and the real-time compensator
(diagrams/compensator.py), each its own diagram, connected by their ports:

    path (TrajectorySource: q_ref, v_ref) --> [+ correction] --> station.position_command
                                         \\--> station.velocity_command
    station.wrench_measured ---> compensator.wrench
    station.position_measured -> compensator.position_measured
    compensator.correction ----> [+]

Loggers record what the studies read.  ``make_simulator`` starts the cell at
rest on the path's first point.
"""

from dataclasses import dataclass
from functools import partial

import numpy as np
from pydrake.common import RandomGenerator
from pydrake.systems.analysis import ApplySimulatorConfig, Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import Adder, Demultiplexer, LogVectorOutput, Multiplexer, TrajectorySource
from pydrake.trajectories import PiecewisePolynomial

from robstiff_drake.diagrams.compensator import filter_coefficients, make_compensator
from robstiff_drake.diagrams.path_references import (  # noqa: F401 (re-exported: callers take them from here too)
    _REFERENCES, planned_path, references_with_kinematic_error)
from robstiff_drake.diagrams import user_model as user_models
from robstiff_drake.diagrams.scenario_models import (
    COEFFICIENT_GROUPS, cutting_setup, model_cutting_setup, model_damping_ratios, model_stiffness, payload_calibration,
    plant_cutting_setup
)
from robstiff_drake.diagrams.scenario import planned_path as scenario_path
from robstiff_drake.diagrams.station import make_milling_station, path_poses
from robstiff_drake.diagrams.user_measurements import (
    calibrated_tool, probed_workpiece, user_measured_damping, user_robot
)
from robstiff_drake.errors import InputError
from robstiff_drake.model.path import PlannedPath
from robstiff_drake.systems.steady_residual import SteadyResidual
from robstiff_drake.model.arm_dynamics import ArmInertia
from robstiff_drake.model.realtime import DeflectionPredictor
from robstiff_drake.model.preview import preview_table
from robstiff_drake.model.program_correction import clock_on
from robstiff_drake.systems.predictive_wrench import PredictiveWrench
from robstiff_drake.systems.preview_correction import PreviewCorrection, PreviewModel

# How far past the path's end the preview is computed (s): the run's own
# run-out (experiment.RUN_OUT_S) and the correction's lead, with margin.
PREVIEW_MARGIN_S = 0.5


@dataclass
class MillingCell:
    """A built diagram and what is needed to run and read it."""

    diagram: object
    station: object
    compensator: object
    scenario: object
    robot: object
    path: PlannedPath
    q_ref_times: np.ndarray
    q_ref: np.ndarray
    force_model: object
    workpiece: object
    tool_m: np.ndarray
    compensation: bool
    loggers: dict
    transport_delay_s: float

    @property
    def plant(self):
        return self.station.plant

    @property
    def natural_frequencies_hz(self):
        return self.station.natural_frequencies_hz

    @property
    def closed_loop_modes(self):
        return self.station.closed_loop_modes

    @property
    def damping_ratios(self):
        return self.station.damping_ratios

    @property
    def plant_time_step_s(self):
        return self.station.plant_step_s


_PREVIEWS = {}  # preview tables (model/preview.py) for a path and a compensator's model, likewise



def build_station(sc, robot, *, q_modes_rad, path=None, whose=None):
    """The scenario's station, its cutting force the plant's own law
    (InputError, one line, if its plant step is unstable for its joints;
    ``whose``: which model's modes the line names, when not the plant's)."""
    _, fmodel, workpiece = plant_cutting_setup(sc)
    path = path if path is not None else scenario_path(sc)
    try:
        return make_milling_station(sc, robot, path=path, force_model=fmodel, workpiece=workpiece,
                                    q_modes_rad=q_modes_rad)
    except ValueError as e:
        error = InputError(f"{sc.source}: plant_config.time_step: " + (f"{whose}: " if whose else "") + str(e))
        error.why = getattr(e, "why", None)  # (the refusal's detail, printed after its line: commands/main.py)
        raise error from None


def check_plant_step(sc, robot, whose=None):
    """Refuse, before anything runs, a scenario whose plant step is unstable
    for its joint modes at the path's first pose (InputError, one line;
    ``whose``: build_station's)."""
    _, _, q_ref = planned_path(sc, robot, robot.tool_point(where="the closed loop"))
    build_station(sc, robot, q_modes_rad=path_poses(q_ref), whose=whose)


def preview_factory(sc, robot, *, path, workpiece, t_ref, q_ref, tool_m, filter_ba, modal_damping=None,
                    offline=False, clock=None):
    """A function (kinematics, deflection model) -> PreviewCorrection: the
    scenario's preview compensator, from the compensator's own models (its
    stiffness, its servo model, its force model per coefficient group;
    model/preview.py) and, with an identified model, what a user measures
    of the rest (diagrams/user_measurements.py: the robot file's inertias
    as a user's file has them, the tool point from a TCP calibration, the
    workpiece's top from a probe, the damping from ``modal_damping(sc)``,
    a modal test on the station).  ``offline``: the cell runs a program
    corrected offline for this plan (``path``, ``t_ref``, ``q_ref``: the
    plan of the program as written), so the preview sends only what its
    scale estimate adds (systems/preview_correction.py); ``clock``: the
    plan's times -> the cell's (model/program_correction.clock_on), or None
    (the same clock)."""
    ss, ctl = sc.sensor, sc.controller
    T = ctl.period_ms / 1e3
    servo = user_models.servo_model(sc)
    groups = [model_cutting_setup(sc, groups=g)[1] for g in COEFFICIENT_GROUPS]
    um = sc._user_model if sc.model.source == "identified" else None
    ratios = model_damping_ratios(sc)
    if um is not None:  # what a user measures (diagrams/user_measurements.py)
        robot = user_robot(sc, robot)
        tool_m = calibrated_tool(sc, tool_m)
        workpiece = probed_workpiece(sc, workpiece)
        if sc.model.identification.damping == "modal_test" and not sc.model.damping_ratios and modal_damping:
            ratios = modal_damping(sc)
    inertia = ArmInertia(robot)
    motors = inertia.motor_inertia(q_ref[0])
    sigma = max(sc.model.identification.coefficient_error, 0.05) if um is not None else 0.05

    def make(kin, deflection):
        C = kin.joint_compliance
        if um is not None:  # the preview's own kinematics: the calibrated tool point
            kin = DeflectionPredictor(robot.dh, 1.0 / C, tool_m)
        key = (path.signature(), T, tuple(C.tolist()), tuple(ratios), servo, tuple(motors), tuple(np.round(tool_m, 12)),
               robot.source,
               hash(np.asarray(q_ref).tobytes()), workpiece.boxes,
               tuple((tuple(m.Kc.tolist()), tuple(m.Ke.tolist()), m.feed_m_per_s) for m in groups))
        table = _PREVIEWS.get(key)
        if table is None:
            pm = PreviewModel(path=path, t_ref=t_ref, q_ref=q_ref, group_models=groups, workpiece=workpiece,
                              kinematics=kin, inertia=inertia, tool_m=tool_m)
            table = preview_table(pm, t_end_s=path.duration_s + PREVIEW_MARGIN_S, period_s=T, compliance=C,
                                  damping_ratios=ratios, servo=servo, motor_inertia_kgm2=motors, tool_m=tool_m)
            if len(_PREVIEWS) >= 8:
                del _PREVIEWS[next(iter(_PREVIEWS))]
            _PREVIEWS[key] = table
        if clock is not None:
            table = (clock(table[0]),) + tuple(table[1:])
        # a correction computed at a tick reaches the robot controller's
        # sampling of its targets after the delay line and the correction's
        # own update (Drake's same-instant semantics: each discrete block
        # adds a period); the measured wrench lags the model's at the same
        # path time by the arm's dead time behind its reference and two
        # sensor samples (sensor, guard)
        return PreviewCorrection(table=table, deflection=deflection, filter_ba=filter_ba, rate_hz=ss.rate_hz,
                                 period_s=T, lead_s=(ctl.delay_steps + 1) * T,
                                 lag_s=servo.dead_time_s + 2.0 / ss.rate_hz, scale_sigma=sigma, offline=offline)

    return make


def build_compensator(sc, robot, station, *, path, workpiece, t_ref=None, q_ref=None, offline_plan=None):
    """The scenario's compensator: its own stiffness model, payload
    calibration and (in predictive and preview modes) cutting-force model;
    preview mode needs the path's joint references (``t_ref``, ``q_ref``).
    ``offline_plan``: (path, t_ref, q_ref) of the program as written when
    the cell runs a program corrected offline for it (the preview then
    sends only what its scale estimate adds)."""
    ss, ctl = sc.sensor, sc.controller
    T = ctl.period_ms / 1e3
    cutter, _, _ = cutting_setup(sc)
    ba = filter_coefficients(ctl.filter, ss.rate_hz, cutter.spindle_rpm)
    predictive = preview = None
    if ctl.mode == "preview":
        plan, clock = (path, t_ref, q_ref), None
        if offline_plan is not None:  # the table on the plan the program was corrected for, put on the cell's clock
            plan = offline_plan
            clock = partial(clock_on, offline_plan[0], path)
        preview = preview_factory(sc, robot, path=plan[0], workpiece=workpiece, t_ref=plan[1], q_ref=plan[2],
                                  tool_m=station.tool_m, filter_ba=ba,
                                  modal_damping=lambda s: user_measured_damping(s, robot, station, q_ref[0]),
                                  offline=offline_plan is not None, clock=clock)
    if ctl.mode == "predictive":
        _, model_forces, _ = model_cutting_setup(sc)
        # a correction computed now acts after the delay line, half a hold,
        # and the station's interpolator and servo
        lead = (ctl.delay_steps + 1.5) * T + station.command_lag_s

        def predictive(kin):
            return PredictiveWrench(force_model=model_forces, workpiece=workpiece, path=path, kinematics=kin,
                                    tool_m=station.tool_m, lead_s=lead, filter_ba=ba, rate_hz=ss.rate_hz, period_s=T)

    return make_compensator(
        rate_hz=ss.rate_hz, filter_ba=ba, max_jump_N=ss.max_jump_N, period_s=T, delay_steps=ctl.delay_steps,
        saturation_rad=np.deg2rad(ctl.saturation_deg), rate_limit_rad_per_s=np.deg2rad(ctl.rate_limit_deg_per_s),
        calibration=payload_calibration(sc, robot), model_dh=robot.dh, model_stiffness_Nm_per_rad=model_stiffness(
            sc, robot), tool_m=station.tool_m, predictive=predictive, preview=preview,
        lost_motion_rad=sc.model.lost_motion_rad or None, coupling_c23_rad_per_Nm=sc.model.coupling_c23_rad_per_Nm,
        controller_plant=station.controller_plant, lost_motion_take_up_Nm=sc.model.lost_motion_take_up_Nm or None,
        lost_motion_law=sc.model.lost_motion_law, lost_motion_friction_Nm=sc.model.lost_motion_friction_Nm or None)


def build_milling_cell(sc, robot, *, compensation=True, log_period_s=None, model_wrench=None, q_reference=None,
                       offline_plan=None):
    """Build the closed-loop diagram of scenario ``sc``: the station, the
    path and (always built, connected only with ``compensation``) the
    compensator.  ``model_wrench``: (times s, (N, 6) sensor-frame wrench)
    subtracted from the measured wrench before the compensator (the part a
    corrected program already compensates: diagrams/offline_compensation.py),
    or (times, wrench, (N,) bool steady): subtracted only where steady, a
    residual held elsewhere, going with the model's force
    (systems/steady_residual.py);
    ``q_reference``: (times s, (N, 6) rad) joint references streamed instead
    of the path's own (a corrected joint reference); ``offline_plan``:
    (path, t_ref, q_ref) of the program as written, when the scenario's
    program is that program corrected offline (preview mode then sends only
    what its scale estimate adds: build_compensator)."""
    tool = robot.tool_point(where="the closed loop")
    _, fmodel, workpiece = cutting_setup(sc)
    path, t_ref, q_ref = planned_path(sc, robot, tool)
    station = build_station(sc, robot, q_modes_rad=path_poses(q_ref), path=path)
    user_models.resolve(sc, robot, q_ref[0])
    comp = build_compensator(sc, robot, station, path=path, workpiece=workpiece, t_ref=t_ref, q_ref=q_ref,
                             offline_plan=offline_plan)

    builder = DiagramBuilder()
    st = builder.AddSystem(station.diagram)
    cp = builder.AddSystem(comp.diagram)
    if q_reference is not None:
        t_ref, q_ref = (np.asarray(v, dtype=float) for v in q_reference)
    traj = PiecewisePolynomial.FirstOrderHold(t_ref, q_ref.T)
    path_src = builder.AddNamedSystem("path", TrajectorySource(traj, output_derivative_order=1))
    path_demux = builder.AddNamedSystem("path_demux", Demultiplexer([6, 6]))
    builder.Connect(path_src.get_output_port(), path_demux.get_input_port())
    if model_wrench is None:
        builder.Connect(st.GetOutputPort("wrench_measured"), cp.GetInputPort("wrench"))
    elif len(model_wrench) == 3:  # heard only where the model's force is steady (systems/steady_residual.py)
        residual = builder.AddNamedSystem("wrench_residual",
                                          SteadyResidual(*model_wrench, period_s=1.0 / sc.sensor.rate_hz))
        builder.Connect(st.GetOutputPort("wrench_measured"), residual.get_input_port())
        builder.Connect(residual.get_output_port(), cp.GetInputPort("wrench"))
    else:
        t_w, w = model_wrench
        known = builder.AddNamedSystem("model_wrench", TrajectorySource(
            PiecewisePolynomial.FirstOrderHold(np.asarray(t_w, dtype=float), -np.asarray(w, dtype=float).T)))
        residual = builder.AddNamedSystem("wrench_residual", Adder(2, 6))
        builder.Connect(st.GetOutputPort("wrench_measured"), residual.get_input_port(0))
        builder.Connect(known.get_output_port(), residual.get_input_port(1))
        builder.Connect(residual.get_output_port(), cp.GetInputPort("wrench"))
    builder.Connect(st.GetOutputPort("position_measured"), cp.GetInputPort("position_measured"))
    if compensation:
        command = builder.AddNamedSystem("q_command", Adder(2, 6))
        builder.Connect(path_demux.get_output_port(0), command.get_input_port(0))
        builder.Connect(cp.GetOutputPort("correction"), command.get_input_port(1))
        builder.Connect(command.get_output_port(), st.GetInputPort("position_command"))
    else:
        builder.Connect(path_demux.get_output_port(0), st.GetInputPort("position_command"))
    builder.Connect(path_demux.get_output_port(1), st.GetInputPort("velocity_command"))

    h = station.plant_step_s
    T = sc.controller.period_ms / 1e3
    log_dt = log_period_s or h
    def compensator_signal(name, period_s):  # (a part of the tick's state read from that state's one port)
        if name in comp.tick_parts:
            return cp.GetOutputPort("tick_state"), period_s, comp.tick_parts[name]
        return cp.GetOutputPort(name), period_s

    loggers = log_signals(builder, {
        "state": (st.GetOutputPort("plant_state"), log_dt),
        "cutting_wrench": (st.GetOutputPort("cutting_wrench"), log_dt),
        "motor": (st.GetOutputPort("motor_position"), log_dt),
        "raw_wrench": compensator_signal("guarded_wrench", 1.0 / sc.sensor.rate_hz),
        "filtered_wrench": compensator_signal("filtered_wrench", T),
        # what the prediction reads (its tool_wrench is derived from these
        # after the run: tool_wrench_log, no Python call per tick)
        "process_wrench": compensator_signal("process_wrench", T),
        "q_sampled": compensator_signal("q_sampled", T),
        "dq": compensator_signal("dq", T),
        "correction": compensator_signal("correction", T),
        "rejected": compensator_signal("rejected", T),
    }, base_s=log_dt)
    diagram = builder.Build()
    diagram.set_name(f"milling_cell_{'compensated' if compensation else 'uncompensated'}")
    delay = comp.chain_delay_s + station.command_lag_s
    return MillingCell(
        diagram=diagram, station=station, compensator=comp, scenario=sc, robot=robot, path=path, q_ref_times=t_ref,
        q_ref=q_ref, force_model=fmodel, workpiece=workpiece, tool_m=tool, compensation=compensation,
        loggers=loggers, transport_delay_s=delay)


def tool_wrench_log(cell, logs):
    """(times, (N, 6)): the wrench the prediction used, at the tool point in
    the base frame (its ``tool_wrench`` output), from the logged sensor-frame
    process wrench and the sampled joint angles."""
    t, w = logs["process_wrench"]
    _, q = logs["q_sampled"]
    pred = cell.compensator.systems["prediction"]
    return t, np.array([pred.tool_wrench_of(wk, qk) for wk, qk in zip(w, q)]).reshape(-1, 6)


@dataclass
class SignalLog:
    """One logged signal: its columns in a (shared) VectorLogSink; a signal
    of period ``period_s`` logged every ``period_s / stride``: every
    ``stride``-th sample from the first on its own instants."""

    logger: object
    columns: slice
    stride: int = 1
    period_s: float = 0.0

    def read(self, root_context):
        """(sample times s, samples (N, size)) from a simulation's root context."""
        log = self.logger.FindLog(root_context)
        t, x = log.sample_times(), log.data()
        first = 0
        if self.stride > 1:  # (the first sample on this signal's own period's instants)
            k = np.round(t / self.period_s)
            on = np.flatnonzero(np.abs(t - k * self.period_s) <= 1e-9 * np.maximum(1.0, np.abs(t)))
            first = int(on[0]) if on.size else t.size
        return t[first::self.stride].copy(), x[self.columns, first::self.stride].T.copy()


def _faster_period(period, fastest):
    """n, 1 or 2, where period = n fastest exactly (so k period = (n k)
    fastest in floating point), or None: a logger copies a slower signal at
    each of its samples, so at most twice as often as it changes."""
    n = round(period / fastest)
    return n if n in (1, 2) and n * fastest == period else None


def log_signals(builder, signals, base_s=None):
    """Log named vector ports, ``{name: (port, period_s[, columns])}`` ->
    ``{name: SignalLog}`` (``columns``: a slice of the port's vector, the
    whole by default).  Signals of one period share one Multiplexer and one
    VectorLogSink, and so do those of ``base_s`` and twice it, at
    ``base_s`` (each read at its own instants:
    SignalLog.stride): one logging event per period, not one per signal,
    and a port read once however many signals it holds."""
    fastest = round(base_s, 12) if base_s else None
    groups = {}
    for name, (port, period, *columns) in signals.items():
        period = round(period, 12)
        stride = _faster_period(period, fastest) if fastest else None
        group = groups.setdefault(fastest if stride else period, {})
        group[name] = (port, columns[0] if columns else slice(0, port.size()), stride or 1, period)
    out = {}
    for period, items in groups.items():
        ports = {}  # (one mux input per port: its offset in the logged vector)
        for port, *_ in items.values():
            ports.setdefault((port.get_system().get_name(), int(port.get_index())), port)
        mux = builder.AddNamedSystem(f"log_every_{period * 1e3:g}_ms_mux",
                                     Multiplexer([port.size() for port in ports.values()]))
        start = {}
        offset = 0
        for i, (key, port) in enumerate(ports.items()):
            builder.Connect(port, mux.get_input_port(i))
            start[key] = offset
            offset += port.size()
        logger = LogVectorOutput(mux.get_output_port(), builder, period)
        logger.set_name(f"log_every_{period * 1e3:g}_ms")
        for name, (port, cols, stride, own) in items.items():
            at = start[(port.get_system().get_name(), int(port.get_index()))]
            out[name] = SignalLog(logger, slice(at + cols.start, at + cols.stop), stride, own)
    return out


def make_simulator(cell):
    """A Simulator with the cell at rest on the path's first point: the
    sensor's random sources seeded from the scenario (sensor.seed), the
    station at rest with the controller commanding q_ref(0), the
    compensator settled on the reading at rest."""
    sim = Simulator(cell.diagram)
    ApplySimulatorConfig(cell.scenario.simulator_config, sim)
    root = sim.get_mutable_context()
    cell.diagram.SetRandomContext(root, RandomGenerator(int(cell.scenario.sensor.seed)))
    _, _, wrench = cell.station.set_initial_state(root, cell.q_ref[0])
    cell.compensator.set_initial_state(root, wrench, cell.q_ref[0])
    sim.Initialize()
    return sim

