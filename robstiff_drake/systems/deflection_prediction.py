"""Deflection prediction: dq = C_q J(q)^T W, from the gravity-free wrench
(moved from the sensor frame to the tool point in the base frame), the
Jacobian at the measured joint angles and the compensator's stiffness model
(which may differ from the plant's).  With lost motion or coupling in the
model, the transmission law of model/transmission.py: the extra twist of
the gears when the process torque adds to the static (gravity) torque they
already carry."""

import numpy as np
from pydrake.systems.framework import LeafSystem

from robstiff_drake.model.kinematics import rpy_to_rotation
from robstiff_drake.model.wrench_frames import wrench_to_tool_base
from robstiff_drake.model import transmission


class DeflectionPrediction(LeafSystem):
    """Inputs ``process_wrench`` (6, sensor frame) and ``q`` (6, rad).
    Outputs ``dq`` (6, rad): the predicted joint deflection, and
    ``tool_wrench`` (6): the wrench at the tool point, base frame.
    With lost motion in the model, input ``static_torque`` (6, N*m): the
    torque the gears carry before the cut (gravity), from the controller's
    model; the lost motion acts only where the total torque changes sign.
    Each is recomputed only when an input changes (the tool wrench is
    computed by both: two cheap transforms cost less than a shared cache
    entry's extra call into Python)."""

    def __init__(self, *, predictor, tool_m, mount_rpy_deg=(0.0, 0.0, 0.0), lost_motion_rad=None,
                 coupling_c23_rad_per_Nm=0.0):
        """``predictor``: the compensator's DeflectionPredictor; ``tool_m``:
        the tool point in the flange frame (m); ``mount_rpy_deg``: the sensor
        frame's rotation on the flange (deg)."""
        super().__init__()
        self._pred = predictor
        # the model's transmission beyond the springs (model/transmission.py)
        self._lost = None if not lost_motion_rad or not any(lost_motion_rad) else np.asarray(lost_motion_rad,
                                                                                               dtype=float)
        self._c23 = float(coupling_c23_rad_per_Nm)
        R_mount = rpy_to_rotation(np.deg2rad(mount_rpy_deg))
        self._R_mount = tuple(R_mount.ravel().tolist())
        self._r_s = tuple((R_mount.T @ np.asarray(tool_m, dtype=float)).tolist())  # tool point, sensor frame
        self._w = self.DeclareVectorInputPort("process_wrench", 6)
        self._q = self.DeclareVectorInputPort("q", 6)
        self._identity_mount = bool(np.allclose(R_mount, np.eye(3), rtol=0.0, atol=0.0))
        deps = {self._w.ticket(), self._q.ticket()}
        self._static = None
        if self._lost is not None:
            self._static = self.DeclareVectorInputPort("static_torque", 6)
            deps.add(self._static.ticket())
        self.DeclareVectorOutputPort("dq", 6, self._calc_dq, prerequisites_of_calc=deps)
        self.DeclareVectorOutputPort("tool_wrench", 6, lambda c, o: o.SetFromVector(self._tool_wrench(c)[0]),
                                     prerequisites_of_calc=deps)

    def _tool_wrench(self, context):
        """(the wrench at the tool point, base frame, as a list; q)."""
        q = self._q.Eval(context)
        return self.tool_wrench_of(self._w.Eval(context), q), q

    def tool_wrench_of(self, process_wrench, q):
        """The wrench at the tool point (base frame, list of 6) for a process
        wrench in the sensor frame at joint angles q (rad): what
        sensor_to_tool_base computes, in scalar arithmetic (the per-cycle
        path)."""
        R = self._pred.pose(q)
        if not self._identity_mount:
            M = self._R_mount
            R = [R[3 * i] * M[j] + R[3 * i + 1] * M[3 + j] + R[3 * i + 2] * M[6 + j] for i in range(3) for j in range(3)]
        w = process_wrench.tolist() if hasattr(process_wrench, "tolist") else process_wrench
        return wrench_to_tool_base(R, self._r_s, w)

    def _calc_dq(self, context, output):
        w, q = self._tool_wrench(context)
        tau = self._pred.joint_torques(q, w)
        if self._lost is None and not self._c23:
            output.SetFromVector([c * t for c, t in zip(self._pred.joint_compliance_list, tau)])
            return
        static = self._static.Eval(context) if self._static is not None else np.zeros(6)
        output.SetFromVector(transmission.static_deflection(static, tau, self._pred.joint_compliance, self._lost,
                                                            self._c23))
