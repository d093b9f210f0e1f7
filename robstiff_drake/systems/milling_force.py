"""The milling force source: the cutting wrench on the tool from the actual
tool position against the workpiece (the process loop), applied to the
spindle body as a spatial force, so the flange-spindle weld carries it and
the wrist sensor feels it as it would on a real cell."""

import math

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.multibody.math import SpatialForce
from pydrake.multibody.plant import ExternallyAppliedSpatialForce
from pydrake.systems.framework import LeafSystem

from robstiff_drake.model.wrench_frames import to_sensor_frame

# The most instants a tooth-resolved update tabulates (its own, the sensor's samples, its end).
MAX_INSTANTS = 8


def _arange(start, stop, step):
    """list(np.arange(start, stop, step)) for floats, value for value
    (numpy's fill: start, start + step, then start + i * (the second minus
    the first)), without numpy's cost for a few values."""
    n = max(0, math.ceil((stop - start) / step))
    if n <= 2:
        return [start, start + step][:n]
    delta = (start + step) - start
    return [start, start + step] + [start + i * delta for i in range(2, n)]


class MillingForceSource(LeafSystem):
    """Samples the robot's link angles every ``period_s`` and computes the
    cutting load at the actual tool point.

    Input  ``q`` (6): link angles, rad (controller convention).
    Output ``spatial_force`` (abstract, a list of one
      ExternallyAppliedSpatialForce): the load held over the period, on the
      spindle body at the tool point (for the plant's applied spatial force
      port).  Tooth-resolved mode: the mean of the tooth-resolved wrench over
      the period, sampled ``samples_per_tooth`` times per tooth pass.
    Output ``wrench`` (6): the wrench on the tool (force N, moment N*m about
      the tool point, base frame): the held load (averaged mode), or the
      instantaneous tooth forces at the held tool position (tooth mode).
    Output ``ripple_sensor`` (6): tooth mode only: the instantaneous wrench
      minus the held one, as the wrist sensor sees it (the part of the tooth
      force the plant's step averages away, which a fast sensor still sees).

    In averaged mode every output is held state (no computation between
    updates).  In tooth mode each update also computes, in the same
    vectorised evaluation as the period's mean, the instantaneous wrench at
    the instants the outputs will be read before the next update: the
    update's own instant (the sensor samples after it, at the same time),
    the sensor's samples (every ``sensor_period_s``) and the update's end
    (the loggers', which publish before the next update), and the sensor's
    ripple at each of them; an output read at another instant computes its
    own.
    """

    def __init__(self, *, force_model, workpiece, path, kinematics, tool_point_m, period_s, spindle_body_index,
                 mode="averaged", samples_per_tooth=20, phase_rad=0.0, sensor_period_s=None):
        super().__init__()
        if mode not in ("averaged", "tooth"):
            raise ValueError(f"mode must be 'averaged' or 'tooth', got {mode!r}")
        self._model = force_model
        self._workpiece = workpiece
        self._path = path
        self._kin = kinematics
        self._tool = tuple(float(v) for v in tool_point_m)
        self._mode = mode
        self._phase = phase_rad
        self._body = spindle_body_index
        # tooth-resolved: the period's mean over samples_per_tooth samples per tooth pass
        n_sub = max(1, int(round(period_s * force_model.cutter.tooth_pass_hz * samples_per_tooth)))
        self._sub_t = np.arange(n_sub) * (period_s / n_sub)
        self._period = float(period_s)
        self._sensor_period = float(sensor_period_s or period_s)
        self._q = self.DeclareVectorInputPort("q", 6)
        # held: flange rotation (9) and tool point (3; tooth mode only, where it is read); the period's wrench
        # (base frame, at the tool point) and the spatial force list
        self._pose = self.DeclareDiscreteState(12)
        self._w = self.DeclareDiscreteState(6)
        self._applied = ExternallyAppliedSpatialForce()  # reused: only its force changes
        self._applied.body_index = self._body
        self._applied.p_BoBq_B = np.array(self._tool)  # the spindle's frame is the flange's
        self._force = self.DeclareAbstractState(AbstractValue.Make([self._spatial_force([0.0] * 6)]))
        self.DeclarePeriodicUnrestrictedUpdateEvent(period_s, 0.0, self._update)
        self.DeclareStateOutputPort("spatial_force", self._force)
        if mode == "averaged":
            self.DeclareStateOutputPort("wrench", self._w)
        else:
            # the instants read before the next update (offsets from the update) and their wrenches (base frame)
            self._offsets = self._read_offsets(0.0)
            # (the instantaneous wrench, base frame, and the ripple, sensor frame, at each instant)
            self._inst = self.DeclareDiscreteState(np.zeros(12 * MAX_INSTANTS))
            self._inst_t = self.DeclareDiscreteState(np.full(MAX_INSTANTS, np.nan))
            now = {self.discrete_state_ticket(self._pose), self.time_ticket(), self.discrete_state_ticket(self._inst),
                   self.discrete_state_ticket(self._inst_t)}
            self.DeclareVectorOutputPort("wrench", 6, lambda c, o: o.SetFromVector(self._tooth_wrench_now(c)),
                                         prerequisites_of_calc=now)
            self.DeclareVectorOutputPort("ripple_sensor", 6, self._calc_ripple,
                                         prerequisites_of_calc=now | {self.discrete_state_ticket(self._w)})

    def _spatial_force(self, w):
        """The wrench w (6: force, moment about the tool point, base frame)
        on the spindle at the tool point (the state copies it when set)."""
        w = np.asarray(w, dtype=float)
        self._applied.F_Bq_W = SpatialForce(w[3:], w[:3])
        return self._applied

    def _read_offsets(self, t):
        """The instants in [t, t + period] that the outputs are read at (the
        update's own instant if it is on the sensor's grid, the sensor's grid
        and the period's end), as times, at most MAX_INSTANTS."""
        T = self._sensor_period
        k = math.floor(t / T + 1e-9)
        first = k * T + T
        ins = _arange(first, t + self._period + 1e-12, T) + [t + self._period]
        if abs(t - k * T) < 1e-9:  # the sensor samples at the update's own instant, after it
            ins.append(t)
        return np.array(sorted({round(v, 12) for v in ins})[:MAX_INSTANTS])

    def _instant(self, context):
        """The index of this instant in the update's table, or None."""
        t = context.get_time()
        for i, ti in enumerate(context.get_discrete_state(self._inst_t).value().tolist()):
            if abs(ti - t) < 1e-9:
                return i
        return None

    def _tooth_wrench_now(self, context):
        i = self._instant(context)
        if i is not None:
            return context.get_discrete_state(self._inst).value()[12 * i:12 * i + 6]
        t = context.get_time()
        p = context.get_discrete_state(self._pose).value()[9:]
        return self._model.tooth_wrench(t, p, self._path.feed_direction(t), self._workpiece, self._phase,
                                        self._path.programmed_speed(t))

    def _ripple(self, R, w_now, w_held):
        """The ripple (sensor frame, list) for the flange rotation R (9
        floats), the instantaneous and the held wrench (base frame, arrays)."""
        return to_sensor_frame(R, self._tool, (w_now - w_held).tolist())

    def _calc_ripple(self, context, output):
        i = self._instant(context)
        if i is not None:
            output.SetFromVector(context.get_discrete_state(self._inst).value()[12 * i + 6:12 * i + 12])
            return
        R = context.get_discrete_state(self._pose).value()[:9].tolist()
        held = context.get_discrete_state(self._w).value()
        output.SetFromVector(self._ripple(R, self._tooth_wrench_now(context), held))

    def step_wrench(self, t, q, instants=()):
        """(wrench over the period starting at t as a list, pose, the
        instantaneous wrenches at ``instants`` (tooth mode; (k, 6))): the
        pose is the flange rotation (row-major 9) and the tool point (3), m."""
        w, pose, inst = self._step(t, q, instants)
        return w.tolist(), pose, inst

    def _step(self, t, q, instants=()):
        """step_wrench with the wrench as an array."""
        pose = self._kin.pose_only(q)
        p = pose[9:]
        u = self._path.feed_direction(t)
        feed = self._path.programmed_speed(t)  # each move's own feed (chip thickness)
        inst = None
        if self._mode == "tooth":
            n = len(self._sub_t)
            rows = self._model.tooth_wrenches(np.concatenate((t + self._sub_t, instants)), p, u, self._workpiece,
                                              self._phase, feed)
            w, inst = rows[:n].sum(axis=0) / n, rows[n:]
        else:
            w = self._model.average_wrench(p, u, self._workpiece, feed)
        return w, pose, inst

    def _update(self, context, state):
        q = self._q.Eval(context)
        t = context.get_time()
        instants = self._read_offsets(t) if self._mode == "tooth" else ()
        w, pose, inst = self._step(t, q, instants)
        discrete = state.get_mutable_discrete_state()
        discrete.set_value(int(self._w), w)
        if inst is not None:
            discrete.set_value(int(self._pose), np.array(pose))  # (read between updates in tooth mode only)
            times = np.full(MAX_INSTANTS, np.nan)
            times[:len(instants)] = instants
            values = np.zeros((MAX_INSTANTS, 12))
            values[:len(inst), :6] = inst
            w_held, R = w, list(pose[:9])
            for i, row in enumerate(inst):
                values[i, 6:] = self._ripple(R, row, w_held)
            discrete.set_value(int(self._inst), values.ravel())
            discrete.set_value(int(self._inst_t), times)
        state.get_mutable_abstract_state(int(self._force)).set_value([self._spatial_force(w)])
