"""The wrist force/torque sensor between flange and spindle, and the guard
that keeps bad samples (dropouts, spikes) out of the compensation chain."""

import math

import numpy as np
from pydrake.common import RandomDistribution
from pydrake.common.value import AbstractValue
from pydrake.multibody.math import SpatialForce
from robstiff_drake.systems.leaf_system import LeafSystem
from pydrake.systems.primitives import RandomSource

from robstiff_drake.model import jit, sensor_sample
from robstiff_drake.model.compensator import guard_accepts
from robstiff_drake.model.realtime import rotate_transposed
from robstiff_drake.model.wrench_frames import to_sensor_frame
from robstiff_drake.systems.milling_force import MAX_INSTANTS, MillingForceSource


class WristForceSensor(LeafSystem):
    """Samples the wrench across the flange-spindle weld at ``rate_hz``.

    Input  ``reaction_forces``: the plant's reaction forces (abstract); the
      weld's reaction carries the payload's weight and inertia and the
      cutting load (which the milling source applies to the spindle).
    Input  ``gaussian`` (6; with noise) and ``uniform`` (3; with dropouts or
      spikes): standard normal and uniform [0, 1) samples, one set per sensor
      sample, from Drake RandomSources (``add_random_inputs``): the randomness
      lives in the Context, so a simulation's noise is set by the context's
      random generator, not by this object.
    Input  ``ripple`` (6), with ``tooth_ripple=True``: the part of the tooth
      force the plant's step averages away (MillingForceSource), which a
      sensor faster than the step still sees; inputs ``instant_table`` and
      ``instant_times`` (optional), the source's table of it, read first
      (no call into Python), ``ripple`` only at an instant not in it.
    Output ``wrench`` (6): (force N, torque N*m) that the payload (spindle,
      tool and the cutting load on it) exerts on the sensor, sensor frame
      (= DH frame 6), plus bias and Gaussian noise; NaN during a dropout, and
      a spike of ``spike_N`` on a random force axis with ``spike_probability``.
    """

    def __init__(self, *, weld_joint_index, rate_hz, force_bias_N=(0, 0, 0), torque_bias_Nm=(0, 0, 0),
                 noise_N=0.0, noise_Nm=0.0, dropout_probability=0.0, spike_probability=0.0, spike_N=0.0,
                 initial_wrench=None, tooth_ripple=False):
        super().__init__()
        self._joint = int(weld_joint_index)
        self._bias = np.concatenate([force_bias_N, torque_bias_Nm]).astype(float).tolist()
        self._noise = [float(noise_N)] * 3 + [float(noise_Nm)] * 3
        self._p_drop = float(dropout_probability)
        self._p_spike = float(spike_probability)
        self._spike = float(spike_N)
        self.period_s = 1.0 / rate_hz
        self._reaction = self.DeclareAbstractInputPort("reaction_forces", AbstractValue.Make([SpatialForce()]))
        # the random inputs exist only where they are used (fewer systems per step)
        self._gauss = self.DeclareVectorInputPort("gaussian", 6) if any(self._noise) else None
        self._uniform = self.DeclareVectorInputPort("uniform", 3) if self._p_drop or self._p_spike else None
        self._ripple = self.DeclareVectorInputPort("ripple", 6) if tooth_ripple else None
        # (tooth_ripple: the milling force's table of instants, read here before ``ripple``, which computes)
        self._table = self.DeclareVectorInputPort("instant_table", 12 * MAX_INSTANTS) if tooth_ripple else None
        self._times = self.DeclareVectorInputPort("instant_times", MAX_INSTANTS) if tooth_ripple else None
        init = np.zeros(6) if initial_wrench is None else np.asarray(initial_wrench, dtype=float)
        self._state = self.DeclareDiscreteState(init)
        self._i_state = int(self._state)  # (a Python int: int() of a pybind index is a call into the bindings)
        self.DeclarePeriodicDiscreteUpdateEvent(self.period_s, 0.0, self._sample)
        self.DeclareStateOutputPort("wrench", self._state)
        # the plain sample (no ripple, dropouts or spikes; the reaction as it is) compiled where numba is
        # (model/sensor_sample.py: the same values bit for bit), written into the state in place
        self._lean = (self._ripple is None and self._uniform is None
                      and type(self).true_wrench is WristForceSensor.true_wrench)
        self._bias_a, self._noise_a = np.array(self._bias), np.array(self._noise)
        if self._lean:
            sensor_sample.warm_up()
            # (the kernel itself, without its wrapper's cost, and the inputs' Eval bound once: model/jit.Kernel.compiled)
            self._fast = (sensor_sample.wrist_sample.compiled(), self._reaction.Eval, self._joint,
                          None if self._gauss is None else self._gauss.Eval, self._i_state)

    def true_wrench(self, context):
        """The noise-free, bias-free wrench (sensor frame) at this instant, a list."""
        # the weld's reaction on the spindle, from the flange: (torque, force)
        t0, t1, t2, f0, f1, f2 = self._reaction.Eval(context)[self._joint].get_coeffs().tolist()
        w = [-f0, -f1, -f2, -t0, -t1, -t2]
        if self._ripple is not None:
            r = None
            if self._times.HasValue(context):
                r = MillingForceSource.ripple_from_table(context.get_time(), self._table.Eval(context).tolist(),
                                                         self._times.Eval(context).tolist())
            w = [a + b for a, b in zip(w, self._ripple.Eval(context).tolist() if r is None else r)]
        return w

    def _sample(self, context, discrete_state):
        if self._lean and jit.available():
            sample, reaction, joint, gauss, i_state = self._fast
            sample(reaction(context)[joint].get_coeffs(), sensor_sample.NO_NOISE if gauss is None else gauss(context),
                   self._bias_a, self._noise_a, discrete_state.get_mutable_value(i_state))
            return
        if self._gauss is not None:
            g = self._gauss.Eval(context).tolist()
            w = [a + b + n * s for a, b, n, s in zip(self.true_wrench(context), self._bias, self._noise, g)]
        else:
            w = [a + b for a, b in zip(self.true_wrench(context), self._bias)]
        if self._uniform is not None:
            u_drop, u_spike, u_axis = self._uniform.Eval(context).tolist()
            if u_drop < self._p_drop:
                w = [math.nan] * 6
            elif u_spike < self._p_spike:
                k = min(int(u_axis * 6.0), 5)  # axis (0-2) and sign from one uniform
                w[k % 3] += self._spike * (1.0 if k < 3 else -1.0)
        discrete_state.set_value(self._i_state, np.array(w))


def add_random_inputs(builder, sensor, name="wrist_sensor"):
    """RandomSources for the sensor's ``gaussian`` and ``uniform`` inputs,
    sampled at the sensor's rate; their state is set by the simulation
    context's random generator (``Diagram.SetRandomContext``)."""
    out = []
    for port, kind, size in (("gaussian", RandomDistribution.kGaussian, 6), ("uniform", RandomDistribution.kUniform, 3)):
        if sensor.HasInputPort(port):
            src = builder.AddNamedSystem(f"{name}_{port}", RandomSource(kind, size, sensor.period_s))
            builder.Connect(src.get_output_port(), sensor.GetInputPort(port))
            out.append(src)
    return out


# The guard re-arms on a finite sample after rejecting every sample for
# this long (s): a genuine step of the force is taken then, as the
# compensator process does after --sensor-timeout-ms (default 20 ms).
GUARD_REARM_S = 0.02


class WrenchGuard(LeafSystem):
    """Holds the last good sample: a non-finite sample, or one that jumps by
    more than ``max_jump_N`` (force) from the last good one, is replaced by
    it; after ``rearm_s`` of rejecting every sample the guard takes the
    next finite one (a genuine step of the force, not a spike).

    Input ``wrench`` (6), output ``wrench`` (6), updated at ``rate_hz``;
    output ``rejected`` (1): how many samples were rejected so far."""

    def __init__(self, *, rate_hz, max_jump_N, initial_wrench=None, rearm_s=GUARD_REARM_S):
        super().__init__()
        self._max_jump = float(max_jump_N)
        self._rearm = max(1, int(round(rearm_s * rate_hz)))
        self._in = self.DeclareVectorInputPort("wrench", 6)
        init = np.zeros(6) if initial_wrench is None else np.asarray(initial_wrench, dtype=float)
        self._state = self.DeclareDiscreteState(init)
        self._count = self.DeclareDiscreteState(1)
        self._run = self.DeclareDiscreteState(1)  # samples rejected in a row
        self.DeclarePeriodicDiscreteUpdateEvent(1.0 / rate_hz, 0.0, self._update)
        self.DeclareStateOutputPort("wrench", self._state)
        self.DeclareStateOutputPort("rejected", self._count)
        self._indices = (int(self._state), int(self._count), int(self._run))

    def _update(self, context, discrete_state):
        i_state, i_count, i_run = self._indices
        guard_step(self._in.Eval(context), discrete_state.get_mutable_value(i_state),
                   discrete_state.get_mutable_value(i_count), discrete_state.get_mutable_value(i_run),
                   self._max_jump, self._rearm)

    def hold(self, context, wrench):
        """Hold ``wrench`` (6) as the last good sample in this block's ``context``."""
        context.get_mutable_discrete_state(self._indices[0]).SetFromVector(wrench)


def guard_step(w, held, count, run, max_jump_N, rearm):
    """The guard's update (WrenchGuard's, and CompensatorTick's where it
    carries the guard): sample ``w`` (6, an array) into the state, whose
    current values arrive in the writeable arrays ``held`` (6, the last
    good sample), ``count`` (1, samples rejected so far) and ``run`` (1,
    rejected in a row), overwritten in place: the sample taken when it is
    good, counted when it is not."""
    if guard_accepts(w.tolist(), held[:3].tolist(), max_jump_N):  # (model/compensator.py)
        held[:] = w
        run[0] = 0.0
    else:
        count[0] += 1.0
        run[0] += 1.0
        if run[0] > rearm and np.all(np.isfinite(w)):  # re-armed on the new level
            held[:] = w
            run[0] = 0.0


class LagFreeCuttingSensor(WristForceSensor):
    """A wrist sensor that reads the cutting wrench without the payload's
    inertia: what the error budget's "force filter lag removed" gives the
    compensator (diagrams/budget.py), with no force filter after it.

    Each sample (at ``rate_hz``, as the real sensor) is the plant's true
    cutting wrench (input ``cutting_wrench``: force N, moment N*m about the
    tool point, base frame) moved to the sensor frame, plus the payload's
    static weight at the arm's pose (input ``tool_pose``: the flange
    rotation and the tool point, base frame, from the link angles; the
    payload of ``set_payload``), plus the real sensor's bias and noise.  So
    the measurement has the real sensor's sampling, bias and noise, and none
    of the payload's inertia (which the real sensor reads while the arm
    vibrates) and no filter lag."""

    def __init__(self, *, tool_m, payload, gravity_m_per_s2=(0.0, 0.0, -9.81), **kw):
        self._tool_m = tuple(float(v) for v in tool_m)
        super().__init__(**kw)
        self._cut = self.DeclareVectorInputPort("cutting_wrench", 6)
        self._pose = self.DeclareVectorInputPort("tool_pose", 12)
        self.set_payload(payload, gravity_m_per_s2)

    def set_payload(self, payload, gravity_m_per_s2=(0.0, 0.0, -9.81)):
        """The payload whose weight the samples carry: ``payload`` a
        PayloadCalibration (its mass and centre of mass; its bias is not
        used: the sensor's own is added), ``gravity_m_per_s2`` the plant's
        gravity (base frame)."""
        self._mass_kg = float(payload.mass_kg)
        self._com_m = [float(v) / 1000.0 for v in (payload.com_mm or (0.0, 0.0, 0.0))]
        self._g = [float(v) for v in gravity_m_per_s2]

    def true_wrench(self, context):
        pose = self._pose.Eval(context).tolist()
        R = pose[:9]
        w = to_sensor_frame(R, self._tool_m, self._cut.Eval(context).tolist())
        # the payload's weight in the sensor frame (= DH frame 6), about the sensor origin
        gx, gy, gz = rotate_transposed(R, self._g)
        fx, fy, fz = self._mass_kg * gx, self._mass_kg * gy, self._mass_kg * gz
        cx, cy, cz = self._com_m
        return [w[0] + fx, w[1] + fy, w[2] + fz, w[3] + cy * fz - cz * fy, w[4] + cz * fx - cx * fz,
                w[5] + cx * fy - cy * fx]
