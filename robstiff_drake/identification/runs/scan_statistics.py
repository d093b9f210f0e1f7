"""Statistics of a measured surface scan that hold for a milled face: its
noise floor, its effective number of independent points, and its
surface-error figures.  Plain numpy; no Drake.

Scan lines run along x, along y or along the machined path; positions
along them are distances from point to point (``along_mm``).

* Noise floor.  The scanner's noise is independent from point to point,
  while the face a 75 mm cutter leaves changes over tens of millimetres: the
  second difference of neighbouring points (0.5 mm apart) holds the noise
  (variance 6 sigma^2) and almost nothing of the face (a 0.1 mm change over
  10 mm gives 0.25 um).  sigma = 1.4826 MAD / sqrt(6), robust to the few
  kinks where the cutter's envelope turns.

* Effective number of independent points.  Residuals that are the scanner's
  noise are independent; residuals a model cannot follow (the arm's
  dynamics, an effect it lacks) are correlated over up to the cutter's
  diameter (each point of the face is the lowest the cutter went while it
  covered the point).  n_eff = n / tau with tau = 1 + 2 sum_k rho_k, the
  residual's integrated autocorrelation along the scan (summed while rho_k
  stays positive, Geyer's initial positive sequence), and never fewer than
  the scan's length over the cutter's diameter (the number of cutter
  footprints that fit along it).  Every test uses n_eff, not n.
"""

import numpy as np
from scipy import stats

MAD_TO_SIGMA = 1.4826
GAP_FACTOR = 3.0  # a step in x over 3x the scan's spacing starts a new segment


def along_mm(x_mm, y_mm):
    """Distance (mm) along the scan from its first point, point to point in
    the file's order."""
    x, y = np.asarray(x_mm, dtype=float), np.asarray(y_mm, dtype=float)
    return np.concatenate([[0.0], np.cumsum(np.hypot(np.diff(x), np.diff(y)))]) if x.size else np.zeros(0)


def segments(x_mm, y_mm):
    """Index arrays of the scan's contiguous pieces, in the file's order: a
    new piece starts where the step to the next point is over GAP_FACTOR x
    the scan's spacing (a gap: no material, a missing reading, the next
    line) or turns back (a line scanned the other way).  Lines along x, along
    y or along a path alike."""
    x, y = np.asarray(x_mm, dtype=float), np.asarray(y_mm, dtype=float)
    if x.size < 2:
        return [np.arange(x.size)]
    dx, dy = np.diff(x), np.diff(y)
    d = np.hypot(dx, dy)
    step = np.median(d[d > 0]) if np.any(d > 0) else 1.0
    gap = d > GAP_FACTOR * step
    cut = gap.copy()
    # a step that turns back against the one before it (neither of them a gap) starts a new piece
    cut[1:] |= ((dx[1:] * dx[:-1] + dy[1:] * dy[:-1]) < 0) & ~gap[1:] & ~gap[:-1]
    return np.split(np.arange(x.size), np.flatnonzero(cut) + 1)


def scan_length_mm(x_mm, y_mm, segs):
    """The scan's length (mm): the sum of its segments' lengths."""
    s = along_mm(x_mm, y_mm)
    return float(sum(np.ptp(s[g]) for g in segs if g.size > 1))


def noise_from_scan(error_mm, segs):
    """The scan's noise, 1 sigma (mm), from the second differences of
    neighbouring points within each segment (see the module docstring);
    None when fewer than 10 second differences exist."""
    e = np.asarray(error_mm, dtype=float)
    d2 = np.concatenate([e[s][:-2] - 2 * e[s][1:-1] + e[s][2:] for s in segs if s.size >= 3] or [np.zeros(0)])
    if d2.size < 10:
        return None
    return float(MAD_TO_SIGMA * np.median(np.abs(d2 - np.median(d2))) / np.sqrt(6.0))


def integrated_autocorrelation(residual, segs):
    """tau = 1 + 2 sum_k rho_k of ``residual`` along the scan (lags within
    segments only), summed while rho_k > 0."""
    r = np.asarray(residual, dtype=float)
    pieces = [r[s] for s in segs if s.size > 1]
    total = float(sum(p @ p for p in pieces))
    if total <= 0:
        return 1.0
    tau = 1.0
    for k in range(1, max(p.size for p in pieces) if pieces else 1):
        rho = sum(float(p[:-k] @ p[k:]) for p in pieces if p.size > k) / total
        if rho <= 0:
            break
        tau += 2.0 * rho
    return tau


def effective_points(residual, segs, length_mm, cutter_diameter_mm):
    """(n_eff, tau): the number of independent points of ``residual`` (see the
    module docstring), between length / cutter diameter and n."""
    n = int(np.asarray(residual).size)
    tau = integrated_autocorrelation(residual, segs)
    floor = max(length_mm / cutter_diameter_mm, 1.0)
    return float(min(max(n / tau, floor), n)), float(tau)


def f_test(rss_small, rss_big, p_added, k_big, n, n_eff):
    """(F, p) of a nested test with correlated residuals: the classical F
    scaled by n_eff / n (the added columns, smooth along the scan, see the
    noise with its variance inflated by tau = n / n_eff), on (p_added,
    n_eff - k_big) degrees of freedom.  p = 1 when n_eff <= k_big (too few
    independent points to test)."""
    df2 = n_eff - k_big
    if p_added <= 0 or df2 <= 0:
        return 0.0, 1.0
    if rss_big <= 0:
        return (np.inf, 0.0) if rss_small > 0 else (0.0, 1.0)
    F = max(rss_small - rss_big, 0.0) / p_added / (rss_big / (n - k_big)) * n_eff / n
    return float(F), float(stats.f.sf(F, p_added, df2))


def consistent_with_floor(residual_mm, floor_mm, n_eff, alpha=0.01):
    """Whether the residual's mean square is what noise of 1 sigma
    ``floor_mm`` gives: rms^2 / floor^2 <= chi2(1 - alpha, n_eff) / n_eff."""
    r = np.asarray(residual_mm, dtype=float)
    ms = float(np.mean(r**2))
    return bool(ms <= floor_mm**2 * stats.chi2.ppf(1.0 - alpha, n_eff) / n_eff)


def surface_stats(x_mm, y_mm, error_mm, segs, cutter_diameter_mm):
    """mean, rms, max_abs, pv (mm) of a measured surface error, and the
    largest |error| near the ends of each segment (``edges_max_abs``:
    within the cutter's radius, at most a third of the segment, of either
    end, measured along it: where the engagement changes) and in between
    (``steady_max_abs``)."""
    s, e = along_mm(x_mm, y_mm), np.asarray(error_mm, dtype=float)
    edge = np.zeros(e.size, dtype=bool)
    for g in segs:
        if g.size == 0:
            continue
        sg = s[g]
        zone = min(cutter_diameter_mm / 2.0, np.ptp(sg) / 3.0)
        edge[g] = (sg - sg.min() <= zone) | (sg.max() - sg <= zone)
    out = {"mean": float(e.mean()), "rms": float(np.sqrt(np.mean(e**2))), "max_abs": float(np.max(np.abs(e))),
           "pv": float(np.ptp(e)), "n_points": int(e.size)}
    out["edges_max_abs"] = float(np.max(np.abs(e[edge]))) if edge.any() else 0.0
    out["steady_max_abs"] = float(np.max(np.abs(e[~edge]))) if (~edge).any() else 0.0
    return out


def mean_square_difference(e_a_mm, e_b_mm, floor_mm):
    """(difference of mean squares b - a (mm^2), its standard error from the
    scan noise alone (mm^2)).  Two cuts of the same pass differ, apart from
    their settings, by the scanner's noise: mean(e^2) of a face s plus noise
    of sigma has variance (4 mean(s^2) sigma^2 + 2 sigma^4) / n."""
    out = []
    for e in (np.asarray(e_a_mm, dtype=float), np.asarray(e_b_mm, dtype=float)):
        ms = float(np.mean(e**2))
        s2 = max(ms - floor_mm**2, 0.0)
        out.append((ms, (4.0 * s2 * floor_mm**2 + 2.0 * floor_mm**4) / e.size))
    (ms_a, v_a), (ms_b, v_b) = out
    return ms_b - ms_a, float(np.sqrt(v_a + v_b))
