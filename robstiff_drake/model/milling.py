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
and ``average_wrench`` over one spindle revolution (the mean of the
tooth-resolved force, integrated over a fine angle grid).
"""

from dataclasses import dataclass

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


class MillingForceModel:
    """Wrench on the tool for a cutter position, in either mode."""

    def __init__(self, cutter, coefficients, feed_m_per_s, n_grid=720):
        self.cutter = cutter
        self.Kc, self.Ke = coefficients.si()
        self.feed_m_per_s = float(feed_m_per_s)
        self.c_f = cutter.feed_per_tooth_m(feed_m_per_s)
        self._grid = (np.arange(n_grid) + 0.5) * (2 * np.pi / n_grid) - np.pi
        self._cg, self._sg = np.cos(self._grid), np.sin(self._grid)
        # For the revolution average, the chip thickness at each grid angle is
        # fixed, so each wrench component is a fixed weight times the axial
        # depth there: W = weights @ a (six dot products in one product).
        lead = self._cg > 0
        self._lead_cg, self._lead_sg = self._cg[lead], self._sg[lead]
        h = self.c_f * self._lead_cg
        kt, kr, ka = (self.Kc[i] * h + self.Ke[i] for i in range(3))
        c, s_ = self._lead_cg, self._lead_sg
        R = cutter.radius_m
        fu, fv, fz = -kt * s_ - kr * c, kt * c - kr * s_, ka
        scale = cutter.n_teeth / n_grid
        self._weights = scale * np.vstack([fu, fv, fz, R * s_ * fz, -R * c * fz, R * (c * fv - s_ * fu)])

    def _per_tooth(self, theta_cos, theta_sin, c_xy, z_b, u, workpiece):
        """Force and moment (about the tool point) for teeth at the given angles,
        summed; (3,), (3,)."""
        R = self.cutter.radius_m
        v = np.array([-u[1], u[0]])
        tip = c_xy[None, :] + R * (theta_cos[:, None] * u[None, :] + theta_sin[:, None] * v[None, :])
        # axial depth under each tooth: the highest uncut box top above the cutter bottom
        inside = ((tip[:, None, 0] >= workpiece.x_m[None, :, 0]) & (tip[:, None, 0] <= workpiece.x_m[None, :, 1])
                  & (tip[:, None, 1] >= workpiece.y_m[None, :, 0]) & (tip[:, None, 1] <= workpiece.y_m[None, :, 1]))
        depth = np.where(inside, workpiece.top_m[None, :] - z_b, 0.0).max(axis=1)
        h = self.c_f * theta_cos
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
        F_uvz = np.array([fu.sum(), fv.sum(), fz.sum()])
        M_uvz = np.array([mu.sum(), mv.sum(), mz.sum()])
        return F_uvz, M_uvz, a

    @staticmethod
    def _to_base(vec_uvz, u):
        return np.array([vec_uvz[0] * u[0] - vec_uvz[1] * u[1], vec_uvz[0] * u[1] + vec_uvz[1] * u[0], vec_uvz[2]])

    def tooth_wrench(self, t_s, tool_point_m, feed_dir_xy, workpiece, phase_rad=0.0):
        """Wrench (force N, moment N*m about the tool point), base frame, on
        the tool at time t with the teeth at their angles then.  With an
        array of times, the sum over them (divide by their number for the
        mean)."""
        u = np.asarray(feed_dir_xy, dtype=float)
        base = phase_rad - self.cutter.spindle_rad_per_s * np.atleast_1d(t_s)  # clockwise from above
        theta = (base[:, None] + 2 * np.pi * np.arange(self.cutter.n_teeth) / self.cutter.n_teeth).ravel()
        F, M, _ = self._per_tooth(np.cos(theta), np.sin(theta), np.asarray(tool_point_m[:2]), tool_point_m[2], u,
                                  workpiece)
        return np.concatenate([self._to_base(F, u), self._to_base(M, u)])

    def average_wrench(self, tool_point_m, feed_dir_xy, workpiece):
        """Wrench averaged over one spindle revolution (N teeth each sweep the grid)."""
        u0, u1 = float(feed_dir_xy[0]), float(feed_dir_xy[1])
        R = self.cutter.radius_m
        cg, sg = self._lead_cg, self._lead_sg
        tx = tool_point_m[0] + R * (cg * u0 - sg * u1)
        ty = tool_point_m[1] + R * (cg * u1 + sg * u0)
        z_b = tool_point_m[2]
        a = np.zeros(len(cg))
        for (x0, x1), (y0, y1), top in zip(workpiece.x_m, workpiece.y_m, workpiece.top_m):
            if top > z_b:
                inside = (tx >= x0) & (tx <= x1) & (ty >= y0) & (ty <= y1)
                np.maximum(a, np.where(inside, top - z_b, 0.0), out=a)
        w = self._weights @ a
        return np.array([w[0] * u0 - w[1] * u1, w[0] * u1 + w[1] * u0, w[2],
                         w[3] * u0 - w[4] * u1, w[3] * u1 + w[4] * u0, w[5]])

    def engagement(self, tool_point_m, feed_dir_xy, workpiece):
        """(radial engagement angle, rad; max axial depth, m) for reporting."""
        u = np.asarray(feed_dir_xy, dtype=float)
        _, _, a = self._per_tooth(self._cg, self._sg, np.asarray(tool_point_m[:2]), tool_point_m[2], u, workpiece)
        return float(np.count_nonzero(a > 0) * 2 * np.pi / len(self._grid)), float(a.max(initial=0.0))
