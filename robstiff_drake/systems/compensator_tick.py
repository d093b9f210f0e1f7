"""The compensator's controller tick as one block: the sample-and-hold of
the filtered wrench and of the reported joint angles, gravity removal, the
deflection prediction, the saturation, the transport delay and the
rate-limited reference correction, in one discrete update per controller
period.  These blocks only hand values on from one to the next once per
period; as separate Drake blocks each cost a call from C++ into Python (or a
discrete update of its own) every tick.  The arithmetic is
model/compensator.py's (GravityRemover, DeflectionModel,
rate_limited_step), shared with the compensator process, and the timing is
that of the separate blocks with Drake's same-instant semantics, exactly:

    tick k:  (w_k, q_k) = the inputs now            (the two ZeroOrderHolds)
             p_k = w_k - bias - weight(q_k)          (GravityRemoval)
             dq_k = C J(q_k)^T p_k                   (DeflectionPrediction)
             s = saturate(dq_{k-1})                  (Saturation, read before the update)
             d = s delayed by n periods              (ZeroOrderHold n = 1, DiscreteTimeDelay n - 1)
             c_k = c_{k-1} moved towards -d          (RateLimitedCorrection)

Where the wrist sensor is read once per controller period, the block
also carries the wrench guard and the force filter (its LinearSystem's
update and output, the same sums in the same order: one C++ block fewer
and one input read fewer per tick) (systems/wrist_sensor.WrenchGuard's update,
``guard_step``, on its part of the state): the guard's sample and the tick's are
taken at the same instants from the same context, so one call into Python
does both, as the two blocks did in two.

All of the block's state is one discrete state group, read and written
in place by the update (one call into the bindings for it, where a group
per value took a call for each read and each write), and its one output
port ``state`` is split into the named signals by a C++ Demultiplexer
(``add_outputs``), which costs no call into Python.

A predictor with state of its own (predictive or preview mode, or lost
motion in the model with its static torque) stays a block of its own:
then ``dq`` is an input (computed from this block's sampled outputs), and
this block samples, removes gravity, saturates, delays and corrects.

With numba installed the update runs as one compiled call
(model/tick_kernels.tick_update: the carried guard, the correction and the
sample, written into the state group in place; the same arithmetic to
round-off; its constants packed in two arrays, as numba's dispatcher costs
about 0.05 us per argument), loaded while the block is built; without it (or with
ROBSTIFF_NO_JIT set, or within model/jit.disabled) the plain-Python
reference below (with wrist_sensor.guard_step), which the kernels are
tested against.
"""

import math

import numpy as np
from pydrake.systems.primitives import Demultiplexer

from robstiff_drake.model import jit, tick_kernels
from robstiff_drake.model.compensator import GravityRemover, rate_limited_step
from robstiff_drake.model.payload import _GRAVITY
from robstiff_drake.systems.leaf_system import LeafSystem
from robstiff_drake.systems.wrist_sensor import GUARD_REARM_S, guard_step


_NONE = np.empty(0)  # (an empty delay line)


def _dot(row, v):
    """sum of value * v[column] over ``row``'s (column, value) pairs, in order, from 0.0."""
    s = 0.0
    for j, a in row:
        s += a * v[j]
    return s


def saturate(v, lo, hi):
    """Drake's Saturation for one value (a NaN passes through)."""
    return lo if v < lo else (hi if v > hi else v)


class CompensatorTick(LeafSystem):
    """Inputs ``wrench`` (6, the filtered wrench, sensor frame), ``q`` (6,
    the reported joint angles, rad) and, with ``deflection`` None, ``dq``
    (6, rad: the predicted deflection from the sampled outputs).

    Output ``state``: the block's whole state, held and updated every
    ``period_s``; ``layout`` names its parts in order, (name, size), and
    ``add_outputs`` splits it into them: ``wrench_sampled`` (6),
    ``q_sampled`` (6), ``process_wrench`` (6, sensor frame: the sampled
    wrench less the payload's weight and bias), ``dq`` (6, rad; only with a
    ``deflection`` model), ``correction`` (6, rad), with a guard
    ``guarded_wrench`` (6) and ``rejected`` (1), and the parts no one reads
    (named with a leading underscore: the guard's rejections in a row, the
    delay line, oldest first).

    ``calibration``/``kinematics``: gravity removal's (GravityRemover);
    ``deflection``: a model/compensator.DeflectionModel without lost motion
    (its dq from the process wrench and q alone), or None for a ``dq``
    input; ``saturation_rad`` (per joint, symmetric), ``delay_steps`` (whole
    periods), ``rate_limit_rad_per_s``: the correction's.

    ``guard``: None, or (rate_hz, max_jump_N[, rearm_s]) of a WrenchGuard
    sampled every ``period_s`` (rate_hz = 1 / period_s) that this block
    carries: then input ``raw_wrench`` (6) and the parts ``guarded_wrench``
    and ``rejected``, the guard's, and ``wrench`` is the filter's output of
    ``guarded_wrench`` as before.

    ``force_filter``: None, or the force filter's LinearSystem
    (systems/force_filter.filter_system, of period ``period_s``; with a
    ``guard``) that this block carries on the guard's samples: then no
    input ``wrench``, and the parts ``filtered_wrench`` (the filter's
    output, held as the LinearSystem's output would be at every instant)
    and ``_filter_state``; ``filter_system`` keeps the LinearSystem (not
    in any diagram) for its design."""

    def __init__(self, *, period_s, calibration, kinematics, deflection, saturation_rad, delay_steps,
                 rate_limit_rad_per_s, guard=None, force_filter=None):
        super().__init__()
        self._remove = GravityRemover(calibration, kinematics)
        self._model = deflection
        sat = saturation_rad * np.ones(6)  # (as the Saturation block's limits)
        self._lo, self._hi = (-sat).tolist(), sat.tolist()
        self._n = int(delay_steps)
        self._step = (np.asarray(rate_limit_rad_per_s, dtype=float) * period_s * np.ones(6)).tolist()
        self._filter = self.filter_system = None
        if force_filter is not None:  # (the force filter's matrices, C-ordered for the kernels)
            if guard is None or force_filter.time_period() != period_s:
                raise ValueError(f"a force filter carried by the tick filters the carried guard's samples at the "
                                 f"tick's period: give guard, and a filter of period {period_s!r} s")
            self.filter_system = force_filter
            self._filter = tuple(np.ascontiguousarray(m, dtype=float) for m in (
                force_filter.A(), force_filter.B(), force_filter.C(), force_filter.D()))
            # (the plain-Python reference's rows: each row's nonzero (column, value), summed in column order)
            self._filter_rows = tuple(tuple(tuple((j, float(v)) for j, v in enumerate(row) if v != 0.0)
                                            for row in m) for m in self._filter)
        n_filter = 0 if force_filter is None else self._filter[0].shape[0]
        self._w_in = self.DeclareVectorInputPort("wrench", 6) if force_filter is None else None
        self._q_in = self.DeclareVectorInputPort("q", 6)
        self._dq_in = self.DeclareVectorInputPort("dq", 6) if deflection is None else None
        self._guard = None
        if guard is not None:  # (WrenchGuard's input and constants)
            rate_hz, max_jump_N, *rest = guard
            rearm_s = rest[0] if rest else GUARD_REARM_S
            if 1.0 / rate_hz != period_s:
                raise ValueError(f"a guard carried by the tick samples at its period: rate_hz {rate_hz!r} is not "
                                 f"1 / period_s {period_s!r}")
            self._raw = self.DeclareVectorInputPort("raw_wrench", 6)
            self._guard = (float(max_jump_N), max(1, int(round(rearm_s * rate_hz))))
        self.layout = tuple((name, size) for name, size, present in (
            ("wrench_sampled", 6, True), ("q_sampled", 6, True), ("process_wrench", 6, True),
            ("dq", 6, deflection is not None), ("correction", 6, True), ("guarded_wrench", 6, guard is not None),
            ("rejected", 1, guard is not None), ("_rejected_in_a_row", 1, guard is not None),
            ("filtered_wrench", 6, force_filter is not None), ("_filter_state", n_filter, n_filter > 0),
            ("_delay_line", 6 * self._n, self._n > 0)) if present)
        self._at, start = {}, 0
        for name, size in self.layout:
            self._at[name] = slice(start, start + size)
            start += size
        # the state a default context starts from: samples of zero, as the holds' zeros
        x0 = np.zeros(start)
        p0, dq0 = self._process_and_dq(np.zeros(6), np.zeros(6))
        x0[self._at["process_wrench"]] = p0
        if dq0 is not None:
            x0[self._at["dq"]] = dq0
        group = self.DeclareDiscreteState(x0)  # (its number, 0, is written as a Python int below)
        self.DeclarePeriodicDiscreteUpdateEvent(period_s, 0.0, self._update)
        self.DeclareStateOutputPort("state", group)
        self._compiled = self._kernel_constants(deflection, sat, period_s, rate_limit_rad_per_s)
        at = self._at
        self._s = tuple(at.get(name) for name in ("wrench_sampled", "q_sampled", "process_wrench", "dq",
                                                  "_delay_line", "correction"))
        self._s_guard = tuple(at.get(name) for name in ("guarded_wrench", "rejected", "_rejected_in_a_row"))
        self._s_filter = (at.get("filtered_wrench"), at.get("_filter_state", slice(0, 0)))
        # (the compiled update's constants, packed: model/tick_kernels.tick_update)
        self._fused = None if self._compiled is None else self._fused_arguments(*self._compiled)
        # (the compiled update's kernel, its inputs' Eval (None: absent) and its constants, for _update)
        self._fast = None if self._fused is None else (tick_kernels.tick_update, *(
            None if port is None else port.Eval for port in (self._raw if guard is not None else None,
                                                               self._w_in, self._q_in, self._dq_in)), *self._fused)
        self.warm_up()

    def add_outputs(self, builder, name=None):
        """A Demultiplexer (C++) in ``builder`` that splits the ``state``
        output into its parts: {part name: its output port}, the unread
        parts (a leading underscore) left out."""
        demux = builder.AddNamedSystem(name or f"{self.get_name()}_outputs",
                                       Demultiplexer([size for _, size in self.layout]))
        builder.Connect(self.GetOutputPort("state"), demux.get_input_port())
        return {part: demux.get_output_port(i) for i, (part, _) in enumerate(self.layout) if part[0] != "_"}

    def part_columns(self, part):
        """The columns (a slice) of ``part`` (a name of ``layout``) in the output ``state``."""
        return self._at[part]

    def held(self, context, part):
        """The held value of ``part`` (a name of ``layout``) in this block's ``context`` (a copy)."""
        return context.get_discrete_state(0).value()[self._at[part]].copy()

    def _kernel_constants(self, deflection, sat, period_s, rate_limit_rad_per_s):
        """The compiled update's constants (model/tick_kernels.py), or None
        where it does not apply (a model with coupling, or a model whose
        kinematics is not gravity removal's)."""
        chain = tick_kernels.chain_constants(self._remove._kin)
        gravity = tick_kernels.gravity_constants(self._remove, _GRAVITY)
        if deflection is None:
            model = np.empty(0)
        elif (deflection.lost is not None or deflection.c23
              or not np.array_equal(tick_kernels.chain_constants(deflection._pred), chain)):
            return None
        else:
            model = tick_kernels.model_constants(deflection)
        step = np.asarray(rate_limit_rad_per_s, dtype=float) * period_s * np.ones(6)
        return chain, gravity, model, -sat, sat, step

    def warm_up(self):
        """Load (or compile) the update's kernels now, not in the first tick
        of a timed simulation (nothing without numba)."""
        if self._compiled is None or not jit.available():
            return
        # (the inputs' values and the state group as the simulation passes them: writeable float arrays)
        x = np.zeros(sum(size for _, size in self.layout))
        update, raw, w, _, dq, consts, at = self._fast
        update(x, _NONE if raw is None else np.zeros(6), _NONE if w is None else np.zeros(6), np.zeros(6),
               _NONE if dq is None else np.zeros(6), consts, at)
        # (from here on the compiled kernel itself, without its wrapper's cost: model/jit.Kernel.compiled)
        self._fast = (tick_kernels.tick_update.compiled(),) + self._fast[1:]

    def _fused_arguments(self, chain, gravity, model, lo, hi, step):
        """tick_update's arguments after its inputs (model/tick_kernels.pack_tick_constants):
        the layout's offsets (TICK_AT_SIZE), the guard's constants and the kernels' constants,
        packed in one float array and one int array."""
        def at(name):
            return self._at[name].start if name in self._at else -1
        offsets = [at("wrench_sampled"), at("q_sampled"), at("process_wrench"), at("dq"),
                   max(at("_delay_line"), 0), 6 * self._n, at("correction"), at("guarded_wrench"),
                   at("rejected"), at("_rejected_in_a_row"), at("filtered_wrench"), max(at("_filter_state"), 0)]
        guard = self._guard if self._guard is not None else (0.0, 0.0)
        matrices = self._filter if self._filter is not None else (np.empty((0, 0)),) * 4
        return tick_kernels.pack_tick_constants(offsets, guard, chain, gravity, model, lo, hi, step, *matrices)

    @property
    def model(self):
        """The deflection model (model/compensator.DeflectionModel), or None."""
        return self._model

    def tool_wrench_of(self, process_wrench, q):
        """The wrench at the tool point (base frame, list of 6) for a process
        wrench in the sensor frame at joint angles q (rad)."""
        return self._model.tool_wrench(process_wrench, q)

    def _process_and_dq(self, w, q):
        """(process wrench, dq or None) of a sample (arrays), as the separate
        blocks computed them."""
        p = np.array(self._remove(w.tolist(), q))
        dq = None if self._model is None else np.asarray(self._model.dq(p, q, None))
        return p, dq

    def set_sample(self, context, wrench, q):
        """Hold the sample (``wrench``, ``q``) in this block's ``context`` (and
        what follows from it: the process wrench, dq)."""
        w, q = np.asarray(wrench, dtype=float), np.asarray(q, dtype=float)
        p, dq = self._process_and_dq(w, q)
        x = context.get_discrete_state(0).value().copy()
        x[self._at["wrench_sampled"]], x[self._at["q_sampled"]], x[self._at["process_wrench"]] = w, q, p
        if dq is not None:
            x[self._at["dq"]] = dq
        context.SetDiscreteState(0, x)

    def hold(self, context, wrench):
        """Hold ``wrench`` (6) as the carried guard's last good sample in this block's ``context``
        (and a carried filter's output of it)."""
        x = context.get_discrete_state(0).value().copy()
        x[self._at["guarded_wrench"]] = wrench
        self._filter_output_reference(x)
        context.SetDiscreteState(0, x)

    def set_filter_state(self, context, state):
        """Set the carried force filter's state (n, the LinearSystem's) in
        this block's ``context``, and its output with it."""
        x = context.get_discrete_state(0).value().copy()
        x[self._s_filter[1]] = state
        self._filter_output_reference(x)
        context.SetDiscreteState(0, x)

    def _filter_output_reference(self, x):
        """The carried filter's output of its state and the guard's sample,
        written into the state ``x`` (nothing without a carried filter):
        C xf + D u, each product summed in column order as Drake's."""
        if self._filter is None:
            return
        _, _, rows_c, rows_d = self._filter_rows
        s_y, s_f = self._s_filter
        xf, u = x[s_f].tolist(), x[self._s_guard[0]].tolist()
        x[s_y] = [_dot(rc, xf) + _dot(rd, u) for rc, rd in zip(rows_c, rows_d)]

    def _filter_state_reference(self, x):
        """The carried filter's update on the state ``x``, in place: xf <- A xf + B u
        with the guard's sample u before the guard's update."""
        rows_a, rows_b, _, _ = self._filter_rows
        s_f = self._s_filter[1]
        xf, u = x[s_f].tolist(), x[self._s_guard[0]].tolist()
        x[s_f] = [_dot(ra, xf) + _dot(rb, u) for ra, rb in zip(rows_a, rows_b)]

    def _update(self, context, discrete_state):
        x = discrete_state.get_mutable_value(0)  # (arrives holding the current state: written in place)
        fast = self._fast
        if fast is not None and jit.available():  # (all of the below in one compiled call)
            update, raw, w, q, dq, consts, at = fast
            update(x, _NONE if raw is None else raw(context), _NONE if w is None else w(context), q(context),
                   _NONE if dq is None else dq(context), consts, at)
            return
        w = None
        if self._filter is not None:  # (the filter's output before this tick, and its update on the guard's sample)
            w = x[self._s_filter[0]].copy()
            self._filter_state_reference(x)
        if self._guard is not None:  # (its own parts of the state: the order of the two updates does not matter)
            g, count, run = self._s_guard
            guard_step(self._raw.Eval(context), x[g], x[count], x[run], *self._guard)
        self._filter_output_reference(x)
        self._update_reference(context, x, w)

    def _update_reference(self, context, x, w=None):
        s_w, s_q, s_p, s_dq, s_line, s_c = self._s
        # the deflection of the previous tick's sample, saturated
        dq = (x[s_dq] if s_dq is not None else self._dq_in.Eval(context)).tolist()
        s = [saturate(v, lo, hi) for v, lo, hi in zip(dq, self._lo, self._hi)]
        if self._n:
            line = x[s_line].tolist()
            d = line[:6]  # n periods ago
            x[s_line] = line[6:] + s
        else:
            d = s
        if math.isfinite(sum(d)):  # (a non-finite one leaves the correction where it is)
            x[s_c] = rate_limited_step(x[s_c].tolist(), d, self._step)
        # this tick's sample
        w, q = self._w_in.Eval(context) if w is None else w, self._q_in.Eval(context)
        p, dq_now = self._process_and_dq(w, q)
        x[s_w], x[s_q], x[s_p] = w, q, p
        if dq_now is not None:
            x[s_dq] = dq_now
