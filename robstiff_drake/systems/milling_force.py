"""The milling force source: the cutting wrench on the tool from the actual
tool position against the workpiece (the process loop) and the tool's
actual progress along its path (the chip's feed per tooth: a tool that lags
its plan cuts where and as fast as it really moves; the chip's direction
is the program's where the tool is, see ``motion``), applied to the spindle body
as a spatial force, so the flange-spindle weld carries it and the wrist
sensor feels it as it would on a real cell."""

import math

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.multibody.math import SpatialForce
from pydrake.multibody.plant import ExternallyAppliedSpatialForce
from robstiff_drake.systems.leaf_system import LeafSystem

from robstiff_drake.model import force_step_kernels, jit, tick_kernels
from robstiff_drake.model.wrench_frames import to_sensor_frame

# The most instants a tooth-resolved update tabulates (its own, the sensor's samples, its end).
MAX_INSTANTS = 8


# The chip follows the tool's progress along its path low-passed at this
# frequency (Hz), below the arm's first mode (about 5 Hz): the path's speed
# ramps (0.5 s) and the tool's lag behind its plan pass, its vibration at
# the arm's modes does not.  The chip's feedback at those modes (process
# damping, regenerative and mode-coupling chatter) is real physics this
# plant leaves out.  It is not left out for a numerical reason alone: the
# regenerative chip (the tool's displacement over a tooth) makes the
# linearised arm on the paper's block chatter in continuous time (+37 1/s
# at 69 Hz, arm modes 4 and 5; model/chip_coupling.py,
# studies/chip_coupling_stability.py, docs/results.md "the chip's
# direction from the tool's own motion"); and even the chip's stable
# low-frequency limit (a velocity coupling) taken explicitly needs a force
# update under 1.8 ms there, not the averaged force's 4 ms.  The plant
# option cutting.chip: regenerative (systems/regenerative_force.py)
# simulates that feedback tooth by tooth instead, the chatter and its
# limit cycle included (studies/regenerative_chatter.py).
FEED_CUTOFF_HZ = 2.0


def chip_window_s(cutter):
    """Over how long the tool's displacement makes the revolution-averaged
    chip (s): one revolution (its chips' mean is the displacement over the
    revolution over the number of teeth)."""
    return 60.0 / cutter.spindle_rpm


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
    cutting load at the actual tool point, the chip from the tool's actual
    progress: where along its path the tool really is (the path's point
    nearest the actual tool point), its progress over the chip's window
    (``chip_window_s``: a revolution; interpolated in the history of
    updates) over that window, low-passed at FEED_CUTOFF_HZ, is the feed
    (m/s) whose feed per tooth is the chip, and the program's direction
    there the feed direction (``motion``).  So a tool that lags its plan
    turns a corner where it reaches it, not at the plan's clock, and a
    speed ramp thins the chip.  The direction is not taken from the tool's
    own motion: that couples the chip to the arm's modes, and on the
    paper's block the regenerative chip that results chatters in the
    linearised physics, not only in the step (studies/chip_coupling_stability.py),
    while every filtered version tried is an artefact of its filter
    (docs/results.md, "the chip's direction from the tool's own motion";
    studies/chip_direction.py).
    ``force_model``: the plant's law (model/plant_cutting.py's
    PlantCuttingLaw, which also takes the cutting travel so far, its flank
    wear's clock) or a linear MillingForceModel.

    Input  ``q`` (6): link angles, rad (controller convention); with
      ``link_state=True`` instead ``link_state`` (12: the plant's state, the
      link angles first), read with no Demultiplexer in front.
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
    Outputs ``instant_table`` (12 MAX_INSTANTS) and ``instant_times``
      (MAX_INSTANTS): tooth mode only: the update's table (the wrench and
      the ripple at each instant it tabulated), held state that the wrist
      sensor reads without a call into Python (``ripple_from_table``).

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
                 mode="averaged", samples_per_tooth=20, phase_rad=0.0, sensor_period_s=None, link_state=False):
        super().__init__()
        if mode not in ("averaged", "tooth"):
            raise ValueError(f"mode must be 'averaged' or 'tooth', got {mode!r}")
        self._model = force_model
        if hasattr(force_model, "warm_up"):
            force_model.warm_up()  # (a compiled kernel loaded while the diagram is built: model/jit.py)
        self._workpiece = workpiece
        self._path = path
        self._kin = kinematics
        self._tool = tuple(float(v) for v in tool_point_m)
        self._tool_a = np.array(self._tool)
        self._mode = mode
        self._phase = phase_rad
        self._body = spindle_body_index
        # tooth-resolved: the period's mean over samples_per_tooth samples per tooth pass
        n_sub = max(1, int(round(period_s * force_model.cutter.tooth_pass_hz * samples_per_tooth)))
        self._sub_t = np.arange(n_sub) * (period_s / n_sub)
        self._period = float(period_s)
        self._feed_gain = 1.0 - math.exp(-2.0 * math.pi * FEED_CUTOFF_HZ * self._period)  # (smoothed_feed)
        self._sensor_period = float(sensor_period_s or period_s)
        # (the link angles, or the plant's state whose first 6 they are: the kernels read q[0:6] alone)
        self._q = self.DeclareVectorInputPort("link_state", 12) if link_state else self.DeclareVectorInputPort("q", 6)
        # held: the period's wrench (base frame, at the tool point) and the spatial force list
        self._w = self.DeclareDiscreteState(6)
        self._wears = hasattr(force_model, "flank_wear_m")
        # held in one group (one call into the bindings reads and writes it in place): the feed direction (2,
        # unit; before the tool first moves, the path's first), the feed (m/s), the cutting travel so far (m),
        # and the tool's recent history over the chip's window (``motion``: (t, s, 0) per update, oldest first)
        u0 = path.feed_direction(0.0)
        self._window = chip_window_s(force_model.cutter)
        self._n_hist = max(2, math.ceil(self._window / self._period + 1e-9) + 2)
        self._process = self.DeclareDiscreteState(np.concatenate(([float(u0[0]), float(u0[1]), 0.0, 0.0],
                                                                  np.full(3 * self._n_hist, np.nan))))
        self._lines = force_step_kernels.line_constants(path)  # (compiled motion: a path of lines only)
        self._fused = self._fused_constants(force_model, kinematics) if mode == "averaged" else None
        self._packed = None if self._fused is None else force_step_kernels.pack_force_constants(*self._fused)
        self._warm_up()
        self._applied = ExternallyAppliedSpatialForce()  # reused: only its force changes
        self._applied.body_index = self._body
        self._applied.p_BoBq_B = np.array(self._tool)  # the spindle's frame is the flange's
        self._applied_list = [self._applied]  # (the abstract state's value, as set)
        self._spatial = np.zeros(6)  # (the compiled update's wrench as a SpatialForce orders it: moment, force)
        self._force = self.DeclareAbstractState(AbstractValue.Make([self._spatial_force([0.0] * 6)]))
        self.DeclarePeriodicUnrestrictedUpdateEvent(period_s, 0.0, self._update)
        # the averaged update straight to the compiled kernel, its input, outputs and constants packed in two arrays
        lean = self._fused is not None and type(self)._step is MillingForceSource._step
        self._fast = (force_step_kernels.averaged_force_update.compiled(), self._q.Eval, *self._packed,
                      self._spatial, self._applied, self._applied_list) if lean else None
        self._indices = (int(self._w), int(self._process), int(self._force))
        self.DeclareStateOutputPort("spatial_force", self._force)
        if mode == "averaged":
            self.DeclareStateOutputPort("wrench", self._w)
        else:
            # held: flange rotation (9) and tool point (3), read between updates
            self._pose = self.DeclareDiscreteState(12)
            # the instants read before the next update (offsets from the update) and their wrenches (base frame)
            self._offsets = self._read_offsets(0.0)
            # (the instantaneous wrench, base frame, and the ripple, sensor frame, at each instant)
            self._inst = self.DeclareDiscreteState(np.zeros(12 * MAX_INSTANTS))
            self._inst_t = self.DeclareDiscreteState(np.full(MAX_INSTANTS, np.nan))
            now = {self.discrete_state_ticket(self._pose), self.time_ticket(), self.discrete_state_ticket(self._inst),
                   self.discrete_state_ticket(self._inst_t), self.discrete_state_ticket(self._process)}
            self.DeclareVectorOutputPort("wrench", 6, lambda c, o: o.SetFromVector(self._tooth_wrench_now(c)),
                                         prerequisites_of_calc=now)
            self.DeclareVectorOutputPort("ripple_sensor", 6, self._calc_ripple,
                                         prerequisites_of_calc=now | {self.discrete_state_ticket(self._w)})
            # the same table as held state (no call into Python to read it): the sensor looks its sample's
            # instant up itself (ripple_from_table), and reads ripple_sensor only at an instant not in it
            self.DeclareStateOutputPort("instant_table", self._inst)
            self.DeclareStateOutputPort("instant_times", self._inst_t)

    def _fused_constants(self, law, kinematics):
        """The constants of the averaged update as one compiled kernel
        (model/force_step_kernels.averaged_force_step), or None where it does
        not apply (a path with arcs, a law other than the plant's)."""
        if self._lines is None or not hasattr(law, "edge_coefficients") or not hasattr(kinematics, "chain_constants"):
            return None
        from robstiff_drake.model import plant_cutting
        return (kinematics.chain_constants(), self._window, *self._lines, self._feed_gain, self._period,
                force_step_kernels.law_constants(law), np.asarray(law.Kc, dtype=float),
                np.asarray(law.Ke, dtype=float), law._boxes(self._workpiece), law._k, law._dR,
                plant_cutting._GAUSS_X, plant_cutting._GAUSS_W)

    def _warm_up(self):
        """Load (or compile) the compiled motion and averaged update now,
        for the arrays a simulation passes them (the context's, read-only),
        not in the first update of a timed run (nothing without numba)."""
        if self._lines is None or not jit.available():
            return
        # (q: the input's; hist and process: views of the state the update writes in place; all writeable)
        q, hist, process = np.zeros(6), np.zeros(3 * self._n_hist), np.zeros(4)
        force_step_kernels.line_motion(0.0, 0.0, 0.0, 0.0, hist, self._window, *self._lines, np.empty(hist.shape[0]))
        if self._fused is not None:
            force_step_kernels.averaged_force_step(q, 0.0, hist, process, *self._fused, np.empty(22 + hist.shape[0]))
            force_step_kernels.averaged_force_update(q, 0.0, np.concatenate((process, hist)), np.zeros(6),
                                                     np.zeros(6), *self._packed)

    def set_progress(self, context, process, hist):
        """Hold ``process`` (u_x, u_y, feed m/s, cutting travel m) and the
        history ``hist`` (3 n, see ``motion``) in this block's ``context``."""
        context.get_mutable_discrete_state(self._indices[1]).SetFromVector(np.concatenate((process, hist)))

    @staticmethod
    def ripple_from_table(t, table, times):
        """The ripple (sensor frame, list of 6) at time t from the
        ``instant_table`` and ``instant_times`` outputs' values (lists), as
        ``ripple_sensor`` reads it; None when t is not a tabulated instant."""
        for i, ti in enumerate(times):
            if abs(ti - t) < 1e-9:
                return table[12 * i + 6:12 * i + 12]
        return None

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
        return self._tooth_wrench_at(context, context.get_time(),
                                     context.get_discrete_state(self._pose).value()[9:])

    def _tooth_wrench_at(self, context, t, p):
        """The instantaneous tooth wrench (base frame) at time t (s) with
        the tool point held at p (m), an instant the update did not tabulate."""
        u0, u1, feed, travel = context.get_discrete_state(self._process).value()[:4].tolist()
        return self._model.tooth_wrenches([t], p, (u0, u1), self._workpiece, self._phase, feed,
                                          **self._wear_args(travel))[0]

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

    def _wear_args(self, travel_m):
        return {"cut_length_m": travel_m} if self._wears else {}

    def motion(self, t, p, hist):
        """(feed direction (2,), horizontal feed m/s, the history with (t,
        s) added) from the tool point p (m) now and ``hist`` (3 n: t, s,
        0 per update, oldest first, NaN before the first): s is where along
        its path the tool really is (the path's point nearest it, found
        from the last update's; at the first, from a search of the whole
        path), the feed its progress since t - window
        (interpolated in the history) over the window, times the path's
        horizontal slope there (a plunge makes no horizontal chip), along
        the path's direction there; a tool that goes back cuts no chip."""
        if self._lines is not None and jit.available() and not math.isnan(hist[-3]):
            # (the arithmetic below, compiled: model/force_step_kernels.py)
            hist = np.asarray(hist, dtype=float)
            out = np.empty(hist.shape[0])
            u0, u1, feed = force_step_kernels.line_motion(t, float(p[0]), float(p[1]), float(p[2]), hist,
                                                          self._window, *self._lines, out)
            return (u0, u1), feed, out
        h = hist.tolist() if hasattr(hist, "tolist") else list(hist)
        last_t, last_s = h[-3], h[-2]
        s = self._path.project(p, last_s) if not math.isnan(last_t) else self._path.nearest_s(p)
        h = h[3:] + [t, s, 0.0]
        # the known updates (a suffix of the history: NaN before the first), oldest first
        first = 0
        while math.isnan(h[first]):
            first += 3
        t0 = t - self._window
        if len(h) - first < 6 or h[first] >= t0:
            ref_t, ref_s = h[first], h[first + 1]
        else:
            i = first + 3  # (numpy's searchsorted: the first known time >= t0; interpolated from the one before)
            while h[i] < t0:
                i += 3
            a_t, a_s, b_t, b_s = h[i - 3], h[i - 2], h[i], h[i + 1]
            f = (t0 - a_t) / (b_t - a_t)
            ref_t, ref_s = a_t + f * (b_t - a_t), a_s + f * (b_s - a_s)
        span = t - ref_t
        rate = (s - ref_s) / span if span > 0 else 0.0
        tg = self._path.tangent_at(s)
        return self._path.feed_direction_at(s), max(rate, 0.0) * math.hypot(tg[0], tg[1]), np.array(h)

    def smoothed_feed(self, feed_now, feed_held):
        """The feed the chip follows (m/s): the tool's progress low-passed
        at FEED_CUTOFF_HZ (first order, one step per update)."""
        return feed_held + self._feed_gain * (feed_now - feed_held)

    def step_wrench(self, t, q, process, hist, instants=()):
        """(wrench over the period starting at t as a list, pose, the
        instantaneous wrenches at ``instants`` (tooth mode; (k, 6)), the
        new process state, the new history): the pose is the flange
        rotation (row-major 9) and the tool point (3), m; ``process``: (u_x,
        u_y, feed m/s, cutting travel m) held from the last update;
        ``hist``: see ``motion``."""
        w, pose, inst, process, hist = self._step(t, q, process, hist, instants)
        return w.tolist(), pose, inst, process, hist

    def _step(self, t, q, process, hist, instants=()):
        """step_wrench with the wrench as an array."""
        if self._fused is not None and jit.available() and not math.isnan(hist[-3]):
            # (the averaged update below in one compiled call: model/force_step_kernels.py)
            hist = np.asarray(hist, dtype=float)
            out = np.empty(22 + hist.shape[0])
            force_step_kernels.averaged_force_step(np.asarray(q, dtype=float), float(t), hist,
                                                   np.asarray(process, dtype=float), *self._fused, out)
            return out[:6], out[10:22], None, out[6:10], out[22:]
        pose = self._kin.pose_only(q)
        p = pose[9:]
        u, feed, hist = self.motion(t, p, hist)
        _, _, feed_held, travel = process.tolist() if hasattr(process, "tolist") else process
        feed = self.smoothed_feed(feed, feed_held)
        wear = self._wear_args(travel)
        inst = None
        if self._mode == "tooth":
            n = len(self._sub_t)
            rows = self._model.tooth_wrenches(np.concatenate((t + self._sub_t, instants)), p, u, self._workpiece,
                                              self._phase, feed, **wear)
            w, inst = rows[:n].sum(axis=0) / n, rows[n:]
        else:
            w = self._model.average_wrench(p, u, self._workpiece, feed, **wear)
        if w[0] != 0.0 or w[1] != 0.0 or w[2] != 0.0:  # in the material: the edges travel (their wear's clock)
            travel += feed * self._period
        return w, pose, inst, np.array([float(u[0]), float(u[1]), feed, travel]), hist

    def _update(self, context, state):
        i_w, i_process, i_force = self._indices
        discrete = state.get_mutable_discrete_state()
        held = discrete.get_mutable_value(i_process)  # (arrives holding the current state: written in place)
        fast = self._fast
        if fast is not None and jit.available() and not math.isnan(held[-3]):
            # (_step's compiled averaged update, the state written in place, with no more calls into Drake than it
            # needs; unless a subclass changes the step: a study's)
            update, q, consts, at, sf, applied, applied_list = fast
            update(q(context), context.get_time(), held, discrete.get_mutable_value(i_w), sf, consts, at)
            applied.F_Bq_W = SpatialForce(sf)
            state.get_mutable_abstract_state(i_force).set_value(applied_list)
            return
        process, hist = held[:4], held[4:]
        q = self._q.Eval(context)[:6]
        t = context.get_time()
        instants = self._read_offsets(t) if self._mode == "tooth" else ()
        w, pose, inst, new_process, new_hist = self._step(t, q, process, hist, instants)
        discrete.set_value(i_w, w)
        held[:4], held[4:] = new_process, new_hist
        if inst is not None:
            pose = np.array(pose)
            discrete.set_value(int(self._pose), pose)  # (read between updates in tooth mode only)
            times = np.full(MAX_INSTANTS, np.nan)
            times[:len(instants)] = instants
            values = np.zeros((MAX_INSTANTS, 12))
            values[:len(inst), :6] = inst
            if jit.available():  # (the loop below compiled: model/tick_kernels.py)
                tick_kernels.sensor_ripples(inst, w, pose, self._tool_a, values)
            else:
                R = pose[:9].tolist()
                for i, d in enumerate((inst - w).tolist()):  # (the ripple, as _ripple: one subtraction for the rows)
                    values[i, 6:] = to_sensor_frame(R, self._tool, d)
            discrete.set_value(int(self._inst), values.ravel())
            discrete.set_value(int(self._inst_t), times)
        state.get_mutable_abstract_state(i_force).set_value([self._spatial_force(w)])
