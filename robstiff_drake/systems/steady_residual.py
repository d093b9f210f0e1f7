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
is not extrapolated) and turned as the model's force has turned since
(systems/steady_residual.turn: the rotation carrying the cut's wrench
then onto its wrench now, applied to the difference's force and torque
alike). Through an arc the model's force
turns with the feed (a 90 degree corner or arc: 90 degrees, all of it
held, steady_mask's window closing on a turning force): unturned, the
contour's law difference then pushed across the new feed direction.
ASSUMPTION: the law's difference is proportional to the force, as a
vector (the plant's Kienzle chip, wear and runout, model/plant_cutting.py,
are not exactly: a first order), and the cut's wrench turns as a rigid
whole (exact for a force at the tool point turning about the tool's axis,
a planar contour's)."""

import numpy as np
from robstiff_drake.systems.leaf_system import LeafSystem

# below this model force (N) a steady residual is the air's: the payload's weight and the sensor's bias
AIR_FORCE_N = 5.0  # model/program_correction.STEADY_FLOOR_N's size


def _smallest_turn(u, v):
    """(3, 3): the smallest rotation taking unit vector ``u`` onto unit
    vector ``v``; at opposite directions a half turn about an axis square
    to ``u``."""
    c = float(u @ v)
    if c < -1.0 + 1e-12:
        e = np.eye(3)[int(np.argmin(np.abs(u)))]
        k = np.cross(u, e)
        k /= np.linalg.norm(k)
        return 2.0 * np.outer(k, k) - np.eye(3)
    k = np.cross(u, v)
    K = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + K + K @ K / (1.0 + c)


def _wrench_frame(f, m):
    """(3, 3) columns: the force's direction, the direction of the torque's
    part square to it, their cross product; None where that torque is under
    a millimetre's lever (no direction to take)."""
    e1 = f / np.linalg.norm(f)
    m_perp = m - (m @ e1) * e1
    n = float(np.linalg.norm(m_perp))
    if n <= 1e-3 * float(np.linalg.norm(f)):
        return None
    e2 = m_perp / n
    return np.column_stack([e1, e2, np.cross(e1, e2)])


def turn(w_then, w_now):
    """(3, 3): the rotation taking the cut's wrench ``w_then`` (6: force N,
    torque N m, force non-zero) onto ``w_now``'s directions: the frame of the
    force and the torque's part square to it (a tool-point force's lever
    torque) carried from then to now, which for a force turning about the
    tool's axis (a planar contour) is that turn exactly, axial force and all;
    where either torque gives no direction, the smallest rotation of the
    force's direction."""
    f0, m0, f1, m1 = (np.asarray(v, dtype=float) for v in (w_then[:3], w_then[3:], w_now[:3], w_now[3:]))
    e_then, e_now = _wrench_frame(f0, m0), _wrench_frame(f1, m1)
    if e_then is None or e_now is None:
        return _smallest_turn(f0 / np.linalg.norm(f0), f1 / np.linalg.norm(f1))
    return e_now @ e_then.T


class SteadyResidual(LeafSystem):
    """Input ``wrench_measured`` (6, sensor frame, N and N m); output
    ``wrench_residual`` (6): measured less the model's wrench ``w`` (N, 6)
    at times ``t_s`` (linear between them) where ``steady`` (N, bool) holds
    at the current time; else the air's residual plus the last steady
    residual's difference to it, scaled by the model's force now over the
    model's force when it was passed (at most 1) and turned as the model's
    force has turned since (module docstring).  The state (updated at
    ``period_s``, the sensor's sample period): the last residual passed
    (6), the air's (6) and the model's wrench then (6, N and N m)."""

    def __init__(self, t_s, w, steady, *, period_s, air_force_N=AIR_FORCE_N):
        super().__init__()
        self._t = np.asarray(t_s, dtype=float)
        self._w = np.asarray(w, dtype=float)
        self._steady = np.asarray(steady, dtype=bool)
        self._air_N = float(air_force_N)
        self._in = self.DeclareVectorInputPort("wrench_measured", 6)
        self._held = self.DeclareDiscreteState(18)
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
        held, air, w_then = x[:6], x[6:12], x[12:18]
        n_then, n_now = float(np.linalg.norm(w_then[:3])), float(np.linalg.norm(w[:3]))
        if n_then <= self._air_N:  # held in the air: the air's residual as it was
            output.SetFromVector(held)
            return
        d = (held - air) * min(1.0, n_now / n_then)
        if n_now > 0.0:
            R = turn(w_then, w)
            d = np.r_[R @ d[:3], R @ d[3:]]
        output.SetFromVector(air + d)

    def _update(self, context, discrete_state):
        t = context.get_time()
        if not (self._passing(t) or t <= 0.0):
            return
        w = self._model(t)
        r = self._in.Eval(context) - w
        x = context.get_discrete_state(self._held).value().copy()
        x[:6], x[12:18] = r, w
        if float(np.linalg.norm(w[:3])) <= self._air_N or t <= 0.0:
            x[6:12] = r
        discrete_state.get_mutable_vector(self._held).SetFromVector(x)
