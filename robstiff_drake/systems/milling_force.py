"""The milling force source: the cutting wrench on the tool from the actual
tool position against the workpiece (the process loop)."""

import numpy as np
from pydrake.systems.framework import LeafSystem

from robstiff_drake.model.kinematics import cross3


class MillingForceSource(LeafSystem):
    """Samples the robot's joint angles every ``period_s``, computes the
    cutting wrench (mechanistic model, tooth-resolved or revolution-averaged)
    at the actual tool point, and holds it until the next sample.

    Input  ``q`` (6): link angles, rad (controller convention).
    Output ``wrench`` (6): force N and moment N*m about the tool point, base
      frame, acting on the tool.
    Output ``generalized_force`` (6): the same load as joint torques J^T W
      (N*m).  The spindle is welded to the flange, so applying these to the
      plant is exactly applying the wrench to the spindle body.
    Output ``wrench_sensor`` (6): the same load as the wrist sensor sees it:
      (force, moment about the sensor origin) in the sensor frame (DH 6).
    """

    def __init__(self, *, force_model, workpiece, path, kinematics, tool_point_m, period_s, mode="averaged",
                 phase_rad=0.0):
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
        self._q = self.DeclareVectorInputPort("q", 6)
        self._state = self.DeclareDiscreteState(18)
        self.DeclarePeriodicDiscreteUpdateEvent(period_s, 0.0, self._update)
        ticket = {self.discrete_state_ticket(self._state)}
        self.DeclareVectorOutputPort("wrench", 6, lambda c, o: o.SetFromVector(self._held(c)[:6]),
                                     prerequisites_of_calc=ticket)
        self.DeclareVectorOutputPort("generalized_force", 6, lambda c, o: o.SetFromVector(self._held(c)[6:12]),
                                     prerequisites_of_calc=ticket)
        self.DeclareVectorOutputPort("wrench_sensor", 6, lambda c, o: o.SetFromVector(self._held(c)[12:]),
                                     prerequisites_of_calc=ticket)

    def _held(self, context):
        return context.get_discrete_state(self._state).value()

    def wrench_at(self, t, q):
        """(wrench at the tool point in the base frame, flange rotation) for
        joint angles q at time t."""
        R, p = self._kin.flange_rotation_and_tool_point(q)
        u = self._path.feed_direction(t)
        if self._mode == "tooth":
            return self._model.tooth_wrench(t, p, u, self._workpiece, self._phase), R
        return self._model.average_wrench(p, u, self._workpiece), R

    def _update(self, context, discrete_state):
        q = self._q.Eval(context)
        w, R = self.wrench_at(context.get_time(), q)
        tau = np.array(self._kin.jacobian_rows(q)) @ w  # rows of J^T
        f_s = R.T @ w[:3]
        m_s = R.T @ w[3:] + cross3(self._tool, f_s)  # moment about the sensor origin
        discrete_state.set_value(self._state, np.concatenate([w, tau, f_s, m_s]))
