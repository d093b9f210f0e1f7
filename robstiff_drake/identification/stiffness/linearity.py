"""What repeated measurements at paired loads say without joint angles:
linearity in load, the offset at zero load that a line through the origin
misses, and repeatability.  Used on the paper's Table 2.  Plain numpy + scipy.

Per pose group (rows that share a pose and a load direction), for each
displacement component d against the load magnitude |F|:
  * a line through the origin, d = s0 |F|, is the conventional model;
  * a line with an intercept, d = s |F| + d0: d0 is the offset at zero load
    (what lost motion, friction or a softer first part of the load curve
    would leave); a nested F-test says whether it is significant;
  * the ratio of the mean displacement at the higher load to that at the
    lower, against the load ratio (2.0 for 360 N / 180 N if linear);
  * repeatability: the pooled standard deviation of repeated measurements
    at the same load.
"""

from dataclasses import dataclass

import numpy as np
from scipy import stats


@dataclass
class ComponentFit:
    slope0_mm_per_N: float  # through the origin
    slope_mm_per_N: float  # with intercept
    intercept_mm: float
    intercept_std_mm: float
    f_stat: float
    p_value: float
    load_ratio: float  # higher / lower load
    disp_ratio: float  # mean d at higher / at lower load
    rms_origin_mm: float
    rms_intercept_mm: float


@dataclass
class GroupResult:
    name: str
    rows: list
    direction: np.ndarray
    loads_N: np.ndarray
    repeatability_mm: np.ndarray  # (3,) pooled std per component
    n_repeat_dof: int
    components: list  # ComponentFit per component, or [] with a single load level
    compliance_um_per_N: np.ndarray  # (3,) d / |F| through the origin


def analyse_group(name, rows, force_N, disp_mm):
    F = np.asarray(force_N, dtype=float)
    D = np.asarray(disp_mm, dtype=float)
    mag = np.linalg.norm(F, axis=1)
    direction = F[0] / mag[0]
    levels = np.unique(np.round(mag, 6))
    # repeatability: deviations from the mean at each load level
    dev, dof = np.zeros(3), 0
    for lv in levels:
        sel = np.isclose(mag, lv)
        if sel.sum() > 1:
            dev += np.sum((D[sel] - D[sel].mean(axis=0)) ** 2, axis=0)
            dof += int(sel.sum()) - 1
    rep = np.sqrt(dev / dof) if dof > 0 else np.full(3, np.nan)
    comps = []
    if len(levels) >= 2:
        X1 = np.column_stack([mag, np.ones_like(mag)])
        n = len(mag)
        lo, hi = np.isclose(mag, levels[0]), np.isclose(mag, levels[-1])
        for i in range(3):
            d = D[:, i]
            s0 = float(mag @ d / (mag @ mag))
            r0 = d - s0 * mag
            coef, *_ = np.linalg.lstsq(X1, d, rcond=None)
            r1 = d - X1 @ coef
            rss0, rss1 = float(r0 @ r0), float(r1 @ r1)
            dof1 = n - 2
            s2 = rss1 / dof1 if dof1 > 0 else np.nan
            cov = s2 * np.linalg.inv(X1.T @ X1)
            f = (rss0 - rss1) / s2 if s2 > 0 else np.inf
            p = float(stats.f.sf(f, 1, dof1)) if np.isfinite(f) else 0.0
            comps.append(ComponentFit(s0, float(coef[0]), float(coef[1]), float(np.sqrt(cov[1, 1])), float(f), p,
                                      float(levels[-1] / levels[0]), float(d[hi].mean() / d[lo].mean()),
                                      float(np.sqrt(rss0 / n)), float(np.sqrt(rss1 / n))))
    compliance = (D.T @ mag / (mag @ mag)) * 1e3
    return GroupResult(name, list(rows), direction, levels, rep, dof, comps, compliance)


def pooled_offset(groups, force_by_group, disp_by_group):
    """Fit d_par = s_g |F| + d0_g per group; return per-group (d0, std) and the
    inverse-variance pooled offset, its std and the two-sided p-value."""
    per = {}
    for g in groups:
        F = force_by_group[g.name]
        D = disp_by_group[g.name]
        mag = np.linalg.norm(F, axis=1)
        u = F / mag[:, None]
        d_par = np.sum(D * u, axis=1)
        X = np.column_stack([mag, np.ones_like(mag)])
        coef, *_ = np.linalg.lstsq(X, d_par, rcond=None)
        r = d_par - X @ coef
        s2 = r @ r / (len(mag) - 2)
        std = float(np.sqrt(s2 * np.linalg.inv(X.T @ X)[1, 1]))
        per[g.name] = (float(coef[1]), std)
    w = np.array([1.0 / s**2 for _, s in per.values()])
    d0 = np.array([v for v, _ in per.values()])
    pooled = float(np.sum(w * d0) / np.sum(w))
    pooled_std = float(1.0 / np.sqrt(np.sum(w)))
    p = float(2 * stats.norm.sf(abs(pooled) / pooled_std))
    return per, pooled, pooled_std, p


CARTESIAN_EXTENSIONS = ("lost_motion", "load_dependent_stiffness", "drift")


def cartesian_diagnosis(rows, force_N, disp_mm):
    """The residual diagnosis as far as data without joint angles allow: at
    one pose and load direction, the six-spring model is d = s |F| per
    component (a line through the origin); the extensions that can show are
    a constant offset along the load's sign (lost motion), a term in |F|^2
    (load-dependent stiffness) and a term in measurement order (drift).
    Returns, per extension and for the base, the leave-one-out RMS (mm) over
    all components, the fit RMS, and the nested F-test against the base."""
    F = np.asarray(force_N, dtype=float)
    D = np.asarray(disp_mm, dtype=float)
    mag = np.linalg.norm(F, axis=1)
    order = np.asarray(rows, dtype=float)
    designs = {
        "base (line through 0)": [mag],
        "lost_motion": [mag, np.sign(F @ F[0]) * 1.0],
        "load_dependent_stiffness": [mag, mag**2],
        "drift": [mag, order],
    }
    n = len(mag)
    out = {}
    base_rss = None
    for name, cols in designs.items():
        X = np.column_stack(cols)
        rss, loo = 0.0, 0.0
        for k in range(3):
            coef, *_ = np.linalg.lstsq(X, D[:, k], rcond=None)
            r = D[:, k] - X @ coef
            rss += float(r @ r)
            H = X @ np.linalg.pinv(X)
            loo += float(np.sum((r / np.maximum(1 - np.diag(H), 1e-12)) ** 2))
        entry = {"loo_rms_mm": float(np.sqrt(loo / (3 * n))), "fit_rms_mm": float(np.sqrt(rss / (3 * n))),
                 "rank": int(np.linalg.matrix_rank(X))}
        if base_rss is None:
            base_rss, base_p = rss, X.shape[1]
        else:
            p_e = 3 * (entry["rank"] - base_p)
            df2 = 3 * (n - entry["rank"])
            if p_e > 0 and df2 > 0 and rss > 0:
                f = ((base_rss - rss) / p_e) / (rss / df2)
                entry.update(f_stat=float(f), p_value=float(stats.f.sf(f, p_e, df2)))
        out[name] = entry
    return out
