"""The real-time compensator as its own Drake diagram (the paper's Fig. 5),
built apart from the station and connected to its ports, as a controller is
to hardware:

    wrench (6, the wrist sensor's raw samples, sensor frame)
      -> WrenchGuard -> force filter (LinearSystem) -> ZOH(T) -> gravity removal
      -> [PredictiveWrench] -> deflection prediction -> saturation
      -> delay (n periods) -> rate-limited correction (T) -> correction (6, rad)
    position_measured (6, the controller's reported joint angles) -> ZOH(T)

Everything after the filter runs once per controller period and only hands
values on, so it is one block, systems/compensator_tick.CompensatorTick
(one call into Python per tick, the separate blocks' timing exactly), which
also carries the guard and the filter where the sensor is read once per
period; a
predictive or preview predictor, or a model with lost motion, stays a block
of its own between the tick's samples and its saturation.

It sees what a controller sees: the joint angles the robot controller
reports (motor encoders, through its gravity model) and the wrist sensor;
nothing of the plant's truth.

Sample-and-hold timing (Drake's same-instant semantics: a discrete block
updated at the same tick as its source sees the source's previous value):
a change of the true wrench reaches the correction after one sensor sample
(sensor), one more (guard), the filter's own lag, one controller period
(ZOH), ``delay_steps`` periods and one more period (the correction's own
update); ``chain_delay_s`` adds these up.  The station's interpolator and
servo add their own lag before the motor moves.
"""

from dataclasses import dataclass

import numpy as np
from pydrake.systems.controllers import InverseDynamics
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource, Multiplexer

from robstiff_drake.model.compensator import DeflectionModel
from robstiff_drake.model.filters import filter_coefficients as model_filter_coefficients
from robstiff_drake.model.realtime import DeflectionPredictor
from robstiff_drake.systems.compensator_tick import CompensatorTick
from robstiff_drake.systems.deflection_prediction import DeflectionPrediction
from robstiff_drake.systems.force_filter import filter_system, group_delay_s, steady_state
from robstiff_drake.systems.wrist_sensor import WrenchGuard

# The compensator's signals a cell may log, exported by name.
LOG_PORTS = ("guarded_wrench", "rejected", "filtered_wrench", "process_wrench", "q_sampled", "dq")


def filter_coefficients(filter_config, rate_hz, spindle_rpm):
    """(b, a) of the scenario's force filter at the sensor rate."""
    fc = filter_config
    return model_filter_coefficients(fc.kind, fc.cutoff_hz, fc.order, rate_hz, spindle_rpm)  # (model/filters.py)


def chain_delay_s(rate_hz, filter_ba, period_s, delay_steps):
    """How long a change of the true wrench takes to reach the correction:
    sensor sample + guard sample + the filter's group delay + the ZOH's
    period + the delay block + the correction's own update (upper bound; a
    change between controller ticks waits less for the ZOH)."""
    b, a = filter_ba
    return 2.0 / rate_hz + group_delay_s(b, a, rate_hz) + (2 + delay_steps) * period_s


@dataclass
class Compensator:
    diagram: object
    systems: dict
    filter_ba: tuple
    chain_delay_s: float
    # {LOG_PORTS or "correction" name: its columns in the output "tick_state"} for the signals that are parts of
    # the tick's state (a logger reads them there, one port for all: diagrams/milling_cell.log_signals)
    tick_parts: dict = None

    def set_initial_state(self, root_context, wrench, q):
        """Settle the chain on a reading at rest: guard, filter and samples."""
        s = self.systems
        guard = s["guard"]  # (a WrenchGuard, or the tick that carries it)
        guard.hold(guard.GetMyMutableContextFromRoot(root_context), wrench)
        filt = s["filter"]  # (a LinearSystem, or the tick that carries it)
        if filt is s["tick"]:
            filt.set_filter_state(filt.GetMyMutableContextFromRoot(root_context),
                                  steady_state(filt.filter_system, wrench))
        else:
            filt.GetMyMutableContextFromRoot(root_context).SetDiscreteState(steady_state(filt, wrench))
        s["tick"].set_sample(s["tick"].GetMyMutableContextFromRoot(root_context), wrench, q)


def make_compensator(*, rate_hz, filter_ba, max_jump_N, period_s, delay_steps, saturation_rad, rate_limit_rad_per_s,
                     calibration, model_dh, model_stiffness_Nm_per_rad, tool_m, predictive=None, preview=None,
                     lost_motion_rad=None, coupling_c23_rad_per_Nm=0.0, controller_plant=None, name="compensator",
                     lost_motion_take_up_Nm=None, lost_motion_law="smooth", lost_motion_friction_Nm=None):
    """The compensator diagram (see module docstring).  ``calibration``: the
    payload calibration it believes; ``model_*``: its kinematics and joint
    stiffness; ``predictive``: a function (kinematics, lead) -> PredictiveWrench
    for predictive compensation, or None; ``preview``: a function
    (kinematics, deflection model) -> PreviewCorrection for preview
    compensation (its ``dq`` replaces the prediction's), or None;
    ``controller_plant``: the
    controller's model, for the gravity torque the gears carry (needed only
    when the model has lost motion); ``lost_motion_law``/``_friction_Nm``:
    model/compensator.DeflectionModel's ``law``/``friction_Nm`` (preview
    mode's table of future deflections is memoryless: it keeps the smooth
    law).  Inputs ``wrench``,
    ``position_measured``; output ``correction`` and the LOG_PORTS, and
    ``tick_state``: the tick's whole state, of which ``Compensator.tick_parts``
    names the parts that are the signals of those names (for a logger)."""
    T = period_s
    builder = DiagramBuilder()
    kin = DeflectionPredictor(model_dh, model_stiffness_Nm_per_rad, tool_m)
    s = {}
    # a guard and filter sampled at the tick's own instants are carried by the tick (one call into Python for
    # the three, and the filter's output is a part of the tick's state)
    carried = 1.0 / rate_hz == T
    if not carried:
        s["guard"] = builder.AddNamedSystem("wrench_guard", WrenchGuard(rate_hz=rate_hz, max_jump_N=max_jump_N))
        s["filter"] = builder.AddNamedSystem("force_filter", filter_system(*filter_ba, rate_hz))
    lost = lost_motion_rad if lost_motion_rad and any(lost_motion_rad) else None
    law = "smooth" if preview is not None else lost_motion_law
    model = DeflectionModel(kin, tool_m, calibration.sensor_mount_rpy_deg or (0.0, 0.0, 0.0), lost,
                            coupling_c23_rad_per_Nm, lost_motion_take_up_Nm, law, lost_motion_friction_Nm)
    # one block per tick: sample, gravity removal, [prediction], saturation, delay, correction
    # (systems/compensator_tick.py); a predictor with its own inputs or state stays its own block
    separate = predictive is not None or preview is not None or lost is not None
    tick = s["tick"] = builder.AddNamedSystem("compensator_tick", CompensatorTick(
        period_s=T, calibration=calibration, kinematics=kin, deflection=None if separate else model,
        saturation_rad=saturation_rad, delay_steps=delay_steps, rate_limit_rad_per_s=rate_limit_rad_per_s,
        guard=(rate_hz, max_jump_N) if carried else None,
        force_filter=filter_system(*filter_ba, rate_hz) if carried else None))
    out = tick.add_outputs(builder)  # (its state's parts, split by a C++ Demultiplexer)
    if carried:
        s["guard"] = s["filter"] = tick
        guard_in, guarded, rejected = tick.GetInputPort("raw_wrench"), out["guarded_wrench"], out["rejected"]
        filtered = out["filtered_wrench"]
    else:
        guard_in, guarded, rejected = (s["guard"].GetInputPort("wrench"), s["guard"].GetOutputPort("wrench"),
                                       s["guard"].GetOutputPort("rejected"))
        builder.Connect(guarded, s["filter"].get_input_port())
        filtered = s["filter"].get_output_port()
        builder.Connect(filtered, tick.GetInputPort("wrench"))
    q_sampled = out["q_sampled"]
    process = out["process_wrench"]
    if not separate:
        s["prediction"] = tick
        dq_port = out["dq"]
    else:
        s["prediction"] = builder.AddNamedSystem("deflection_prediction", DeflectionPrediction(
            predictor=kin, tool_m=tool_m, mount_rpy_deg=calibration.sensor_mount_rpy_deg or (0.0, 0.0, 0.0),
            lost_motion_rad=lost, coupling_c23_rad_per_Nm=coupling_c23_rad_per_Nm,
            take_up_Nm=lost_motion_take_up_Nm, law=law, friction_Nm=lost_motion_friction_Nm, period_s=T,
            controller_plant=controller_plant))
        if lost is not None:  # the gravity torque the gears carry, from the controller's model
            zeros = builder.AddNamedSystem("zero_velocity", ConstantVectorSource(np.zeros(6)))
            q_state = builder.AddNamedSystem("sampled_q_as_state", Multiplexer([6, 6]))
            builder.Connect(q_sampled, q_state.get_input_port(0))
            builder.Connect(zeros.get_output_port(), q_state.get_input_port(1))
            s["static_torque"] = builder.AddNamedSystem("static_torque", InverseDynamics(
                controller_plant, InverseDynamics.InverseDynamicsMode.kGravityCompensation))
            builder.Connect(q_state.get_output_port(), s["static_torque"].get_input_port_estimated_state())
            builder.Connect(s["static_torque"].get_output_port(), s["prediction"].GetInputPort("static_torque"))
        if predictive is not None:
            s["predictive"] = builder.AddNamedSystem("predictive_wrench", predictive(kin))
            builder.Connect(process, s["predictive"].GetInputPort("process_wrench"))
            builder.Connect(q_sampled, s["predictive"].GetInputPort("q"))
            process = s["predictive"].GetOutputPort("process_wrench")
        builder.Connect(process, s["prediction"].GetInputPort("process_wrench"))
        builder.Connect(q_sampled, s["prediction"].GetInputPort("q"))
        dq_port = s["prediction"].GetOutputPort("dq")
        if preview is not None:
            s["preview"] = builder.AddNamedSystem("preview_correction", preview(kin, s["prediction"].model))
            builder.Connect(process, s["preview"].GetInputPort("process_wrench"))
            builder.Connect(q_sampled, s["preview"].GetInputPort("q"))
            dq_port = s["preview"].GetOutputPort("dq")
        builder.Connect(dq_port, tick.GetInputPort("dq"))

    builder.ExportInput(guard_in, "wrench")
    builder.ExportInput(tick.GetInputPort("q"), "position_measured")
    builder.ExportOutput(out["correction"], "correction")
    builder.ExportOutput(guarded, "guarded_wrench")
    builder.ExportOutput(rejected, "rejected")
    builder.ExportOutput(filtered, "filtered_wrench")
    builder.ExportOutput(process, "process_wrench")
    builder.ExportOutput(q_sampled, "q_sampled")
    builder.ExportOutput(dq_port, "dq")
    builder.ExportOutput(tick.GetOutputPort("state"), "tick_state")
    parts = ["correction", "q_sampled"] + ["guarded_wrench", "rejected", "filtered_wrench"] * carried \
        + ["process_wrench"] * (predictive is None) + ["dq"] * (not separate)
    diagram = builder.Build()
    diagram.set_name(name)
    s["kinematics"] = kin
    return Compensator(diagram, s, filter_ba, chain_delay_s(rate_hz, filter_ba, period_s, delay_steps),
                       {part: tick.part_columns(part) for part in parts})
