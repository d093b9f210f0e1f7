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
also carries the wrench guard (systems/wrist_sensor.WrenchGuard's update,
``guard_step``, on its own state): the guard's sample and the tick's are
taken at the same instants from the same context, so one call into Python
does both, as the two blocks did in two.

A predictor with state of its own (predictive or preview mode, or lost
motion in the model with its static torque) stays a block of its own:
then ``dq`` is an input (computed from this block's sampled outputs), and
this block samples, removes gravity, saturates, delays and corrects.

With numba installed the update runs as two compiled kernels
(model/tick_kernels.py: the same arithmetic to round-off), loaded while
the block is built; without it (or with ROBSTIFF_NO_JIT set, or within
model/jit.disabled) the plain-Python reference below, which the kernels
are tested against.
"""

import math

import numpy as np
from robstiff_drake.systems.leaf_system import LeafSystem

from robstiff_drake.model import jit, tick_kernels
from robstiff_drake.model.compensator import GravityRemover, rate_limited_step
from robstiff_drake.model.payload import _GRAVITY
from robstiff_drake.systems.wrist_sensor import GUARD_REARM_S, guard_step


_NONE = np.empty(0)  # (an empty delay line)


def saturate(v, lo, hi):
    """Drake's Saturation for one value (a NaN passes through)."""
    return lo if v < lo else (hi if v > hi else v)


class CompensatorTick(LeafSystem):
    """Inputs ``wrench`` (6, the filtered wrench, sensor frame), ``q`` (6,
    the reported joint angles, rad) and, with ``deflection`` None, ``dq``
    (6, rad: the predicted deflection from the sampled outputs).

    Outputs (all held state, updated every ``period_s``): ``wrench_sampled``
    (6), ``q_sampled`` (6), ``process_wrench`` (6, sensor frame: the sampled
    wrench less the payload's weight and bias), ``dq`` (6, rad; only with a
    ``deflection`` model) and ``correction`` (6, rad).

    ``calibration``/``kinematics``: gravity removal's (GravityRemover);
    ``deflection``: a model/compensator.DeflectionModel without lost motion
    (its dq from the process wrench and q alone), or None for a ``dq``
    input; ``saturation_rad`` (per joint, symmetric), ``delay_steps`` (whole
    periods), ``rate_limit_rad_per_s``: the correction's.

    ``guard``: None, or (rate_hz, max_jump_N[, rearm_s]) of a WrenchGuard
    sampled every ``period_s`` (rate_hz = 1 / period_s) that this block
    carries: then input ``raw_wrench`` (6) and outputs ``guarded_wrench``
    (6) and ``rejected`` (1), the guard's, and ``wrench`` is the filter's
    output of ``guarded_wrench`` as before."""

    def __init__(self, *, period_s, calibration, kinematics, deflection, saturation_rad, delay_steps,
                 rate_limit_rad_per_s, guard=None):
        super().__init__()
        self._remove = GravityRemover(calibration, kinematics)
        self._model = deflection
        sat = saturation_rad * np.ones(6)  # (as the Saturation block's limits)
        self._lo, self._hi = (-sat).tolist(), sat.tolist()
        self._n = int(delay_steps)
        self._step = (np.asarray(rate_limit_rad_per_s, dtype=float) * period_s * np.ones(6)).tolist()
        self._w_in = self.DeclareVectorInputPort("wrench", 6)
        self._q_in = self.DeclareVectorInputPort("q", 6)
        self._dq_in = self.DeclareVectorInputPort("dq", 6) if deflection is None else None
        # the state a default context starts from: samples of zero, as the holds' zeros
        w0, q0 = np.zeros(6), np.zeros(6)
        p0, dq0 = self._process_and_dq(w0, q0)
        self._w = self.DeclareDiscreteState(w0)
        self._q = self.DeclareDiscreteState(q0)
        self._p = self.DeclareDiscreteState(p0)
        self._dq = self.DeclareDiscreteState(dq0) if deflection is not None else None
        self._line = self.DeclareDiscreteState(6 * self._n) if self._n else None  # oldest first
        self._c = self.DeclareDiscreteState(6)
        self.DeclarePeriodicDiscreteUpdateEvent(period_s, 0.0, self._update)
        self.DeclareStateOutputPort("wrench_sampled", self._w)
        self.DeclareStateOutputPort("q_sampled", self._q)
        self.DeclareStateOutputPort("process_wrench", self._p)
        if self._dq is not None:
            self.DeclareStateOutputPort("dq", self._dq)
        self.DeclareStateOutputPort("correction", self._c)
        self._guard = None
        if guard is not None:  # (WrenchGuard's state, ports and constants)
            rate_hz, max_jump_N, *rest = guard
            rearm_s = rest[0] if rest else GUARD_REARM_S
            if 1.0 / rate_hz != period_s:
                raise ValueError(f"a guard carried by the tick samples at its period: rate_hz {rate_hz!r} is not "
                                 f"1 / period_s {period_s!r}")
            self._raw = self.DeclareVectorInputPort("raw_wrench", 6)
            g = self.DeclareDiscreteState(np.zeros(6))
            count, run = self.DeclareDiscreteState(1), self.DeclareDiscreteState(1)
            self.DeclareStateOutputPort("guarded_wrench", g)
            self.DeclareStateOutputPort("rejected", count)
            self._guard = ((int(g), int(count), int(run)), float(max_jump_N), max(1, int(round(rearm_s * rate_hz))))
            self.held_group = int(g)  # (Compensator.set_initial_state)
        self._compiled = self._kernel_constants(deflection, sat, period_s, rate_limit_rad_per_s)
        # the state groups' numbers as Python ints (int() of a pybind index is a call into the bindings)
        self._i = tuple(-1 if g is None else int(g) for g in (self._w, self._q, self._p, self._dq, self._line, self._c))
        self.warm_up()

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
        chain, gravity, model, lo, hi, step = self._compiled
        held = np.zeros(6)
        held.flags.writeable = False  # (a state's value, as the update reads it)
        line = np.zeros(6 * self._n)
        line.flags.writeable = not self._n  # (the state's, or the empty line's)
        for dq in (held, np.zeros(6)):  # (the held dq, or the dq input's)
            tick_kernels.correction_step(dq, line, held, lo, hi, step, np.empty(6 * self._n + 6))
        tick_kernels.pose_and_deflection(np.zeros(6), chain, np.zeros(6), gravity, model,
                                         np.empty(18 if self._model is None else 24))

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
        context.SetDiscreteState(int(self._w), w)
        context.SetDiscreteState(int(self._q), q)
        context.SetDiscreteState(int(self._p), p)
        if dq is not None:
            context.SetDiscreteState(int(self._dq), dq)

    def _update(self, context, discrete_state):
        if self._guard is not None:  # (its own state groups: the order of the two updates does not matter)
            guard_step(self._raw.Eval(context), discrete_state, *self._guard)
        if self._compiled is not None and jit.available():
            self._update_compiled(context, discrete_state)
        else:
            self._update_reference(context, discrete_state)

    def _update_compiled(self, context, discrete_state):
        """_update_reference's arithmetic in two compiled kernels."""
        chain, gravity, model, lo, hi, step = self._compiled
        i_w, i_q, i_p, i_dq, i_line, i_c = self._i
        held = context.get_discrete_state()  # (one call into Drake for the three values read)
        dq = held.get_value(i_dq) if i_dq >= 0 else self._dq_in.Eval(context)
        n6 = 6 * self._n
        out = np.empty(n6 + 6)
        tick_kernels.correction_step(dq, held.get_value(i_line) if n6 else _NONE, held.get_value(i_c), lo, hi, step,
                                     out)
        if n6:
            discrete_state.set_value(i_line, out[:n6])
        discrete_state.set_value(i_c, out[n6:])
        w, q = self._w_in.Eval(context), self._q_in.Eval(context)
        res = np.empty(18 if i_dq < 0 else 24)
        tick_kernels.pose_and_deflection(q, chain, w, gravity, model, res)
        discrete_state.set_value(i_w, w)
        discrete_state.set_value(i_q, q)
        discrete_state.set_value(i_p, res[12:18])
        if i_dq >= 0:
            discrete_state.set_value(i_dq, res[18:24])

    def _update_reference(self, context, discrete_state):
        # the deflection of the previous tick's sample, saturated
        dq = (context.get_discrete_state(self._dq).value() if self._dq is not None
              else self._dq_in.Eval(context)).tolist()
        s = [saturate(v, lo, hi) for v, lo, hi in zip(dq, self._lo, self._hi)]
        if self._n:
            line = context.get_discrete_state(self._line).value().tolist()
            d = line[:6]  # n periods ago
            discrete_state.set_value(int(self._line), np.array(line[6:] + s))
        else:
            d = s
        if math.isfinite(sum(d)):  # (a non-finite one leaves the correction where it is)
            c = context.get_discrete_state(self._c).value().tolist()
            discrete_state.set_value(int(self._c), np.array(rate_limited_step(c, d, self._step)))
        # this tick's sample
        w, q = self._w_in.Eval(context), self._q_in.Eval(context)
        p, dq_now = self._process_and_dq(w, q)
        discrete_state.set_value(int(self._w), w)
        discrete_state.set_value(int(self._q), q)
        discrete_state.set_value(int(self._p), p)
        if dq_now is not None:
            discrete_state.set_value(int(self._dq), dq_now)
