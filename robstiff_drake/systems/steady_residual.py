"""The measured wrench less the model's, heard only where the model's force
is steady: the online compensator's input on top of a program corrected
offline for that model (diagrams/offline_compensation.py).

Where the model's force is changing (a cut's entry and exit, a corner)
the measured force need not follow it in time: the plant's chip takes its
direction and feed from the tool's real motion, so at face_and_contour's
entry the measured force rises ~0.35 s after the model's and first points
~90 degrees off it.  The difference there is the engagement's timing, not
a force the program does not already hold; heard, it drove the plain
compensator to 0.3 mrad and the 75 mm cutter 0.3 mm into the face.  So
while the model's force is not steady (model/program_correction.
steady_mask) this block holds the last residual it passed (the air's or
the steady cut's), and passes measured less model again once the model's
force has been steady for the mask's window."""

import numpy as np
from pydrake.systems.framework import BasicVector

from robstiff_drake.systems.leaf_system import LeafSystem


class SteadyResidual(LeafSystem):
    """Input ``wrench_measured`` (6, sensor frame, N and N m); output
    ``wrench_residual`` (6): measured less the model's wrench ``w`` (N, 6)
    at times ``t_s`` (linear between them) where ``steady`` (N, bool) holds
    at the current time, else the last output passed (held at
    ``period_s``, the sensor's sample period)."""

    def __init__(self, t_s, w, steady, *, period_s):
        super().__init__()
        self._t = np.asarray(t_s, dtype=float)
        self._w = np.asarray(w, dtype=float)
        self._steady = np.asarray(steady, dtype=bool)
        self._in = self.DeclareVectorInputPort("wrench_measured", 6)
        self._held = self.DeclareDiscreteState(6)
        self.DeclareVectorOutputPort("wrench_residual", 6, self._calc,
                                     prerequisites_of_calc={self._in.ticket(), self.xd_ticket(), self.time_ticket()})
        self.DeclarePeriodicDiscreteUpdateEvent(period_s, 0.0, self._update)
        self._first = True

    def _passing(self, t):
        i = int(np.searchsorted(self._t, t, side="right")) - 1
        return bool(self._steady[min(max(i, 0), len(self._steady) - 1)])

    def _residual(self, context):
        m = self._in.Eval(context)
        t = context.get_time()
        w = np.array([np.interp(t, self._t, self._w[:, j]) for j in range(6)])
        return m - w

    def _calc(self, context, output):
        if self._passing(context.get_time()) or context.get_time() <= 0.0:
            output.SetFromVector(self._residual(context))
        else:
            output.SetFromVector(context.get_discrete_state(self._held).value())

    def _update(self, context, discrete_state):
        if self._passing(context.get_time()) or context.get_time() <= 0.0:
            discrete_state.get_mutable_vector(self._held).SetFromVector(self._residual(context))
