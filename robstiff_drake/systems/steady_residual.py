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
steady_mask) this block holds a residual (below), and passes measured
less model again once the model's force has been steady for the mask's
window.

What it holds is not the last residual as it was: the law's difference the
residual carries is a force the cut makes, so it goes with the cut's
force. Held as it was, it kept the steady contour's law difference (18 N,
with the start of the force's fall 31 N) through face_contour_fanuc's R20
arc, lead-out and exit, where the model's force fell to 15-37 N and then
none, for 4 s until the air was steady again: the plain compensator put
the tool about 0.09 mm lower there and cut the floor under the lead-out
+0.074 and +0.092 mm (mean) deep (the corrected program alone: -0.019 and
+0.000 mm there; studies/plain_on_top_residual.py). So the held residual
is the air's (the payload's weight and the sensor's bias, the last
residual passed where the model's force was below ``air_force_N``) plus
the last steady cut's difference to it scaled by the model's force now
over the model's force then (at most 1: a heavier cut than the one heard
is not extrapolated). ASSUMPTION: the law's difference is proportional to
the force (the plant's Kienzle chip, wear and runout,
model/plant_cutting.py, are not exactly: a first order)."""

import numpy as np
from robstiff_drake.systems.leaf_system import LeafSystem

# below this model force (N) a steady residual is the air's: the payload's weight and the sensor's bias
AIR_FORCE_N = 5.0  # model/program_correction.STEADY_FLOOR_N's size


class SteadyResidual(LeafSystem):
    """Input ``wrench_measured`` (6, sensor frame, N and N m); output
    ``wrench_residual`` (6): measured less the model's wrench ``w`` (N, 6)
    at times ``t_s`` (linear between them) where ``steady`` (N, bool) holds
    at the current time; else the air's residual plus the last steady
    residual's difference to it, scaled by the model's force now over the
    model's force when it was passed (at most 1; module docstring).  The
    state (updated at ``period_s``, the sensor's sample period): the last
    residual passed (6), the air's (6) and the model's force then (N)."""

    def __init__(self, t_s, w, steady, *, period_s, air_force_N=AIR_FORCE_N):
        super().__init__()
        self._t = np.asarray(t_s, dtype=float)
        self._w = np.asarray(w, dtype=float)
        self._steady = np.asarray(steady, dtype=bool)
        self._air_N = float(air_force_N)
        self._in = self.DeclareVectorInputPort("wrench_measured", 6)
        self._held = self.DeclareDiscreteState(13)
        self.DeclareVectorOutputPort("wrench_residual", 6, self._calc,
                                     prerequisites_of_calc={self._in.ticket(), self.xd_ticket(), self.time_ticket()})
        self.DeclarePeriodicDiscreteUpdateEvent(period_s, 0.0, self._update)

    def _passing(self, t):
        i = int(np.searchsorted(self._t, t, side="right")) - 1
        return bool(self._steady[min(max(i, 0), len(self._steady) - 1)])

    def _model(self, t):
        return np.array([np.interp(t, self._t, self._w[:, j]) for j in range(6)])

    def _calc(self, context, output):
        t = context.get_time()
        w = self._model(t)
        if self._passing(t) or t <= 0.0:
            output.SetFromVector(self._in.Eval(context) - w)
            return
        x = context.get_discrete_state(self._held).value()
        held, air, force_then = x[:6], x[6:12], x[12]
        scale = min(1.0, float(np.linalg.norm(w[:3])) / force_then) if force_then > self._air_N else 1.0
        output.SetFromVector(air + scale * (held - air))

    def _update(self, context, discrete_state):
        t = context.get_time()
        if not (self._passing(t) or t <= 0.0):
            return
        w = self._model(t)
        r = self._in.Eval(context) - w
        x = context.get_discrete_state(self._held).value().copy()
        force = float(np.linalg.norm(w[:3]))
        x[:6], x[12] = r, force
        if force <= self._air_N or t <= 0.0:
            x[6:12] = r
        discrete_state.get_mutable_vector(self._held).SetFromVector(x)
