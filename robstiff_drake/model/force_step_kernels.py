"""The milling force's update (systems/milling_force.py) as compiled
kernels (model/jit.py), for a path of straight lines: where along its path
the tool is and its progress over the chip's window (``line_motion``: the
source's ``motion`` with PlannedPath.project), and, in the
revolution-averaged mode on the plant's cutting law, the whole update in
one call (``averaged_force_step``: the tool's pose, the motion, the
smoothed feed, the worn edge coefficients, the averaged wrench and the
cutting travel).

The same scalar operations in the same order as the plain-Python
references they replace (MillingForceSource.motion, smoothed_feed and
_step, PlannedPath.project and _element, PlantCuttingLaw.edge_coefficients
and average_wrench), so the compiled results equal them to round-off
(tests/test_force_step_kernels.py).  Python's ``min`` and ``max`` are
written out (``max(a, b)``: b if b > a else a) so that a NaN goes where
Python's goes.  Without numba the callers keep those references.

Constant packing (float64 arrays): ``lines`` ((n, 10), ``line_constants``):
per element its start point (3, m), unit direction (3), length (m), the
horizontal feed direction (2, ``PlannedPath.feed_direction_at``) and the
horizontal slope (hypot of the direction's x and y: ``tangent_at``'s);
``knots`` (n + 1): the elements' start arc lengths and the path's length
(m); ``law`` (LAW_SIZE, ``law_constants``): the tooth pass frequency (Hz),
h_ref^(1 - e), the chip exponent e, the edge ramp's chip (m), the cutter's
radius (m), the wear land's friction and normal stress (N/m^2), the flank
wear at the start (m) and its growth per metre of travel.  The milling
force's per-tick update (``averaged_force_update``) takes all of these
packed in one float64 array and their offsets in one int64 array
(``pack_force_constants``): numba's dispatcher costs about 0.05 us per
argument and call.
"""

import math

import numpy as np

from robstiff_drake.model.cutting_kernels import average_wrench_at
from robstiff_drake.model.jit import kernel
from robstiff_drake.model.tick_kernels import pose_and_deflection

LAW_SIZE = 9
MAX_STEP_M = 0.005  # (PlannedPath.project's defaults)
ITERATIONS = 4


def line_constants(path):
    """(lines, knots) of a model/path.PlannedPath (see the module
    docstring), or None when an element is not a straight line."""
    from robstiff_drake.model.path_elements import Line
    if any(type(e) is not Line for e in path.elements):
        return None
    rows = []
    for i, e in enumerate(path.elements):
        d = path._elem_dirs[i]  # (feed_direction_at on a line)
        tg = e.tangent(0.0)  # (tangent_at on a line)
        rows.append(list(e.p0_xyz) + list(e.u_xyz) + [e.length, float(d[0]), float(d[1]),
                                                       math.hypot(tg[0], tg[1])])
    return np.array(rows, dtype=float).reshape(-1, 10), np.array(path._s_knots, dtype=float)


def law_constants(law):
    """``law`` of a model/plant_cutting.PlantCuttingLaw (see the module docstring)."""
    h_scale, e, ramp, _Kc = law._constants()
    p = law.physics
    return np.array([law.cutter.tooth_pass_hz, h_scale, e, ramp, law.cutter.radius_m, p.land_friction,
                     p.land_stress_N_per_m2, p.flank_wear_m, p.flank_wear_per_m], dtype=float)


@kernel
def element_at(s, knots, n):
    """The element of a path of n at arc length s (m): bisect_right in
    ``knots`` minus one, clamped to 0..n-1 (PlannedPath._element)."""
    lo, hi = 0, n + 1
    while lo < hi:
        mid = (lo + hi) // 2
        if s < knots[mid]:
            hi = mid
        else:
            lo = mid + 1
    i = lo - 1
    i = 0 if 0 > i else i
    return n - 1 if n - 1 < i else i


@kernel
def line_motion(t, px, py, pz, hist, window_s, lines, knots, hist_out):
    """MillingForceSource.motion for a path of lines, the history's last
    update known (not NaN): writes the history with (t, s, 0) added to
    ``hist_out`` and returns (u_x, u_y, horizontal feed m/s)."""
    m = hist.shape[0]
    n = lines.shape[0]
    total = knots[n]
    # PlannedPath.project from the last update's s
    s = hist[m - 2]
    s = 0.0 if 0.0 > s else s
    s = total if total < s else s
    for _ in range(ITERATIONS):
        i = element_at(s, knots, n)
        ls = s - knots[i]
        ls = 0.0 if 0.0 > ls else ls
        ls = lines[i, 6] if lines[i, 6] < ls else ls
        T0, T1, T2 = lines[i, 3], lines[i, 4], lines[i, 5]
        P0, P1, P2 = lines[i, 0] + T0 * ls, lines[i, 1] + T1 * ls, lines[i, 2] + T2 * ls
        step = (px - P0) * T0 + (py - P1) * T1 + (pz - P2) * T2
        step = -MAX_STEP_M if -MAX_STEP_M > step else step
        step = MAX_STEP_M if MAX_STEP_M < step else step
        s = s + step
        s = 0.0 if 0.0 > s else s
        s = total if total < s else s
        if abs(step) < 1e-9:
            break
    for j in range(m - 3):
        hist_out[j] = hist[j + 3]
    hist_out[m - 3], hist_out[m - 2], hist_out[m - 1] = t, s, 0.0
    h = hist_out
    first = 0
    while math.isnan(h[first]):
        first += 3
    t0 = t - window_s
    if m - first < 6 or h[first] >= t0:
        ref_t, ref_s = h[first], h[first + 1]
    else:
        j = first + 3
        while h[j] < t0:
            j += 3
        a_t, a_s, b_t, b_s = h[j - 3], h[j - 2], h[j], h[j + 1]
        f = (t0 - a_t) / (b_t - a_t)
        ref_t, ref_s = a_t + f * (b_t - a_t), a_s + f * (b_s - a_s)
    span = t - ref_t
    rate = (s - ref_s) / span if span > 0 else 0.0
    i = element_at(s, knots, n)
    rate = 0.0 if 0.0 > rate else rate
    return lines[i, 7], lines[i, 8], rate * lines[i, 9]


@kernel
def averaged_force_step(q, t, hist, process, chain, window_s, lines, knots, feed_gain, period_s, law, Kc, Ke,
                        boxes, k_back, dR, gauss_x, gauss_w, out):
    """MillingForceSource._step in the averaged mode on the plant's law
    (PlantCuttingLaw), a path of lines, the history's last update known:
    ``q`` (6, rad), ``process`` (u_x, u_y, feed m/s, travel m, held),
    ``hist`` (3 n, see ``motion``), ``Kc``, ``Ke`` (3: the law's cutting
    and unworn edge coefficients), ``boxes`` (PlantCuttingLaw._boxes),
    ``k_back``, ``dR`` (its runout chip's), ``gauss_x``, ``gauss_w`` (its
    Gauss-Legendre nodes).  Writes the wrench (6, base frame, at the tool
    point) to ``out[:6]``, the new process state to ``out[6:10]``, the
    tool's pose (the flange rotation, row-major 9, and the tool point 3, m,
    base frame) to ``out[10:22]`` and the new history to ``out[22:]``."""
    none = np.empty(0)
    pose = out[10:22]
    pose_and_deflection(q, chain, none, none, none, pose)
    px, py, pz = pose[9], pose[10], pose[11]
    u0, u1, feed = line_motion(t, px, py, pz, hist, window_s, lines, knots, out[22:])
    feed_held, travel = process[2], process[3]
    feed = feed_held + feed_gain * (feed - feed_held)  # (smoothed_feed)
    # the worn edge (PlantCuttingLaw.edge_coefficients)
    dKr = law[6] * (law[7] + law[8] * (0.0 if 0.0 > travel else travel))
    Ke_w = np.empty(3)
    Ke_w[0], Ke_w[1], Ke_w[2] = Ke[0] + law[5] * dKr, Ke[1] + dKr, Ke[2] + 0.5 * dKr
    w = average_wrench_at(px, py, pz, u0, u1, boxes, feed / law[0], law[1], law[2], law[3], Kc, Ke_w, law[4],
                          k_back, dR, gauss_x, gauss_w)
    if w[0] != 0.0 or w[1] != 0.0 or w[2] != 0.0:  # in the material: the edges travel (their wear's clock)
        travel += feed * period_s
    for i in range(6):
        out[i] = w[i]
    out[6], out[7], out[8], out[9] = u0, u1, feed, travel


# ``averaged_force_update``'s offsets (int64, ``pack_force_constants``): where each of the FORCE_PIECES packed
# constants (averaged_force_step's, from ``chain`` to ``gauss_w``) starts and where the last ends, then the path's
# lines, the workpiece's boxes and the cutter's teeth (rows of ``lines``, ``boxes`` and ``dR``)
FORCE_PIECES = 14
FORCE_OFFSETS_SIZE = FORCE_PIECES + 4


def pack_force_constants(chain, window_s, lines, knots, feed_gain, period_s, law, Kc, Ke, boxes, k_back, dR,
                         gauss_x, gauss_w):
    """(consts, offsets) for ``averaged_force_update``: averaged_force_step's
    constants (arrays row-major, floats as one value each) in one float64
    array, in its order, and their int64 offsets (FORCE_OFFSETS_SIZE, see
    above).  Built once: two arguments in place of fourteen, each of which
    costs numba's dispatcher its type's look-up at every call."""
    lines, boxes, dR = (np.asarray(v, dtype=float) for v in (lines, boxes, dR))
    if lines.shape[1:] != (10,) or boxes.shape[1:] != (5,) or dR.shape != (dR.shape[0],) * 2:
        raise ValueError(f"lines (n, 10), boxes (B, 5) and dR (n, n): got {lines.shape}, {boxes.shape}, {dR.shape}")
    pieces = [np.ravel(np.asarray(v, dtype=float)) for v in (chain, window_s, lines, knots, feed_gain, period_s, law,
                                                              Kc, Ke, boxes, k_back, dR, gauss_x, gauss_w)]
    starts = np.cumsum([0] + [len(v) for v in pieces])
    offsets = np.concatenate((starts, [lines.shape[0], boxes.shape[0], dR.shape[0]])).astype(np.int64)
    return np.concatenate(pieces), offsets


@kernel
def averaged_force_update(q, t, held, wrench, spatial, consts, at):
    """``averaged_force_step`` on the milling force's held state, written
    in place (systems/milling_force.MillingForceSource's update), its
    constants packed in ``consts`` and ``at`` (``pack_force_constants``):
    ``held`` (the process state, 4, then the history, 3 n) overwritten with
    the new ones, the wrench (6, base frame, at the tool point) written to
    ``wrench`` and, as Drake's SpatialForce orders it (the moment, then the
    force), to ``spatial`` (6)."""
    chain, window_s = consts[at[0]:at[1]], consts[at[1]]
    lines, knots = consts[at[2]:at[3]].reshape((at[FORCE_PIECES + 1], 10)), consts[at[3]:at[4]]
    feed_gain, period_s, law = consts[at[4]], consts[at[5]], consts[at[6]:at[7]]
    Kc, Ke, boxes = consts[at[7]:at[8]], consts[at[8]:at[9]], consts[at[9]:at[10]].reshape((at[FORCE_PIECES + 2], 5))
    n_teeth = at[FORCE_PIECES + 3]
    k_back, dR = consts[at[10]:at[11]], consts[at[11]:at[12]].reshape((n_teeth, n_teeth))
    gauss_x, gauss_w = consts[at[12]:at[13]], consts[at[13]:at[14]]
    n = held.shape[0]
    out = np.empty(n + 18)  # (22 + the history's 3 n)
    averaged_force_step(q, t, held[4:], held[:4], chain, window_s, lines, knots, feed_gain, period_s, law, Kc, Ke,
                        boxes, k_back, dR, gauss_x, gauss_w, out)
    for i in range(4):
        held[i] = out[6 + i]
    for i in range(n - 4):
        held[4 + i] = out[22 + i]
    for i in range(6):
        wrench[i] = out[i]
    for i in range(3):
        spatial[i], spatial[3 + i] = out[3 + i], out[i]
