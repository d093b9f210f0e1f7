"""Mechanistic face-milling force model (Altintas' linear edge-force model)
with the engagement computed from the actual cutter position against the
workpiece.  Plain numpy; no Drake.

Geometry (base frame, metres).  The spindle axis points straight down; the
cutter's bottom face is a disc of radius R at height z_b around the tool
point c.  The feed direction u is horizontal; v = z x u.  A tooth at angle
theta (from u, counter-clockwise seen from above) sits at c + R (cos theta u +
sin theta v).  The cutter turns clockwise seen from above (a right-hand
cutter, M03), so the tooth moves along t = sin theta u - cos theta v.
Chip thickness is h = c_f cos theta on the leading half (cos theta > 0), with
c_f the feed per tooth: the "c sin(phi)" of the textbook with phi = theta +
90 deg measured from the cross-feed axis.

A tooth cuts where its tip is over uncut material (inside a workpiece box,
leading half) and the cutter bottom is below the box top; the axial depth is
a = top - z_b.  Per tooth, on the tool:
    F = -F_t t - F_r (cos theta u + sin theta v) + F_a z,
    F_t = K_tc a h + K_te a,  F_r = K_rc a h + K_re a,  F_a = K_ac a h + K_ae a,
and the moment about the tool point is sum r x F (this includes the cutting
torque about the spindle axis, which the spindle housing, and so the wrist
sensor, carries).

Two modes: ``tooth_wrench`` at the current tooth angles (tooth-resolved),
and ``average_wrench`` over one spindle revolution: the mean of the
tooth-resolved wrench, W = N / (2 pi) * integral over the leading half of
a(theta) w(theta) d theta.  Each component of w is a combination of 1,
cos, sin, cos sin and cos^2 (h = c_f cos theta is linear in cos theta), and
a(theta) is piecewise constant between the angles where the tooth tip
crosses a box edge, so the integral is exact in closed form: no angle grid.
"""

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np


@dataclass(frozen=True)
class CuttingCoefficients:
    """Linear edge-force model: cutting (N/mm^2) and edge (N/mm) coefficients."""

    Ktc_N_per_mm2: float
    Krc_N_per_mm2: float
    Kac_N_per_mm2: float
    Kte_N_per_mm: float
    Kre_N_per_mm: float
    Kae_N_per_mm: float

    def si(self):
        """(K_tc, K_rc, K_ac) in N/m^2 and (K_te, K_re, K_ae) in N/m."""
        return (np.array([self.Ktc_N_per_mm2, self.Krc_N_per_mm2, self.Kac_N_per_mm2]) * 1e6,
                np.array([self.Kte_N_per_mm, self.Kre_N_per_mm, self.Kae_N_per_mm]) * 1e3)


@dataclass(frozen=True)
class Cutter:
    diameter_m: float
    n_teeth: int
    spindle_rpm: float

    @property
    def radius_m(self):
        return 0.5 * self.diameter_m

    @property
    def spindle_rad_per_s(self):
        return self.spindle_rpm * 2 * np.pi / 60.0

    @property
    def tooth_pass_hz(self):
        return self.spindle_rpm / 60.0 * self.n_teeth

    def feed_per_tooth_m(self, feed_m_per_s):
        return feed_m_per_s / self.tooth_pass_hz


@dataclass(frozen=True)
class Workpiece:
    """Uncut material as axis-aligned boxes: (N, 2) x, y ranges and (N,) tops (m).
    A box's bottom is far below any cut: only its top face is machined."""

    x_m: np.ndarray
    y_m: np.ndarray
    top_m: np.ndarray

    @staticmethod
    def from_boxes(boxes_m):
        """boxes_m: iterable of (x0, x1, y0, y1, top)."""
        b = np.asarray(boxes_m, dtype=float).reshape(-1, 5)
        return Workpiece(b[:, 0:2], b[:, 2:4], b[:, 4])

    @cached_property
    def boxes(self):
        """The boxes as tuples of floats (x0, x1, y0, y1, top), for scalar code."""
        return tuple((x0, x1, y0, y1, top) for (x0, x1), (y0, y1), top in
                     zip(self.x_m.tolist(), self.y_m.tolist(), self.top_m.tolist()))


# Up to this many workpiece boxes, tip_depths tests the tips box by box (fewer array operations).
FEW_BOXES = 8


def tip_depths(x, y, z_b, workpiece):
    """The axial depth of cut (m, >= 0) under tooth tips at (x, y) (arrays,
    m) for a cutter bottom at z_b: the highest uncut box top above it, 0
    where no box is.  Box by box for a few boxes, all at once (tips x boxes)
    for many."""
    if len(workpiece.boxes) <= FEW_BOXES:
        depth = np.zeros(np.shape(x))
        for x0, x1, y0, y1, top in workpiece.boxes:
            if top > z_b:
                np.maximum(depth, np.where((x >= x0) & (x <= x1) & (y >= y0) & (y <= y1), top - z_b, 0.0), out=depth)
        return depth
    X, Y = x[:, None], y[:, None]
    inside = ((X >= workpiece.x_m[None, :, 0]) & (X <= workpiece.x_m[None, :, 1])
              & (Y >= workpiece.y_m[None, :, 0]) & (Y <= workpiece.y_m[None, :, 1]))
    return np.maximum(np.where(inside, workpiece.top_m[None, :] - z_b, 0.0).max(axis=1), 0.0)


class MillingForceModel:
    """Wrench on the tool for a cutter position, in either mode."""

    def __init__(self, cutter, coefficients, feed_m_per_s):
        self.cutter = cutter
        self.Kc, self.Ke = coefficients.si()
        self.feed_m_per_s = float(feed_m_per_s)
        self.c_f = cutter.feed_per_tooth_m(feed_m_per_s)
        # Revolution average: rows (f_u, f_v, f_z, m_u, m_v, m_z) of the
        # per-tooth wrench per metre of depth as coefficients of the basis
        # (1, c, s, c s, c^2), c = cos theta, s = sin theta; times N / (2 pi):
        # the edge part, and the cutting part per metre of feed per tooth.
        Kt, Kr, Ka = self.Kc
        (Kte, Kre, Kae) = self.Ke
        R = cutter.radius_m
        n = cutter.n_teeth / (2 * np.pi)
        edge = np.array([
            [0.0, -Kre, -Kte, 0.0, 0.0],     # f_u = -k_t s - k_r c
            [0.0, Kte, -Kre, 0.0, 0.0],      # f_v = k_t c - k_r s
            [Kae, 0.0, 0.0, 0.0, 0.0],       # f_z = k_a
            [0.0, 0.0, R * Kae, 0.0, 0.0],   # m_u = R s f_z
            [0.0, -R * Kae, 0.0, 0.0, 0.0],  # m_v = -R c f_z
            [R * Kte, 0.0, 0.0, 0.0, 0.0],   # m_z = R k_t (the cutting torque)
        ]) * n
        cut = np.array([
            [0.0, 0.0, 0.0, -Kt, -Kr],
            [0.0, 0.0, 0.0, -Kr, Kt],
            [0.0, Ka, 0.0, 0.0, 0.0],
            [0.0, 0.0, 0.0, R * Ka, 0.0],
            [0.0, 0.0, 0.0, 0.0, -R * Ka],
            [0.0, R * Kt, 0.0, 0.0, 0.0],
        ]) * n
        self._edge, self._cut = edge, cut
        self._basis = self._basis_at(self.c_f)

    def _basis_at(self, c_f):
        return [tuple(float(v) for v in row) for row in self._edge + c_f * self._cut]

    def chip_per_tooth_m(self, feed_m_per_s=None):
        """The feed per tooth (m) at ``feed_m_per_s`` (None: the model's own feed)."""
        return self.c_f if feed_m_per_s is None else self.cutter.feed_per_tooth_m(feed_m_per_s)

    def _per_tooth(self, theta_cos, theta_sin, c_xy, z_b, u, workpiece, c_f=None):
        """Force and moment (about the tool point) for teeth at the given angles,
        summed; (3,), (3,)."""
        (fu, fv, fz, mu, mv, mz), a = self._tooth_terms(theta_cos, theta_sin, c_xy, z_b, u, workpiece, c_f)
        return np.array([fu.sum(), fv.sum(), fz.sum()]), np.array([mu.sum(), mv.sum(), mz.sum()]), a

    def _tooth_terms(self, theta_cos, theta_sin, c_xy, z_b, u, workpiece, c_f=None):
        """((f_u, f_v, f_z, m_u, m_v, m_z) per tooth angle, depth a per tooth);
        ``c_f``: the feed per tooth (m), None: the model's own."""
        R = self.cutter.radius_m
        v = np.array([-u[1], u[0]])
        tip = c_xy[None, :] + R * (theta_cos[:, None] * u[None, :] + theta_sin[:, None] * v[None, :])
        depth = tip_depths(tip[:, 0], tip[:, 1], z_b, workpiece)  # axial depth under each tooth
        h = (self.c_f if c_f is None else c_f) * theta_cos
        a = np.where((h > 0) & (depth > 0), depth, 0.0)
        Ft = self.Kc[0] * a * h + self.Ke[0] * a
        Fr = self.Kc[1] * a * h + self.Ke[1] * a
        Fa = self.Kc[2] * a * h + self.Ke[2] * a
        # in (u, v, z): t = (sin, -cos, 0), radial = (cos, sin, 0)
        fu = -Ft * theta_sin - Fr * theta_cos
        fv = Ft * theta_cos - Fr * theta_sin
        fz = Fa
        # lever from the tool point (cutter centre, bottom face) to the tooth tip
        ru, rv = R * theta_cos, R * theta_sin
        mu = rv * fz
        mv = -ru * fz
        mz = ru * fv - rv * fu
        return (fu, fv, fz, mu, mv, mz), a

    @staticmethod
    def _to_base(vec_uvz, u):
        return np.array([vec_uvz[0] * u[0] - vec_uvz[1] * u[1], vec_uvz[0] * u[1] + vec_uvz[1] * u[0], vec_uvz[2]])

    def tooth_wrench(self, t_s, tool_point_m, feed_dir_xy, workpiece, phase_rad=0.0, feed_m_per_s=None):
        """Wrench (force N, moment N*m about the tool point), base frame, on
        the tool at time t with the teeth at their angles then.  With an
        array of times, the sum over them (divide by their number for the
        mean).  ``feed_m_per_s``: the feed (chip thickness) there; None: the
        model's."""
        u = np.asarray(feed_dir_xy, dtype=float)
        base = phase_rad - self.cutter.spindle_rad_per_s * np.atleast_1d(t_s)  # clockwise from above
        theta = (base[:, None] + 2 * np.pi * np.arange(self.cutter.n_teeth) / self.cutter.n_teeth).ravel()
        F, M, _ = self._per_tooth(np.cos(theta), np.sin(theta), np.asarray(tool_point_m[:2]), tool_point_m[2], u,
                                  workpiece, self.chip_per_tooth_m(feed_m_per_s))
        return np.concatenate([self._to_base(F, u), self._to_base(M, u)])

    def tooth_wrenches(self, t_s, tool_point_m, feed_dir_xy, workpiece, phase_rad=0.0, feed_m_per_s=None):
        """(n, 6): the wrench of ``tooth_wrench`` at each of the times ``t_s``
        (n,), one row each (one vectorised evaluation); ``feed_m_per_s`` as
        there.  Each tooth's wrench in (u, v, z) is its depth a times a
        linear form in (1, c, s, c s, c^2) of its angle (the basis of
        ``average_wrench``, c = cos theta, s = sin theta), so the teeth of
        each row are summed in that basis and turned into wrenches by one
        product: the same numbers as ``tooth_wrench`` to round-off, with a
        third of its array operations (this runs every plant step of a
        tooth-resolved simulation)."""
        u0, u1 = float(feed_dir_xy[0]), float(feed_dir_xy[1])
        n = self.cutter.n_teeth
        t = np.atleast_1d(np.asarray(t_s, dtype=float))
        n_t = t.size
        theta = ((phase_rad - self.cutter.spindle_rad_per_s * t)[:, None] + 2 * np.pi * np.arange(n) / n).ravel()
        c, s = np.cos(theta), np.sin(theta)
        R = self.cutter.radius_m
        x = float(tool_point_m[0]) + R * (c * u0 - s * u1)  # the tooth tips (tooth_wrench's tip)
        y = float(tool_point_m[1]) + R * (c * u1 + s * u0)
        z_b = float(tool_point_m[2])
        depth = tip_depths(x, y, z_b, workpiece)
        c_f = self.chip_per_tooth_m(feed_m_per_s)
        a = np.where(c > 0, depth, 0.0) if c_f > 0 else np.zeros(theta.shape)  # engaged: chip h = c_f c > 0
        phi = np.empty((5, theta.size))
        phi[0] = a
        phi[1] = a * c
        phi[2] = a * s
        phi[3] = phi[1] * s
        phi[4] = phi[1] * c
        # per row: (6, 5) per-tooth basis (average_wrench's without its n / (2 pi)) times the teeth's sums
        w = ((self._edge + c_f * self._cut) * (2 * np.pi / n)) @ phi.reshape(5, n_t, n).sum(axis=2)
        out = np.empty((n_t, 6))
        out[:, 0] = w[0] * u0 - w[1] * u1
        out[:, 1] = w[0] * u1 + w[1] * u0
        out[:, 2] = w[2]
        out[:, 3] = w[3] * u0 - w[4] * u1
        out[:, 4] = w[3] * u1 + w[4] * u0
        out[:, 5] = w[5]
        return out

    def lead_intervals(self, tool_point_m, feed_dir_xy, workpiece):
        """The leading half of the cutter (theta in [-pi/2, pi/2]) split where a
        tooth tip crosses a box edge: a list of (theta_a, theta_b, depth m)
        with depth > 0, the highest uncut top above the cutter bottom there."""
        u0, u1 = float(feed_dir_xy[0]), float(feed_dir_xy[1])
        phi = math.atan2(u1, u0)  # tip at absolute angle theta + phi
        R = self.cutter.radius_m
        cx, cy, z_b = float(tool_point_m[0]), float(tool_point_m[1]), float(tool_point_m[2])
        boxes = [(x0, x1, y0, y1, top - z_b) for x0, x1, y0, y1, top in workpiece.boxes if top > z_b]
        if not boxes:
            return []
        half = 0.5 * math.pi
        cuts = [-half, half]
        for x0, x1, y0, y1, _ in boxes:
            for X in (x0, x1):
                r = (X - cx) / R
                if -1.0 < r < 1.0:
                    a = math.acos(r)
                    cuts += [a - phi, -a - phi]
            for Y in (y0, y1):
                r = (Y - cy) / R
                if -1.0 < r < 1.0:
                    a = math.asin(r)
                    cuts += [a - phi, math.pi - a - phi]
        two_pi = 2 * math.pi
        angles = sorted({t for t in ((c + math.pi) % two_pi - math.pi for c in cuts) if -half <= t <= half})
        out = []
        for ta, tb in zip(angles[:-1], angles[1:]):
            tm = 0.5 * (ta + tb) + phi
            x, y = cx + R * math.cos(tm), cy + R * math.sin(tm)
            depth = 0.0
            for x0, x1, y0, y1, d in boxes:
                if d > depth and x0 <= x <= x1 and y0 <= y <= y1:
                    depth = d
            if depth > 0.0:
                if out and out[-1][1] == ta and out[-1][2] == depth:
                    out[-1] = (out[-1][0], tb, depth)
                else:
                    out.append((ta, tb, depth))
        return out

    def average_wrench(self, tool_point_m, feed_dir_xy, workpiece, feed_m_per_s=None):
        """Wrench (force N, moment N*m about the tool point, base frame) averaged
        over one spindle revolution, integrated exactly over the engaged arcs.
        ``feed_m_per_s``: the feed there (the chip thickness follows it);
        None: the model's own feed."""
        S0 = S1 = S2 = S3 = S4 = 0.0
        for ta, tb, a in self.lead_intervals(tool_point_m, feed_dir_xy, workpiece):
            sa, ca, sb, cb = math.sin(ta), math.cos(ta), math.sin(tb), math.cos(tb)
            # antiderivatives of 1, c, s, c s, c^2
            S0 += a * (tb - ta)
            S1 += a * (sb - sa)
            S2 += a * (ca - cb)
            S3 += a * 0.5 * (sb * sb - sa * sa)
            S4 += a * 0.5 * ((tb - ta) + sb * cb - sa * ca)
        basis = self._basis if feed_m_per_s is None or feed_m_per_s == self.feed_m_per_s else \
            self._basis_at(self.cutter.feed_per_tooth_m(feed_m_per_s))
        w = [b0 * S0 + b1 * S1 + b2 * S2 + b3 * S3 + b4 * S4 for b0, b1, b2, b3, b4 in basis]
        u0, u1 = float(feed_dir_xy[0]), float(feed_dir_xy[1])
        return np.array([w[0] * u0 - w[1] * u1, w[0] * u1 + w[1] * u0, w[2],
                         w[3] * u0 - w[4] * u1, w[3] * u1 + w[4] * u0, w[5]])

    def engagement(self, tool_point_m, feed_dir_xy, workpiece):
        """(radial engagement angle, rad; max axial depth, m) for reporting."""
        arcs = self.lead_intervals(tool_point_m, feed_dir_xy, workpiece)
        return sum(tb - ta for ta, tb, _ in arcs), max((a for _, _, a in arcs), default=0.0)
