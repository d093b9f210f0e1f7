"""The milling force source: the cutting wrench on the tool from the actual
tool position against the workpiece (the process loop)."""

import numpy as np
from pydrake.systems.framework import LeafSystem

from robstiff_drake.model.kinematics import cross3


class MillingForceSource(LeafSystem):
    """Samples the robot's joint angles every ``period_s`` (the plant step)
    and computes the cutting load at the actual tool point.

    Input  ``q`` (6): link angles, rad (controller convention).
    Output ``generalized_force`` (6): joint torques J^T W of the load held
      over the step (N*m), for the plant.  The spindle is welded to the
      flange, so this is exactly the wrench applied to the spindle body.
      Tooth-resolved mode: W is the mean of the tooth-resolved wrench over the
      step, sampled ``samples_per_tooth`` times per tooth pass.
    Output ``wrench`` (6): the wrench on the tool (force N, moment N*m about
      the tool point, base frame) at the current time: in tooth-resolved mode
      the instantaneous tooth forces at the held tool position (what a
      fast sensor sees), in averaged mode the revolution average.
    Output ``wrench_sensor`` (6): ``wrench`` as the wrist sensor sees it,
      (force, moment about the sensor origin) in the sensor frame (DH 6).
    """

    def __init__(self, *, force_model, workpiece, path, kinematics, tool_point_m, period_s, mode="averaged",
                 samples_per_tooth=20, phase_rad=0.0):
        super().__init__()
        if mode not in ("averaged", "tooth"):
            raise ValueError(f"mode must be 'averaged' or 'tooth', got {mode!r}")
        self._model = force_model
        self._workpiece = workpiece
        self._path = path
        self._kin = kinematics
        self._tool = np.asarray(tool_point_m, dtype=float)
        self._mode = mode
        self._phase = phase_rad
        # tooth-resolved: the step's mean over samples_per_tooth samples per tooth pass
        n_sub = max(1, int(round(period_s * force_model.cutter.tooth_pass_hz * samples_per_tooth)))
        self._sub_t = np.arange(n_sub) * (period_s / n_sub)
        self._q = self.DeclareVectorInputPort("q", 6)
        # held: tool point (3), flange rotation (9), joint torques (6), step wrench (6)
        self._state = self.DeclareDiscreteState(24)
        self.DeclarePeriodicDiscreteUpdateEvent(period_s, 0.0, self._update)
        held = {self.discrete_state_ticket(self._state)}
        now = held | ({self.time_ticket()} if mode == "tooth" else set())
        self.DeclareVectorOutputPort("generalized_force", 6, lambda c, o: o.SetFromVector(self._held(c)[12:18]),
                                     prerequisites_of_calc=held)
        self.DeclareVectorOutputPort("wrench", 6, lambda c, o: o.SetFromVector(self._wrench_now(c)),
                                     prerequisites_of_calc=now)
        self.DeclareVectorOutputPort("wrench_sensor", 6, self._calc_sensor, prerequisites_of_calc=now)

    def _held(self, context):
        return context.get_discrete_state(self._state).value()

    def _wrench_now(self, context):
        x = self._held(context)
        if self._mode == "averaged":
            return x[18:24]
        t = context.get_time()
        return self._model.tooth_wrench(t, x[:3], self._path.feed_direction(t), self._workpiece, self._phase)

    def _calc_sensor(self, context, output):
        w = self._wrench_now(context)
        R = self._held(context)[3:12].reshape(3, 3)
        f_s = R.T @ w[:3]
        output.SetFromVector(np.concatenate([f_s, R.T @ w[3:] + cross3(self._tool, f_s)]))

    def step_wrench(self, t, q):
        """(wrench over the step starting at t, flange rotation, tool point)."""
        R, p = self._kin.flange_rotation_and_tool_point(q)
        u = self._path.feed_direction(t)
        if self._mode == "tooth":
            w = self._model.tooth_wrench(t + self._sub_t, p, u, self._workpiece, self._phase) / len(self._sub_t)
        else:
            w = self._model.average_wrench(p, u, self._workpiece)
        return w, R, p

    def _update(self, context, discrete_state):
        q = self._q.Eval(context)
        w, R, p = self.step_wrench(context.get_time(), q)
        tau = np.array(self._kin.jacobian_rows(q)) @ w  # rows of J^T
        discrete_state.set_value(self._state, np.concatenate([p, R.ravel(), tau, w]))
