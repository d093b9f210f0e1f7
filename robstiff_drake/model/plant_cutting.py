"""The plant's cutting physics: a richer law than the compensator's linear,
revolution-averaged model (model/milling.py), so that compensation is
tested against a force it does not share.  Plain numpy; no Drake.

What differs from the compensator's model (each with its size and source):

- Chip thickness and feed direction come from where the tool ACTUALLY
  is and how fast it progresses, given by the caller
  (systems/milling_force.py: the tool's progress along its path over a
  revolution, low-passed at 2 Hz, and the path's direction where the tool
  is), not from the planned path at clock time: the feed per tooth is that
  feed / tooth-pass frequency, so a tool that lags the plan, slows in a
  ramp or reaches a corner late makes its chip (and force direction) where
  it really is.
- A nonlinear chip-thickness law (Kienzle): the cutting part of each
  force per unit depth is k_c h_ref^m_c h^(1 - m_c).  1 - m_c = 0.75
  (m_c = 0.25): Sandvik Coromant's value for its ISO N (aluminium)
  material groups; Koenig and Klocke, Fertigungsverfahren 1, list 0.70-0.80
  for wrought AlMgSi alloys (1 - m_c, with k_c1.1 about 700-830 N/mm^2).
  The law passes through the scenario's linear coefficients at the mean
  chip h_ref = (2 / pi) c_f of the scenario's feed (the scenario's
  coefficients are then what a linear cutting test at that feed fits): a
  thinner chip cuts with a higher specific force, a thicker one lower.
- Edge (ploughing) forces: the scenario's edge coefficients (Kte, Kre,
  Kae) plus the flank wear land's ploughing, dK_re = sigma_n VB,
  dK_te = mu sigma_n VB, dK_ae = 0.5 dK_re (the wear land pressed on the
  machined surface: Smithey, Kapoor and DeVor, "A new mechanistic model for
  predicting worn tool cutting forces", Machining Sci. Tech. 5(1), 2001;
  the land's normal stress of the order of the work material's flow
  stress).  sigma_n = 300 N/mm^2: 6082-T6's yield strength 260-310 MPa
  (EN 755-2); mu = 0.3 (carbide on aluminium, dry).
- The edge forces ramp in with the chip up to ``edge_ramp_chip_m`` (the
  linear model's edge force is the intercept of a fit at real chips; at a
  chip that thins to nothing, a cutter at rest or crawling, a rounded
  edge's ploughing goes with the chip up to about its edge radius: the
  minimum chip thickness is 0.2-0.4 of it, Liu, DeVor and Kapoor, J. Manuf.
  Sci. Eng. 126(4), 2004).  10 um: the hone of a sharp insert for
  aluminium (ASSUMPTION, 5-20 um by grade).
- Flank wear growing along the cut: VB = VB0 + rate * (cut length).
  ASSUMPTION: VB0 = 0.02 mm (a fresh insert's edge after run-in), rate
  0.3 mm per km of cutting travel (an insert reaching ISO 3685's VB =
  0.3 mm criterion after about a kilometre of cut, the order of carbide
  face milling of aluminium); over one job of metres its drift is small,
  over a shift of parts it is not.
- Cutter runout: tooth j's radius is R + rho cos(2 pi j / N - lambda), so
  tooth j's chip is the least over k = 1..N of k c_f cos theta + R_j -
  R_(j-k) (the surface the tooth k back left; Kline and DeVor, "The
  effect of runout on cutting geometry and forces in end milling", Int. J.
  Mach. Tool Des. Res. 23(2-3), 1983).  rho = 0.010 mm: a face mill's
  insert runout on a robot spindle's taper and arbor, 5-20 um (the
  inserts' seat tolerance and a collet or arbor's TIR).

The revolution-averaged mode integrates the tooth-resolved law over the
engaged arcs (model/milling.py's lead_intervals, which are exact) with
Gauss-Legendre points in each arc, tooth by tooth (runout makes the teeth
differ); the tooth-resolved mode evaluates it at the teeth's angles.
"""

from dataclasses import dataclass

import numpy as np

from robstiff_drake.model import jit
from robstiff_drake.model.cutting_kernels import average_wrench_at, tooth_wrenches_at
from robstiff_drake.model.milling import Workpiece, tip_depths


@dataclass(frozen=True)
class PlantCuttingPhysics:
    """The sizes of the plant's cutting physics (see the module docstring)."""

    chip_exponent: float = 0.75            # 1 - m_c (Kienzle); 1: the linear law
    runout_m: float = 10e-6                # radial runout of the inserts, m
    runout_angle_rad: float = 0.0          # where the largest radius sits (tooth 0's angle from it), rad
    flank_wear_m: float = 0.02e-3          # VB at the start of the cut, m
    flank_wear_per_m: float = 0.3e-6       # VB growth per metre of cutting travel (0.3 mm per km)
    land_stress_N_per_m2: float = 300e6    # sigma_n: the wear land's normal stress
    land_friction: float = 0.3             # mu on the wear land
    edge_ramp_chip_m: float = 10e-6        # the chip up to which the edge forces ramp in, m (0: a step)

    @staticmethod
    def linear():
        """The compensator's law as a plant: linear chip, no runout, no wear."""
        return PlantCuttingPhysics(chip_exponent=1.0, runout_m=0.0, flank_wear_m=0.0, flank_wear_per_m=0.0,
                                   edge_ramp_chip_m=0.0)


# Gauss-Legendre points per engaged arc of the revolution average (nodes and weights on [-1, 1])
GAUSS_POINTS = 10
_GAUSS_X, _GAUSS_W = np.polynomial.legendre.leggauss(GAUSS_POINTS)


class PlantCuttingLaw:
    """The plant's wrench on the tool (force N, moment N*m about the tool
    point, base frame), in the calling convention of MillingForceModel:
    ``average_wrench`` and ``tooth_wrenches`` take the feed direction and
    feed (m/s) the caller measured (the tool's actual velocity), and the
    cutting travel so far (m, the flank wear's clock)."""

    def __init__(self, linear_model, physics=None, reference_feed_m_per_s=None):
        self.linear = linear_model
        self.cutter = linear_model.cutter
        self.physics = physics or PlantCuttingPhysics()
        self.Kc, self.Ke = linear_model.Kc, linear_model.Ke
        self.feed_m_per_s = linear_model.feed_m_per_s
        feed = reference_feed_m_per_s or linear_model.feed_m_per_s
        # the chip at which the Kienzle law equals the scenario's linear coefficients (m)
        self.h_ref_m = 2.0 / np.pi * self.cutter.feed_per_tooth_m(feed)
        n = self.cutter.n_teeth
        R = self.cutter.radius_m
        rho, lam = self.physics.runout_m, self.physics.runout_angle_rad
        radii = R + rho * np.cos(2 * np.pi * np.arange(n) / n - lam)
        # tooth j cuts what tooth j-1 left: its chip grows by R_j - R_(j-1)
        self.runout_chip_m = radii - np.roll(radii, 1)
        # ... unless a tooth further back cut deeper: tooth j-k's surface lies k feeds back, R_j - R_(j-k)
        # nearer (k = 1..n): the chip is the least of them (k = n: the tooth's own last pass)
        self._k = np.arange(1, n + 1, dtype=float)
        # the compiled kernels' constants, made when first used
        self._kernel_args = self._tooth_angles = self._last_boxes = None
        self._dR = np.array([[radii[j] - radii[(j - k) % n] for k in range(1, n + 1)] for j in range(n)])

    def chips_m(self, c_f, cos_theta):
        """The chip (m) of each tooth: (..., n) for cos theta of shape (...,
        n), tooth j in the last axis; the least of k c_f cos theta + R_j -
        R_(j-k) over the teeth k back (Kline and DeVor's runout chip)."""
        c = np.asarray(cos_theta, dtype=float)
        return np.min(c_f * c[..., None] * self._k + self._dR, axis=-1)

    def flank_wear_m(self, cut_length_m=0.0):
        p = self.physics
        return p.flank_wear_m + p.flank_wear_per_m * max(float(cut_length_m), 0.0)

    def edge_coefficients(self, cut_length_m=0.0):
        """(K_te, K_re, K_ae) in N/m with the wear land's ploughing."""
        p = self.physics
        dKr = p.land_stress_N_per_m2 * self.flank_wear_m(cut_length_m)
        return self.Ke + np.array([p.land_friction * dKr, dKr, 0.5 * dKr])

    def chip_forces(self, h_m, a_m, cut_length_m=0.0):
        """Per-tooth (F_t, F_r, F_a), N, for chips h (m) and depths a (m),
        arrays of one shape: 0 where a <= 0 or h < 0 (a tooth that runout
        keeps off the surface); the edge forces ramp in up to a chip of
        ``edge_ramp_chip_m`` (with 0: in full at h = 0, the linear model's)."""
        h = np.asarray(h_m, dtype=float)
        a = np.where(h >= 0, np.asarray(a_m, dtype=float), 0.0)
        h = np.maximum(h, 0.0)
        e = self.physics.chip_exponent
        chip = h if e == 1.0 else self.h_ref_m ** (1.0 - e) * h ** e
        ramp = self.physics.edge_ramp_chip_m
        edge = a if ramp <= 0 else a * np.minimum(h / ramp, 1.0)
        Ke = self.edge_coefficients(cut_length_m)
        return tuple(self.Kc[i] * a * chip + Ke[i] * edge for i in range(3))

    def _wrench_uvz(self, c, s, h, a, cut_length_m):
        """(f_u, f_v, f_z, m_u, m_v, m_z) of each tooth at cos/sin (c, s) of
        its angle with chip h and depth a (arrays of one shape)."""
        Ft, Fr, Fa = self.chip_forces(h, a, cut_length_m)
        R = self.cutter.radius_m
        fu = -Ft * s - Fr * c
        fv = Ft * c - Fr * s
        return fu, fv, Fa, R * s * Fa, -R * c * Fa, R * (c * fv - s * fu)

    @staticmethod
    def _to_base(w, u0, u1):
        """(..., 6) in (u, v, z) -> base frame."""
        out = np.empty(w.shape)
        out[..., 0] = w[..., 0] * u0 - w[..., 1] * u1
        out[..., 1] = w[..., 0] * u1 + w[..., 1] * u0
        out[..., 2] = w[..., 2]
        out[..., 3] = w[..., 3] * u0 - w[..., 4] * u1
        out[..., 4] = w[..., 3] * u1 + w[..., 4] * u0
        out[..., 5] = w[..., 5]
        return out

    def tooth_wrenches(self, t_s, tool_point_m, feed_dir_xy, workpiece, phase_rad=0.0, feed_m_per_s=None,
                       cut_length_m=0.0):
        """(n, 6): the tooth-resolved wrench at each time of ``t_s`` (base
        frame), the teeth at their angles then, the chip from ``feed_m_per_s``
        (None: the scenario's feed) along ``feed_dir_xy``.  Compiled
        (model/cutting_kernels.py) when numba is installed, else
        ``tooth_wrenches_reference``; the two agree to round-off."""
        if not jit.available():
            return self.tooth_wrenches_reference(t_s, tool_point_m, feed_dir_xy, workpiece, phase_rad, feed_m_per_s,
                                                 cut_length_m)
        h_scale, e, ramp, Kc = self._constants()
        if self._tooth_angles is None:
            n = self.cutter.n_teeth
            self._tooth_angles = 2 * np.pi * np.arange(n) / n
        boxes = self._boxes(workpiece)
        return tooth_wrenches_at(np.atleast_1d(np.asarray(t_s, dtype=float)), float(tool_point_m[0]),
                                 float(tool_point_m[1]), float(tool_point_m[2]), float(feed_dir_xy[0]),
                                 float(feed_dir_xy[1]), float(phase_rad), float(self.cutter.spindle_rad_per_s),
                                 self._tooth_angles, float(self.linear.chip_per_tooth_m(feed_m_per_s)), h_scale, e,
                                 ramp, Kc, self.edge_coefficients(cut_length_m), float(self.cutter.radius_m), self._k,
                                 self._dR, boxes)

    def tooth_wrenches_reference(self, t_s, tool_point_m, feed_dir_xy, workpiece, phase_rad=0.0, feed_m_per_s=None,
                                 cut_length_m=0.0):
        """``tooth_wrenches`` vectorised in numpy (the compiled kernel's reference)."""
        u0, u1 = float(feed_dir_xy[0]), float(feed_dir_xy[1])
        n = self.cutter.n_teeth
        t = np.atleast_1d(np.asarray(t_s, dtype=float))
        theta = (phase_rad - self.cutter.spindle_rad_per_s * t)[:, None] + 2 * np.pi * np.arange(n) / n  # (T, n)
        c, s = np.cos(theta), np.sin(theta)
        R = self.cutter.radius_m
        x = float(tool_point_m[0]) + R * (c * u0 - s * u1)
        y = float(tool_point_m[1]) + R * (c * u1 + s * u0)
        depth = tip_depths(x.ravel(), y.ravel(), float(tool_point_m[2]), workpiece).reshape(theta.shape)
        c_f = self.linear.chip_per_tooth_m(feed_m_per_s)
        depth = np.where(c > 0, depth, 0.0)  # the leading half cuts
        h = self.chips_m(c_f, c)
        parts = self._wrench_uvz(c, s, h, depth, cut_length_m)
        w = np.stack([p.sum(axis=1) for p in parts], axis=-1)  # (T, 6)
        return self._to_base(w, u0, u1)

    def tooth_wrench(self, t_s, tool_point_m, feed_dir_xy, workpiece, phase_rad=0.0, feed_m_per_s=None,
                     cut_length_m=0.0):
        """The summed tooth_wrenches over the times ``t_s`` (one time: its wrench)."""
        return self.tooth_wrenches(t_s, tool_point_m, feed_dir_xy, workpiece, phase_rad, feed_m_per_s,
                                   cut_length_m).sum(axis=0)

    def average_wrench(self, tool_point_m, feed_dir_xy, workpiece, feed_m_per_s=None, cut_length_m=0.0):
        """The wrench averaged over one spindle revolution (base frame):
        each tooth integrated over the engaged arcs of the leading half.
        Compiled (model/cutting_kernels.py) when numba is installed, else
        ``average_wrench_reference``; the two agree to round-off."""
        if not jit.available():
            return self.average_wrench_reference(tool_point_m, feed_dir_xy, workpiece, feed_m_per_s, cut_length_m)
        h_scale, e, ramp, Kc = self._constants()
        return average_wrench_at(float(tool_point_m[0]), float(tool_point_m[1]), float(tool_point_m[2]),
                                 float(feed_dir_xy[0]), float(feed_dir_xy[1]), self._boxes(workpiece),
                                 float(self.linear.chip_per_tooth_m(feed_m_per_s)), h_scale, e, ramp, Kc,
                                 self.edge_coefficients(cut_length_m), self.cutter.radius_m, self._k, self._dR,
                                 _GAUSS_X, _GAUSS_W)

    def _constants(self):
        """(h_ref^(1 - e), e, the edge ramp's chip m, Kc): the law's
        constants for the compiled kernels, as the reference computes them."""
        if self._kernel_args is None:
            e = self.physics.chip_exponent
            self._kernel_args = (float(self.h_ref_m ** (1.0 - e)), float(e), float(self.physics.edge_ramp_chip_m),
                                 self.Kc)
        return self._kernel_args

    def _boxes(self, workpiece):
        """The workpiece's boxes as a (B, 5) array (x0, x1, y0, y1, top, m),
        kept for the last workpiece asked for."""
        last = self._last_boxes
        if last is None or last[0] is not workpiece:
            last = self._last_boxes = (workpiece, np.array(workpiece.boxes, dtype=float).reshape(-1, 5))
        return last[1]

    def warm_up(self):
        """Load (or compile) the compiled kernel now, not in the first
        update of a timed simulation (nothing without numba)."""
        if jit.available():
            c = self.cutter
            tool = (0.0, 0.0, -1e-3)
            box = Workpiece(x_m=np.array([[-2 * c.radius_m, 2 * c.radius_m]]),
                            y_m=np.array([[-2 * c.radius_m, 2 * c.radius_m]]), top_m=np.array([0.0]))
            self.average_wrench(tool, (1.0, 0.0), box, self.feed_m_per_s)
            self.tooth_wrenches([0.0, 1e-3], tool, (1.0, 0.0), box, 0.0, self.feed_m_per_s)

    def average_wrench_reference(self, tool_point_m, feed_dir_xy, workpiece, feed_m_per_s=None, cut_length_m=0.0):
        """``average_wrench`` vectorised in numpy (the reference the compiled
        kernel is tested against)."""
        arcs = self.linear.lead_intervals(tool_point_m, feed_dir_xy, workpiece)
        u0, u1 = float(feed_dir_xy[0]), float(feed_dir_xy[1])
        if not arcs:
            return np.zeros(6)
        ab = np.array(arcs)  # (arcs, 3): from, to, depth
        mid, half = 0.5 * (ab[:, 0] + ab[:, 1]), 0.5 * (ab[:, 1] - ab[:, 0])
        th = (mid[:, None] + half[:, None] * _GAUSS_X[None, :]).ravel()
        wt = (half[:, None] * _GAUSS_W[None, :]).ravel()
        dep = np.repeat(ab[:, 2], GAUSS_POINTS)
        c, s = np.cos(th), np.sin(th)
        c_f = self.linear.chip_per_tooth_m(feed_m_per_s)
        h = self.chips_m(c_f, np.broadcast_to(c[:, None], (len(c), self.cutter.n_teeth)))  # (points, teeth)
        Ft, Fr, Fa = (f.sum(axis=1) * wt for f in self.chip_forces(h, np.broadcast_to(dep[:, None], h.shape),
                                                                    cut_length_m))
        R = self.cutter.radius_m
        fu = -Ft @ s - Fr @ c
        fv = Ft @ c - Fr @ s
        fz = Fa.sum()
        w = np.array([fu, fv, fz, R * (Fa @ s), -R * (Fa @ c), R * Ft.sum()]) / (2 * np.pi)
        return self._to_base(w, u0, u1)
