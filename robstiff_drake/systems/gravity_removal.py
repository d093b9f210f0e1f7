"""Gravity removal: subtracts the payload's weight (and the sensor's bias)
from the filtered wrench, for any robot configuration, with the parameters
that `robstiff calibrate-payload` identifies.  The arithmetic is
model/compensator.GravityRemover's (shared with the compensator process).

The compensator diagram runs this inside its one block per tick
(systems/compensator_tick.py); this block alone is the reference that one
is tested against, bit for bit (tests/test_compensator_tick.py)."""

import numpy as np
from robstiff_drake.systems.leaf_system import LeafSystem

from robstiff_drake.model.compensator import GravityRemover


class GravityRemoval(LeafSystem):
    """Inputs ``wrench`` (6, sensor frame) and ``q`` (6, rad); output
    ``process_wrench`` (6): the wrench minus the payload's weight and bias
    (model/compensator.GravityRemover, scalar arithmetic for the per-cycle
    path).  Direct feedthrough, recomputed only when an input changes."""

    def __init__(self, *, calibration, kinematics):
        super().__init__()
        self._remove = GravityRemover(calibration, kinematics)
        self._w = self.DeclareVectorInputPort("wrench", 6)
        self._q = self.DeclareVectorInputPort("q", 6)
        self.DeclareVectorOutputPort(
            "process_wrench", 6, self._calc,
            prerequisites_of_calc={self._w.ticket(), self._q.ticket()})

    def _calc(self, context, output):
        output.SetFromVector(np.array(self._remove(self._w.Eval(context).tolist(), self._q.Eval(context))))
