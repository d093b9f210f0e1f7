"""Predictive compensation (beyond the paper): the compensator knows the
planned path, the workpiece and a cutting-force model, so it corrects for the
load it *will* meet when the correction takes effect, and uses the measured
wrench only to correct the model's error (a Smith-predictor structure):

    W_used = W_model(t + lead) + [W_measured - filter(W_model)]

``lead`` is when the correction computed now acts on the arm (the delay to
the correction plus half a period of hold).  ``filter(W_model)`` is the
model's wrench passed through an exact replica of the measurement chain (the
same discrete filter at the sensor rate, fed two sensor samples late as the
sensor and guard deliver it), so that the bracket is only the model's error:
zero for an exact model even while the force changes, and the delayed error
otherwise.

The model's wrench is a function of the path time alone; a tick needs it
at three times (the replica's next sample, the replica's output and the
lead), and the replica's sample at a tick is the output's time of the tick
before, so the last few are kept (keyed by the time, a float: a time
computed another way is computed again).  The linear model's average runs
compiled when numba is installed (model/cutting_kernels.py's
``linear_average_wrench``: MillingForceModel.average_wrench's operations in
its order)."""

import numpy as np
from robstiff_drake.systems.leaf_system import LeafSystem
from scipy import signal

from robstiff_drake.model import jit
from robstiff_drake.model.cutting_kernels import linear_average_wrench
from robstiff_drake.model.milling import MillingForceModel
from robstiff_drake.model.wrench_frames import to_sensor_frame

_KEPT = 8  # model wrenches kept (a tick asks for three, one of them the tick before's)


class PredictiveWrench(LeafSystem):
    """Inputs ``process_wrench`` (6, sensor frame, measured, filtered and
    gravity-free, sampled at the last controller tick) and ``q`` (6, rad).
    Output ``process_wrench`` (6, sensor frame): the wrench to compensate for.
    Discrete state: the replica filter (advanced every ``period_s`` through
    the sensor samples of the period) and the tick time."""

    def __init__(self, *, force_model, workpiece, path, kinematics, tool_m, lead_s, filter_ba, rate_hz, period_s):
        super().__init__()
        self._model = force_model
        self._wp = workpiece
        self._path = path
        self._kin = kinematics
        self._tool = tuple(float(v) for v in tool_m)
        self._lead = float(lead_s)
        self._h = 1.0 / rate_hz
        self._n_sub = max(1, int(round(period_s * rate_hz)))
        A, B, C, D = signal.tf2ss(*filter_ba)
        self._A, self._B, self._C, self._D = A, B[:, 0], C[0], float(np.squeeze(D))
        self._nf = A.shape[0]
        self._kept = {}  # {(t s, compiled): model wrench}
        self._linear = None  # (boxes (B, 5) m, radius m, basis (6, 5)) for the compiled linear model
        if type(force_model) is MillingForceModel:
            self._linear = (np.array(workpiece.boxes, dtype=float).reshape(-1, 5),
                            float(force_model.cutter.radius_m), np.array(force_model._basis, dtype=float))
        self._w = self.DeclareVectorInputPort("process_wrench", 6)
        self._q = self.DeclareVectorInputPort("q", 6)
        # replica filter states (nf x 6, column per channel) and the time of the last tick
        self._state = self.DeclareDiscreteState(self._nf * 6 + 1)
        self.DeclarePeriodicDiscreteUpdateEvent(period_s, 0.0, self._advance)
        self.DeclareVectorOutputPort(
            "process_wrench", 6, self._calc,
            prerequisites_of_calc={self._w.ticket(), self._q.ticket(), self.discrete_state_ticket(self._state)})

    def model_wrench_base(self, t):
        """The model's wrench (tool point, base frame) on the planned path at t."""
        compiled = self._linear is not None and jit.available()
        kept = self._kept
        w = kept.get((t, compiled))
        if w is None:
            w = self.model_wrench_reference(t) if not compiled else self._model_wrench_compiled(t)
            if len(kept) >= _KEPT:
                del kept[next(iter(kept))]  # (the oldest)
            kept[(t, compiled)] = w
        return w

    def model_wrench_reference(self, t):
        """``model_wrench_base`` in plain Python (the force model's own average)."""
        return self._model.average_wrench(self._path.position(t), self._path.feed_direction(t), self._wp)

    def _model_wrench_compiled(self, t):
        p, u = self._path.position(t), self._path.feed_direction(t)
        boxes, radius_m, basis = self._linear
        return linear_average_wrench(float(p[0]), float(p[1]), float(p[2]), float(u[0]), float(u[1]), boxes,
                                     radius_m, basis)

    def _to_sensor(self, w, R):
        """A wrench at the tool point (base frame) as the sensor sees it, for
        the flange rotation R (row-major 9 floats)."""
        return np.array(to_sensor_frame(R, self._tool, w.tolist()))

    def _split(self, context):
        x = context.get_discrete_state(self._state).value()
        return x[:-1].reshape(self._nf, 6), x[-1]

    def _advance(self, context, discrete_state):
        """Run the replica through the sensor samples up to this tick."""
        X, _ = self._split(context)
        t = context.get_time()
        for j in range(self._n_sub, 0, -1):
            u = self.model_wrench_base(t - j * self._h - 2 * self._h)
            X = self._A @ X + np.outer(self._B, u)
        discrete_state.set_value(self._state, np.concatenate([X.ravel(), [t]]))

    def _calc(self, context, output):
        X, t = self._split(context)
        replica = self._C @ X + self._D * self.model_wrench_base(t - 2 * self._h)
        R = self._kin.pose(self._q.Eval(context))[:9]
        ahead = self._to_sensor(self.model_wrench_base(t + self._lead), R)
        output.SetFromVector(ahead + self._w.Eval(context) - self._to_sensor(replica, R))
