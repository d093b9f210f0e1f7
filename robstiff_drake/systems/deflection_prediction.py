"""Deflection prediction: dq = C_q J(q)^T W, from the gravity-free wrench
(moved from the sensor frame to the tool point in the base frame), the
Jacobian at the measured joint angles and the compensator's stiffness model
(which may differ from the plant's)."""

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import LeafSystem, ValueProducer

from robstiff_drake.model.kinematics import cross3, rpy_to_rotation
from robstiff_drake.systems.joint_effects import effect_dq


def sensor_to_tool_base(w_sensor, R_flange, tool_m, R_mount=None):
    """A wrench measured in the sensor frame (about its origin, which is the
    flange origin) as a wrench (force N, moment N*m about the tool point) in
    the base frame.  ``tool_m`` is the tool point in the flange frame."""
    R_mount = np.eye(3) if R_mount is None else R_mount
    Rs = R_flange @ R_mount
    f_s, m_s = w_sensor[:3], w_sensor[3:]
    r_s = R_mount.T @ tool_m  # tool point in the sensor frame
    return np.concatenate([Rs @ f_s, Rs @ (m_s - cross3(r_s, f_s))])


class DeflectionPrediction(LeafSystem):
    """Inputs ``process_wrench`` (6, sensor frame) and ``q`` (6, rad).
    Outputs ``dq`` (6, rad): the predicted joint deflection, and
    ``tool_wrench`` (6): the wrench at the tool point, base frame.
    Both are recomputed only when an input changes."""

    def __init__(self, *, predictor, tool_m, mount_rpy_deg=(0.0, 0.0, 0.0), lost_motion_rad=None,
                 coupling_c23_rad_per_Nm=0.0):
        super().__init__()
        self._pred = predictor
        # the model's joint effects beyond the springs (see systems/joint_effects.py)
        self._lost = None if not lost_motion_rad else np.asarray(lost_motion_rad, dtype=float)
        self._c23 = float(coupling_c23_rad_per_Nm)
        self._tool = np.asarray(tool_m, dtype=float)
        self._R_mount = rpy_to_rotation(np.deg2rad(mount_rpy_deg))
        self._w = self.DeclareVectorInputPort("process_wrench", 6)
        self._q = self.DeclareVectorInputPort("q", 6)
        deps = {self._w.ticket(), self._q.ticket()}
        # one computation serves both outputs
        self._both = self.DeclareCacheEntry(
            "tool_wrench_and_dq", ValueProducer(allocate=lambda: AbstractValue.Make(np.zeros(12)),
                                                calc=self._calc_both), prerequisites_of_calc=deps)
        self.DeclareVectorOutputPort("dq", 6, lambda c, o: o.SetFromVector(self._get(c)[6:]),
                                     prerequisites_of_calc={self._both.ticket()})
        self.DeclareVectorOutputPort("tool_wrench", 6, lambda c, o: o.SetFromVector(self._get(c)[:6]),
                                     prerequisites_of_calc={self._both.ticket()})

    def _get(self, context):
        return self._both.Eval(context)

    def _calc_both(self, context, value):
        q = self._q.Eval(context)
        R, _ = self._pred.flange_rotation_and_tool_point(q)
        w = sensor_to_tool_base(self._w.Eval(context), R, self._tool, self._R_mount)
        dq, _ = self._pred(q, w)
        if self._lost is not None or self._c23:
            tau = dq / self._pred.joint_compliance
            dq = dq + effect_dq(tau, self._lost if self._lost is not None else np.zeros(6), self._c23)
        value.set_value(np.concatenate([w, dq]))
