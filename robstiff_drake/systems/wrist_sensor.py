"""The wrist force/torque sensor between flange and spindle, and the guard
that keeps bad samples (dropouts, spikes) out of the compensation chain."""

import math

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.multibody.math import SpatialForce
from pydrake.systems.framework import LeafSystem

from robstiff_drake.model.compensator import guard_accepts

NOISE_BLOCK = 4096  # noise samples drawn at once (per-sample draws are slow)


class WristForceSensor(LeafSystem):
    """Samples the wrench across the flange-spindle weld at ``rate_hz``.

    Input  ``reaction_forces``: the plant's reaction forces (abstract); the
      weld's reaction carries the payload's weight and inertia.
    Input  ``process_wrench`` (6): the cutting load in the sensor frame (the
      milling source applies it to the arm as joint torques, so the weld's
      reaction does not include it; the sensor adds it back).
    Output ``wrench`` (6): (force N, torque N*m) that the payload (spindle,
      tool and the cutting load on it) exerts on the sensor, sensor frame
      (= DH frame 6), plus bias and Gaussian noise; NaN during a dropout, and
      a spike of ``spike_N`` on a random force axis with ``spike_probability``.
    """

    def __init__(self, *, weld_joint_index, rate_hz, force_bias_N=(0, 0, 0), torque_bias_Nm=(0, 0, 0),
                 noise_N=0.0, noise_Nm=0.0, dropout_probability=0.0, spike_probability=0.0, spike_N=0.0,
                 seed=0, initial_wrench=None):
        super().__init__()
        self._joint = int(weld_joint_index)
        self._bias = np.concatenate([force_bias_N, torque_bias_Nm]).astype(float)
        self._noise = np.array([noise_N] * 3 + [noise_Nm] * 3, dtype=float)
        self._p_drop = float(dropout_probability)
        self._p_spike = float(spike_probability)
        self._spike = float(spike_N)
        self._seed = seed
        self._restart_noise()
        self._reaction = self.DeclareAbstractInputPort("reaction_forces", AbstractValue.Make([SpatialForce()]))
        self._process = self.DeclareVectorInputPort("process_wrench", 6)
        init = np.zeros(6) if initial_wrench is None else np.asarray(initial_wrench, dtype=float)
        self._state = self.DeclareDiscreteState(init)
        self.DeclarePeriodicDiscreteUpdateEvent(1.0 / rate_hz, 0.0, self._sample)
        # every simulation starts the noise sequence afresh: the same
        # scenario gives the same numbers, even when a diagram is reused
        self.DeclareInitializationDiscreteUpdateEvent(lambda context, discrete_state: self._restart_noise())
        self.DeclareStateOutputPort("wrench", self._state)

    def _restart_noise(self):
        self._rng = np.random.default_rng(self._seed)
        self._block, self._next = None, NOISE_BLOCK

    def true_wrench(self, context):
        """The noise-free, bias-free wrench (sensor frame) at this instant, a list."""
        # the weld's reaction on the spindle, from the flange: (torque, force)
        t0, t1, t2, f0, f1, f2 = self._reaction.Eval(context)[self._joint].get_coeffs().tolist()
        p0, p1, p2, p3, p4, p5 = self._process.Eval(context).tolist()
        return [p0 - f0, p1 - f1, p2 - f2, p3 - t0, p4 - t1, p5 - t2]

    def _draw(self):
        """(noise 6, dropout and spike uniforms, spike axis, spike sign) for
        one sample, from blocks drawn at once and kept as Python lists."""
        if self._next >= NOISE_BLOCK:
            r = self._rng
            self._block = ((r.standard_normal((NOISE_BLOCK, 6)) * self._noise + self._bias).tolist(),
                           r.random((NOISE_BLOCK, 2)).tolist(), r.integers(0, 3, NOISE_BLOCK).tolist(),
                           r.choice([-1.0, 1.0], NOISE_BLOCK).tolist())
            self._next = 0
        i = self._next
        self._next += 1
        return self._block[0][i], self._block[1][i], self._block[2][i], self._block[3][i]

    def _sample(self, context, discrete_state):
        offset, u, axis, sign = self._draw()  # bias + noise
        w = [a + b for a, b in zip(self.true_wrench(context), offset)]
        if self._p_drop or self._p_spike:
            if u[0] < self._p_drop:
                w = [math.nan] * 6
            elif u[1] < self._p_spike:
                w[axis] += self._spike * sign
        discrete_state.set_value(self._state, np.array(w))


class WrenchGuard(LeafSystem):
    """Holds the last good sample: a non-finite sample, or one that jumps by
    more than ``max_jump_N`` (force) from the last good one, is replaced by it.

    Input ``wrench`` (6), output ``wrench`` (6), updated at ``rate_hz``;
    output ``rejected`` (1): how many samples were rejected so far."""

    def __init__(self, *, rate_hz, max_jump_N, initial_wrench=None):
        super().__init__()
        self._max_jump = float(max_jump_N)
        self._in = self.DeclareVectorInputPort("wrench", 6)
        init = np.zeros(6) if initial_wrench is None else np.asarray(initial_wrench, dtype=float)
        self._state = self.DeclareDiscreteState(init)
        self._count = self.DeclareDiscreteState(1)
        self.DeclarePeriodicDiscreteUpdateEvent(1.0 / rate_hz, 0.0, self._update)
        self.DeclareStateOutputPort("wrench", self._state)
        self.DeclareStateOutputPort("rejected", self._count)

    def _update(self, context, discrete_state):
        # discrete_state arrives holding the current state: overwrite it in
        # place when the sample is good, count it when it is not
        w = self._in.Eval(context)
        held = discrete_state.get_mutable_vector(int(self._state)).get_mutable_value()
        if guard_accepts(w.tolist(), held[:3].tolist(), self._max_jump):  # (model/compensator.py)
            held[:] = w
        else:
            discrete_state.get_mutable_vector(int(self._count)).get_mutable_value()[0] += 1.0
