"""The milling force source: the cutting wrench on the tool from the actual
tool position against the workpiece (the process loop)."""

import numpy as np
from pydrake.systems.framework import LeafSystem

from robstiff_drake.model.realtime import to_sensor_frame

__all__ = ["MillingForceSource", "to_sensor_frame"]


class MillingForceSource(LeafSystem):
    """Samples the robot's joint angles every ``period_s`` and computes the
    cutting load at the actual tool point.

    Input  ``q`` (6): link angles, rad (controller convention).
    Output ``generalized_force`` (6): joint torques J^T W of the load held
      over the period (N*m), for the plant.  The spindle is welded to the
      flange, so this is exactly the wrench applied to the spindle body.
      Tooth-resolved mode: W is the mean of the tooth-resolved wrench over the
      period, sampled ``samples_per_tooth`` times per tooth pass.
    Output ``wrench`` (6): the wrench on the tool (force N, moment N*m about
      the tool point, base frame) at the current time: in tooth-resolved mode
      the instantaneous tooth forces at the held tool position (what a
      fast sensor sees), in averaged mode the revolution average.
    Output ``wrench_sensor`` (6): ``wrench`` as the wrist sensor sees it,
      (force, moment about the sensor origin) in the sensor frame (DH 6).

    In averaged mode every output is held state (no computation between
    updates); in tooth-resolved mode ``wrench`` and ``wrench_sensor`` are
    computed from the time and the held tool pose.
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
        self._tool = tuple(float(v) for v in tool_point_m)
        self._mode = mode
        self._phase = phase_rad
        # tooth-resolved: the period's mean over samples_per_tooth samples per tooth pass
        n_sub = max(1, int(round(period_s * force_model.cutter.tooth_pass_hz * samples_per_tooth)))
        self._sub_t = np.arange(n_sub) * (period_s / n_sub)
        self._q = self.DeclareVectorInputPort("q", 6)
        # held: flange rotation (9) and tool point (3); joint torques; the
        # period's wrench (base frame, at the tool point) and as the sensor sees it
        self._pose = self.DeclareDiscreteState(12)
        self._tau = self.DeclareDiscreteState(6)
        self._w = self.DeclareDiscreteState(6)
        self._ws = self.DeclareDiscreteState(6)
        self.DeclarePeriodicDiscreteUpdateEvent(period_s, 0.0, self._update)
        self.DeclareStateOutputPort("generalized_force", self._tau)
        if mode == "averaged":
            self.DeclareStateOutputPort("wrench", self._w)
            self.DeclareStateOutputPort("wrench_sensor", self._ws)
        else:
            now = {self.discrete_state_ticket(self._pose), self.time_ticket()}
            self.DeclareVectorOutputPort("wrench", 6, lambda c, o: o.SetFromVector(self._tooth_wrench_now(c)),
                                         prerequisites_of_calc=now)
            self.DeclareVectorOutputPort("wrench_sensor", 6, self._calc_sensor, prerequisites_of_calc=now)

    def _tooth_wrench_now(self, context):
        p = context.get_discrete_state(self._pose).value()[9:]
        t = context.get_time()
        return self._model.tooth_wrench(t, p, self._path.feed_direction(t), self._workpiece, self._phase)

    def _calc_sensor(self, context, output):
        R = context.get_discrete_state(self._pose).value()[:9].tolist()
        output.SetFromVector(to_sensor_frame(R, self._tool, self._tooth_wrench_now(context).tolist()))

    def step_wrench(self, t, q):
        """(wrench over the period starting at t as a list, pose): the pose is
        the flange rotation (row-major 9) and the tool point (3), m."""
        pose = self._kin.pose(q)
        p = pose[9:]
        u = self._path.feed_direction(t)
        if self._mode == "tooth":
            w = self._model.tooth_wrench(t + self._sub_t, p, u, self._workpiece, self._phase) / len(self._sub_t)
        else:
            w = self._model.average_wrench(p, u, self._workpiece)
        return w.tolist(), pose

    def _update(self, context, discrete_state):
        q = self._q.Eval(context)
        w, pose = self.step_wrench(context.get_time(), q)
        # (numpy arrays: set_value converts them faster than lists)
        discrete_state.set_value(self._pose, np.array(pose))
        discrete_state.set_value(self._tau, np.array(self._kin.joint_torques(q, w)))
        discrete_state.set_value(self._w, np.array(w))
        discrete_state.set_value(self._ws, np.array(to_sensor_frame(pose[:9], self._tool, w)))
