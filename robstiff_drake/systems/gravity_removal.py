"""Gravity removal: subtracts the payload's weight (and the sensor's bias)
from the filtered wrench, for any robot configuration, with the parameters
that `robstiff calibrate-payload` identifies."""

import numpy as np
from pydrake.systems.framework import LeafSystem

from robstiff_drake.model.payload import payload_weight


class GravityRemoval(LeafSystem):
    """Inputs ``wrench`` (6, sensor frame) and ``q`` (6, rad); output
    ``process_wrench`` (6): the wrench minus the payload's weight and bias
    (``payload_wrench``, here in scalar arithmetic for the per-cycle path).
    Direct feedthrough, recomputed only when an input changes."""

    def __init__(self, *, calibration, kinematics):
        super().__init__()
        m, c, bf, bt, R_mount = calibration.arrays()
        self._m = m
        self._c = tuple(c.tolist())
        self._bias = np.concatenate([bf, bt])
        self._R_mount = tuple(R_mount.ravel().tolist())
        self._kin = kinematics
        self._w = self.DeclareVectorInputPort("wrench", 6)
        self._q = self.DeclareVectorInputPort("q", 6)
        self.DeclareVectorOutputPort(
            "process_wrench", 6, self._calc,
            prerequisites_of_calc={self._w.ticket(), self._q.ticket()})

    def _calc(self, context, output):
        R = self._kin.pose(self._q.Eval(context))  # rotation in the first nine
        weight = payload_weight(R, self._R_mount, self._m, self._c)
        output.SetFromVector(self._w.Eval(context) - self._bias - weight)
