"""Deflection prediction: dq = C_q J(q)^T W, from the gravity-free wrench
(moved from the sensor frame to the tool point in the base frame), the
Jacobian at the measured joint angles and the compensator's stiffness model
(which may differ from the plant's).  With lost motion or coupling in the
model, the transmission law of model/transmission.py: the extra twist of
the gears when the process torque adds to the static (gravity) torque they
already carry."""

import numpy as np
from pydrake.systems.framework import LeafSystem

from robstiff_drake.model.compensator import DeflectionModel


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
                 coupling_c23_rad_per_Nm=0.0, take_up_Nm=None):
        """``predictor``: the compensator's DeflectionPredictor; ``tool_m``:
        the tool point in the flange frame (m); ``mount_rpy_deg``: the sensor
        frame's rotation on the flange (deg)."""
        super().__init__()
        # the arithmetic: model/compensator.DeflectionModel (shared with the compensator process)
        self._model = DeflectionModel(predictor, tool_m, mount_rpy_deg, lost_motion_rad, coupling_c23_rad_per_Nm,
                                      take_up_Nm)
        self._lost = self._model.lost
        self._w = self.DeclareVectorInputPort("process_wrench", 6)
        self._q = self.DeclareVectorInputPort("q", 6)
        deps = {self._w.ticket(), self._q.ticket()}
        self._static = None
        if self._lost is not None:
            self._static = self.DeclareVectorInputPort("static_torque", 6)
            deps.add(self._static.ticket())
        self.DeclareVectorOutputPort("dq", 6, self._calc_dq, prerequisites_of_calc=deps)
        self.DeclareVectorOutputPort("tool_wrench", 6, lambda c, o: o.SetFromVector(self._tool_wrench(c)[0]),
                                     prerequisites_of_calc=deps)

    @property
    def model(self):
        """Its arithmetic (model/compensator.DeflectionModel)."""
        return self._model

    def _tool_wrench(self, context):
        """(the wrench at the tool point, base frame, as a list; q)."""
        q = self._q.Eval(context)
        return self.tool_wrench_of(self._w.Eval(context), q), q

    def tool_wrench_of(self, process_wrench, q):
        """The wrench at the tool point (base frame, list of 6) for a process
        wrench in the sensor frame at joint angles q (rad)
        (model/compensator.DeflectionModel)."""
        return self._model.tool_wrench(process_wrench, q)

    def _calc_dq(self, context, output):
        static = self._static.Eval(context) if self._static is not None else None
        output.SetFromVector(np.asarray(self._model.dq(self._w.Eval(context), self._q.Eval(context), static)))
