"""The regenerative chip (issue 29): each tooth cuts what the tool's own
motion leaves, not a chip along the program.  Plain numpy; no Drake.

Tooth j at angle phi_j(t) = phase - Omega t + 2 pi j / N (rad, from the
base x axis, clockwise seen from above: the plant law's sense) has the
radial unit vector r_j = (cos phi_j, sin phi_j) in the horizontal plane
(the spindle vertical, as the plant's law takes it).  Its chip (m) is

    h_j(t) = min over k = 1..M of (p(t) - p(t - k tau)) . r_j + R_j - R_(j-k)

p the tool centre's ACTUAL position (x, y), tau = 60 / (rpm N) one tooth
period, R_j tooth j's radius with runout: the surface the tooth k back
left is where the tool centre was k tooth periods ago, at that tooth's
radius (the standard regenerative chip, Altintas, "Manufacturing
Automation", 2nd ed., ch. 3-4: the dynamic chip is the displacement
between the present and the previous tooth's pass, along the tooth's
normal; with runout, and after teeth that left the cut, the deepest of
the earlier passes' surfaces: Kline and DeVor's runout chip, which the
plant's law also uses, and the time-domain chatter simulations' stored
surface).  Memory: M = MEMORY_REVOLUTIONS revolutions of tooth passes
(ASSUMPTION, docs/assumptions.md): the surface a tool's vibration or a
retreat left is remembered until the feed has carried the cutter past it
(8 revolutions: 2.7 mm at the block's 20 mm/s, against a chatter
amplitude of tenths of a millimetre; on the paper's chattering block 16
revolutions change the surface by at most 8 um, 4 by up to 0.07 mm:
studies/regenerative_chatter.py --memory-revolutions); an older one is
taken as cut away since.  The geometry is the linearised one (the displacement along the
tooth's radius, the tool's motion small against its radius).

A tooth cuts where the workpiece is under its tip (the law's box depth)
AND its chip is positive: a tooth whose chip is <= 0 has left the cut (no
cutting force, no edge force).  That replaces the plant law's "the
leading half of the program's direction cuts": in straight steady
cutting at feed per tooth c_f along u, p(t) - p(t - k tau) = k c_f u and
h_j is the law's ``chips_m`` (c_f cos theta_j, theta from u), positive
only on the leading half, so the wrench is the law's tooth-resolved one
(tests/test_regenerative_chip.py).  The forces per tooth are the law's
own (``PlantCuttingLaw.chip_forces`` and ``_wrench_uvz``: Kienzle
exponent, edge forces and their ramp, flank wear).
"""

import math

import numpy as np

from robstiff_drake.model.milling import tip_depths


MEMORY_REVOLUTIONS = 8


class RegenerativeChip:
    """The tooth-resolved wrench of a PlantCuttingLaw ``law`` with the
    regenerative chip.  ``phase_rad``: tooth 0's angle from base x at t = 0."""

    def __init__(self, law, phase_rad=0.0):
        if not hasattr(law, "chip_forces"):
            raise TypeError("the regenerative chip needs the plant's cutting law (model/plant_cutting.PlantCuttingLaw)")
        self.law = law
        self.cutter = law.cutter
        self.phase_rad = float(phase_rad)
        n = self.cutter.n_teeth
        self.n_teeth = n
        self.tooth_period_s = 1.0 / self.cutter.tooth_pass_hz
        m = n * MEMORY_REVOLUTIONS
        self.memory_s = m * self.tooth_period_s
        self._k = np.arange(1, m + 1, dtype=float)
        # R_j - R_(j-k) for k = 1..M: the law's (k = 1..N) repeated each revolution
        self._dR = law._dR[:, (np.arange(m) % n)]
        self._angles = 2 * np.pi * np.arange(n) / n

    def angles_rad(self, t_s):
        """(T, N): the teeth's angles (from base x) at the times ``t_s``."""
        t = np.atleast_1d(np.asarray(t_s, dtype=float))
        return (self.phase_rad - self.cutter.spindle_rad_per_s * t)[:, None] + self._angles

    def past_times_s(self, t_s):
        """(T, M): t - k tau for k = 1..M, the instants whose tool centres
        left the surfaces the teeth cut at the times ``t_s``."""
        t = np.atleast_1d(np.asarray(t_s, dtype=float))
        return t[:, None] - self._k[None, :] * self.tooth_period_s

    def chips_m(self, theta_rad, now_xy_m, past_xy_m):
        """(T, N) chips (m): ``theta_rad`` (T, N) the teeth's angles,
        ``now_xy_m`` (2,) or (T, 2) the tool centre now, ``past_xy_m``
        (T, K, 2) its centre k = 1..K tooth periods back (K <= M)."""
        c, s = np.cos(theta_rad), np.sin(theta_rad)
        now = np.asarray(now_xy_m, dtype=float).reshape(-1, 1, 2)
        d = now - np.asarray(past_xy_m, dtype=float)  # (T, K, 2): the displacement since each pass
        K = d.shape[1]
        # (T, N, K): displacement k . r_j + R_j - R_(j-k)
        h = c[:, :, None] * d[:, None, :, 0] + s[:, :, None] * d[:, None, :, 1] + self._dR[None, :, :K]
        return h.min(axis=-1)

    def wrenches(self, t_s, tool_point_m, past_xy_m, workpiece, cut_length_m=0.0, detail=False):
        """(T, 6): the wrench on the tool (force N, moment N*m about the
        tool point, base frame) at each time of ``t_s``, the tool centre at
        ``tool_point_m`` (3, m) and, k tooth periods before each time, at
        ``past_xy_m`` (T, M, 2; ``past_times_s`` gives the instants).
        ``detail``: (w, (theta rad, depth m, chip m), each (T, N)) for
        ``out_of_cut``."""
        theta = self.angles_rad(t_s)
        c, s = np.cos(theta), np.sin(theta)
        R = self.cutter.radius_m
        p = np.asarray(tool_point_m, dtype=float)
        depth = tip_depths((p[0] + R * c).ravel(), (p[1] + R * s).ravel(), float(p[2]), workpiece).reshape(theta.shape)
        h = self.chips_m(theta, p[:2], past_xy_m)
        a = np.where(h > 0.0, depth, 0.0)  # a tooth whose chip is <= 0 has left the cut
        parts = self.law._wrench_uvz(c, s, np.maximum(h, 0.0), a, cut_length_m)
        w = np.stack([q.sum(axis=1) for q in parts], axis=-1)  # (u, v) = (x, y): the base frame
        if not detail:
            return w
        return w, (theta, depth, h)

    def out_of_cut(self, theta_rad, depth_m, h_m, feed_dir_xy, feed_m_per_s):
        """(engaged, out) counts: the tooth samples that the plant's law
        with the program's chip cuts (material under the tip, the leading
        half of ``feed_dir_xy``, its chip at ``feed_m_per_s`` along it
        positive: runout keeps some teeth off the slot's sides), and of
        those the ones whose regenerative chip is <= 0 (out of the cut)."""
        u = np.asarray(feed_dir_xy, dtype=float)
        cos_u = np.cos(theta_rad) * u[0] + np.sin(theta_rad) * u[1]
        program = self.law.chips_m(self.law.linear.chip_per_tooth_m(feed_m_per_s), cos_u)
        engaged = (cos_u > 0.0) & (depth_m > 0.0) & (program > 0.0)
        return int(engaged.sum()), int((engaged & (h_m <= 0.0)).sum())


class ToolHistory:
    """The tool centre's horizontal position over the last ``span_s``:
    rows (t s, x m, y m) in a fixed-size array, oldest first, NaN rows
    before the first (for a discrete state).  ``at`` interpolates
    linearly; before the first known instant it holds the first."""

    def __init__(self, span_s, step_s):
        self.n_rows = max(3, math.ceil(span_s / step_s + 1e-9) + 3)

    def empty(self):
        return np.full(3 * self.n_rows, np.nan)

    def pushed(self, hist, t_s, xy_m):
        """A copy of ``hist`` with (t, x, y) added (the oldest row dropped)."""
        out = np.empty(3 * self.n_rows)
        out[:-3] = np.asarray(hist, dtype=float)[3:]
        out[-3:] = (t_s, xy_m[0], xy_m[1])
        return out

    @staticmethod
    def at(hist, times_s):
        """(shape of times, 2): the positions at ``times_s`` (m)."""
        h = np.asarray(hist, dtype=float).reshape(-1, 3)
        h = h[~np.isnan(h[:, 0])]
        t = np.asarray(times_s, dtype=float)
        if len(h) == 0:
            return np.full(t.shape + (2,), np.nan)
        return np.stack([np.interp(t, h[:, 0], h[:, 1]), np.interp(t, h[:, 0], h[:, 2])], axis=-1)
