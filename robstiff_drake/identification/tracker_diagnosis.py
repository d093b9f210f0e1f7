"""Diagnosis of an absolute-position (laser tracker) campaign: what the
robot file's nominal arm gets wrong, traced to named effects, with the
accuracy a tracker user reports (mean, rms, max of the 3D error, held out).
Plain numpy + scipy; no Drake.

1. Units and frame: positions without a unit in the header are told from
   the arm's reach (tracker_campaign.position_scale); points on one line,
   fewer than 4 poses, or a registration that leaves more than
   MAX_REGISTRATION_MM (another arm, other angles) are refused.
2. The declared model: the nominal arm, the instrument's registration
   (closed form, then Gauss-Newton) and the measured point on the flange.
3. Identifiability: of the chain's parameters (theta, d, a, alpha; beta
   between nearly parallel axes), those whose columns of the identification
   Jacobian add rank to the registration's, the measured point's and the
   ones kept before them (as kinematic calibration does); a block of another
   effect that adds less than its rank is not tried, with the reason.
4. Search: forward steps over the effects of tracker_terms.py on 5
   pose-grouped folds (linearised at the declared fit, fold Gram matrices):
   an effect is added when it lowers the held-out RMS by MIN_GAIN, passes a
   pose-clustered Wald test at ALPHA / (effects tried in the round), is of
   physical size (tracker_terms' ranges, its 95 % interval reaching them is
   enough) and keeps every joint's compliance positive; one that fits but
   is not physical or plausible is a lead.  A backward check drops what no
   longer earns its place.
5. The final model by Gauss-Newton on all rows (a gross-error screen, then
   once more without the flagged rows); held-out errors by Gauss-Newton in
   each fold from its training rows only, before (registration and measured
   point on the nominal arm) and after.
6. What is left: a non-parametric joint-space map (residual_map.py), kept
   only if it generalises (held out, nested).
7. The verdict against the noise floor (stated, or from repeated poses),
   confounded effects (correlation of the estimates), and with a second file
   the validation: its 3D errors under the fitted model and registration,
   and with the registration refitted to it.
"""

from dataclasses import dataclass, field

import numpy as np
from scipy import stats

from robstiff_drake.errors import InputError
from robstiff_drake.identification import noise_floor as nf
from robstiff_drake.identification import residual_map as rmap
from robstiff_drake.identification.confounding import CONFOUNDED_MIN, confounded_pairs
from robstiff_drake.identification.cross_validation import FOLD_SEED, K_FOLDS, pose_groups, splits, wald_p
from robstiff_drake.identification.registration import check_geometry, register
from robstiff_drake.identification.threads import single_blas_thread
from robstiff_drake.identification.tracker_campaign import position_scale
from robstiff_drake.identification.tracker_fit import Fit, LinearCV, Problem, independent_columns, rows_to_eq
from robstiff_drake.identification.tracker_model import GEOM, geometry_jacobian, geometry_params, gravity_in_base
from robstiff_drake.identification.tracker_terms import blocks as all_blocks
from robstiff_drake.model import kinematics as kin
from robstiff_drake.progress import progress

MAX_REGISTRATION_MM = 25.0  # 3D RMS left by registration on the nominal arm: beyond, another arm or other angles
WARN_REGISTRATION_MM = 10.0
# An effect must lower the held-out RMS by this much (thousands of rows make a
# 2 % gain certain; the Wald test and the held-out folds guard against overfitting)
MIN_GAIN = 0.02
MIN_KEEP_GAIN = 0.01
ALPHA = 0.01
OUTLIER_SIGMAS = 6.0
MIN_ROWS_FOR_MAP = 200


def stats3d(e):
    """{mean, rms, max} of 3D error lengths (mm) of e (n, 3) mm."""
    L = np.linalg.norm(e, axis=1)
    return {"mean": float(L.mean()), "rms": float(np.sqrt(np.mean(L**2))), "max": float(L.max())}


@dataclass
class TrackerDiagnosis:
    report: dict  # the JSON
    fit: Fit = None
    problem: Problem = None
    robot: object = None
    warnings: list = field(default_factory=list)


def _tool_guess_m(campaign, robot, tool_m):
    if tool_m is not None:
        return np.asarray(tool_m, float)
    if campaign.tool_mm is not None:
        return np.asarray(campaign.tool_mm, float) / 1e3
    return robot.payload.tool_point_m if robot.payload.tool_point_m is not None else np.zeros(3)


def _declared_fit(problem, robot, rows, guess):
    T = kin.frames(robot.dh, problem.q[rows])
    R, t, u = register(T[:, 6, :3, 3], T[:, 6, :3, :3], problem.m[rows], guess)
    fit = Fit(R, t, u, np.zeros((6, 5)))
    return problem.gauss_newton(fit, [], rows)


def _rms3d(problem, fit, rows):
    e = problem.m[rows] - problem.predict(fit, rows)
    return float(np.sqrt(np.mean(np.sum(e**2, axis=1)))) * 1e3


def _check_angles(campaign, robot, problem, rows, guess, rms_deg, w):
    """Angles that all lie within +-pi and register 3x better read as radians are radians."""
    if np.max(np.abs(campaign.q_deg)) > np.pi + 1e-9 or "q1" in campaign.units:
        return
    alt = Problem(robot, np.rad2deg(campaign.q_deg), problem.m)
    try:
        rms_rad = _rms3d(alt, _declared_fit(alt, robot, rows, guess), rows)
    except InputError:
        return
    if rms_rad * 3 < rms_deg:
        raise InputError(f"{campaign.path}: joint angles q1..q6 look like radians, not degrees: every angle is within "
                         f"+-pi, and read as radians the registration leaves {rms_rad:.3g} mm RMS against "
                         f"{rms_deg:.3g} mm as degrees; write the controller's degrees or name the unit (q1 [rad])")


def _identifiable(problem, fit, rows, robot):
    """(geometry kept [(link, kind)], not identifiable [(link, kind)]) by the greedy rank test."""
    ev, dh = problem.evaluate(fit, rows)
    X, _, _ = problem.columns(fit, [], rows)
    Jg = geometry_jacobian(ev.T, ev.p, dh)
    cand = geometry_params(robot)
    order = sorted(range(len(cand)), key=lambda i: (GEOM.index(cand[i][1]), cand[i][0]))
    Z = np.stack([np.einsum("ij,nj->ni", fit.R, Jg[:, :, k, GEOM.index(kind)]) for k, kind in cand], axis=-1)
    allX = np.hstack([X, Z.reshape(-1, len(cand))])
    kept = independent_columns(allX, list(range(9)) + [9 + i for i in order])
    free = [cand[i - 9] for i in kept if i >= 9]
    return free, [c for c in cand if c not in free], allX[:, kept]


def _candidate_blocks(problem, fit, rows, free, Xgeo):
    """The blocks the campaign can be searched for, their columns at the
    declared fit, and [(name, reason)] of those it cannot."""
    problem.geo_free = free
    ev, _ = problem.evaluate(fit, rows)
    out, skipped = [], []
    for b in all_blocks(ev, free):
        why = b.needs(ev) if b.needs else None
        if why:
            skipped.append({"name": b.name, "reason": why})
            continue
        X, sl, _ = problem.columns(fit, [b], rows)
        Z = X[:, sl[b.name]]
        if b.frame != "geometry":
            kept = independent_columns(np.hstack([Xgeo, Z]), list(range(Xgeo.shape[1] + Z.shape[1])))
            if len(kept) < Xgeo.shape[1] + Z.shape[1]:
                skipped.append({"name": b.name, "reason": "not identifiable: its columns add less than their rank to "
                                                          "the registration's, the measured point's and the geometry's"})
                continue
        out.append((b, Z))
    return out, skipped


def _checks(b, values, half, problem, ev_info):
    ok, why = b.plausible(values, ev_info)
    if not ok:
        smallest = np.sign(values) * np.maximum(np.abs(values) - half, 0.0)
        if b.plausible(smallest, ev_info)[0]:
            ok, why = True, why + ", but its 95 % interval reaches the physical range"
    physical = True
    if b.name == "joint_compliance":
        physical = bool(np.all(values > 0))
    return ok, why, physical


MAX_RESTARTS = 3


def _search(cv, base_cols, cands, info, pbar, kept_init=()):
    """Forward selection, then the backward check, over the candidate blocks.
    Forward steps judge a block by its fit only (held-out gain, clustered
    Wald test): before the arm's geometry is in, the sag or a transmission
    error absorbs part of the geometry's residual and would look
    non-physical; the backward check then drops whatever no longer earns its
    place or is implausible or non-physical at the model's final fit, and
    the forward search resumes without the implausible ones (they are
    leads).  Returns (kept, rounds, leads, dropped, declared RMS, final RMS
    (m, linearised), {name: columns})."""
    cols_of = {}
    i = len(base_cols)
    for b, Z in cands:
        cols_of[b.name] = np.arange(i, i + Z.shape[1])
        i += Z.shape[1]
    by_name = {b.name: b for b, _ in cands}
    kept, rounds, leads, dropped, banned = list(kept_init), [], {}, [], set()

    def cols(names):
        return np.concatenate([base_cols] + [cols_of[n] for n in names])

    def judge(names, name):
        c = cols(names)
        coef, cov, G = cv.fit(c)
        pos = np.arange(len(c) - len(cols_of[name]), len(c))  # the block's columns come last
        b = by_name[name]
        p = wald_p(coef, cov, pos, G)  # is it different from the declared model's value?
        half = stats.t.ppf(0.975, max(G - 1, 1)) * np.sqrt(np.maximum(np.diag(cov)[pos], 0))
        ok, why, physical = _checks(b, b.start + coef[pos], half, None, info)
        if not physical:
            why = (why + "; " if why else "") + "non-physical (a negative compliance)"
        return p, ok and physical, why

    current = cv.heldout_rms(cols(kept))
    rms_declared = current
    for _ in range(MAX_RESTARTS + 1):
        while True:
            pool = [b.name for b, _ in cands if b.name not in kept and b.name not in banned]
            if not pool:
                break
            results = []
            for name in pool:
                rms = cv.heldout_rms(cols(kept + [name]))
                r = {"name": name, "rms_mm": rms * 1e3, "p_grouped": None}
                if rms <= (1 - MIN_GAIN) * current:
                    r["p_grouped"] = judge(kept + [name], name)[0]
                results.append(r)
            rounds.append(results)
            if pbar is not None:
                pbar.update(1)
            fits = [r for r in results if r["p_grouped"] is not None and r["p_grouped"] < ALPHA / len(results)]
            if not fits:
                break
            best = min(fits, key=lambda r: r["rms_mm"])
            kept.append(best["name"])
            current = best["rms_mm"] / 1e3
        gone = []
        while kept:
            weak = []
            for name in kept:
                rest = [n for n in kept if n != name]
                gain = 1 - current / cv.heldout_rms(cols(rest))
                p, ok, why = judge(rest + [name], name)
                if not ok:
                    weak.append((0, -gain, name, why))
                elif gain < MIN_KEEP_GAIN or p > ALPHA / len(kept):
                    weak.append((1, gain, name, None))
            if not weak:
                break
            _, _, name, why = min(weak)
            kept.remove(name)
            dropped.append(name)
            if why is not None:  # implausible or non-physical at the final fit: a lead, not tried again
                gone.append(name)
                leads[name] = {"name": name, "rms_mm": current * 1e3, "plausibility": why, "round": len(rounds)}
            current = cv.heldout_rms(cols(kept))
        if not gone:
            break
        banned |= set(gone)
    for name in list(leads):  # a lead's own fit with the final model, for the report
        if name in kept:
            leads.pop(name)
            continue
        leads[name]["rms_mm"] = cv.heldout_rms(cols(kept + [name])) * 1e3
        leads[name]["plausibility"] = judge(kept + [name], name)[2] or leads[name]["plausibility"]
    # a lead matters only if it fits better than the final model
    out = [leads[n] for n in leads if leads[n]["rms_mm"] < current * 1e3]
    dropped = [n for n in dict.fromkeys(dropped) if n not in kept]
    return kept, rounds, sorted(out, key=lambda r: r["rms_mm"]), dropped, rms_declared, current, cols_of


def _values(fit, blocks):
    """{block: its parameters' values in ``fit``}."""
    out = {}
    for b in blocks:
        out[b.name] = (np.array([fit.geo[k, GEOM.index(kind)] for k, kind in b.geo]) if b.frame == "geometry"
                       else fit.coef[b.name])
    return out


def _linearised(problem, fit, cands, rows, tests, groups):
    """The search's LinearCV at ``fit``: the registration's and measured
    point's columns, then every candidate's (kept ones at their values)."""
    every = [b for b, _ in cands]
    fit_all = fit.copy()
    for b in every:
        if b.frame != "geometry" and b.name not in fit_all.coef:
            fit_all.coef[b.name] = np.full(len(b.params), b.start)
    fit_all.blocks = list(fit.blocks)
    X, sl, ev = problem.columns(fit_all, every, rows)
    r = (problem.m[rows] - problem.predict(fit, rows)).reshape(-1)
    # the kept blocks' parameters counted from the declared model's values, as in the first pass: the
    # target is the residual plus what they contribute, linearised here, so any subset of blocks can be fitted
    for name, v in _values(fit, fit.blocks).items():
        b = next(x for x in every if x.name == name)
        r = r + X[:, sl[name]] @ (v - b.start)
    order = [np.arange(9)] + [np.arange(sl[b.name].start, sl[b.name].stop) for b in every]
    cv = LinearCV(X[:, np.concatenate(order)], r, tests, np.repeat(groups[rows], 3))
    return cv, {"ev": ev, "c_nom": problem.c_nom}


def _heldout(problem, fit_all, blocks, folds, pbar=None):
    """Held-out residuals (N, 3) m (rows outside the folds' tests: NaN) by
    Gauss-Newton in each fold from the all-rows fit, and the fold fits."""
    e = np.full((problem.n, 3), np.nan)
    fits = []
    for train, test in folds:
        f = problem.gauss_newton(fit_all, blocks, train, iterations=4)
        e[test] = problem.m[test] - problem.predict(f, test)
        fits.append(f)
        if pbar is not None:
            pbar.update(1)
    return e, fits


def _residual_map(problem, fits, folds, e_after):
    """Held-out residuals with the non-parametric map (nested), per-fold
    means without/with it, and whether it generalises."""
    e_map = e_after.copy()
    per_fold = []
    for f, (train, test) in zip(fits, folds):
        train = train[rmap.subsample(len(train), rmap.MAX_ROWS)]
        ev_tr, _ = problem.evaluate(f, train)
        r_train = (problem.m[train] - problem.predict(f, train, ev_tr)) @ f.R  # base frame
        pick = rmap.subsample(len(train), rmap.CHOOSE_ROWS)
        H, ridge = rmap.choose(problem.q_ctrl[train][pick], ev_tr.Jv[pick], r_train[pick])
        mp = rmap.ResidualMap(H, ridge).fit(problem.q_ctrl[train], ev_tr.Jv, r_train)
        ev_te, _ = problem.evaluate(f, test)
        e_map[test] = e_after[test] - mp.predict(problem.q_ctrl[test], ev_te.Jv) @ f.R.T
        per_fold.append((float(np.mean(np.linalg.norm(e_after[test], axis=1))),
                         float(np.mean(np.linalg.norm(e_map[test], axis=1)))))
    return e_map, per_fold


def _floor(problem, groups, rows, noise_mm):
    """The floor: stated, or the pooled scatter of rows measured at one pose."""
    g = groups[rows]
    _, inv, counts = np.unique(g, return_inverse=True, return_counts=True)
    rep = None
    dof = int(np.sum(counts[counts > 1] - 1))
    if dof >= nf.MIN_REPLICATE_DOF:
        means = np.zeros((len(counts), 3))
        np.add.at(means, inv, problem.m[rows])
        means /= counts[:, None]
        dev = problem.m[rows] - means[inv]
        rep = float(np.sqrt(np.sum(dev**2) / (3 * dof))) * 1e3
    if noise_mm is not None:
        return nf.Floor(float(noise_mm), "stated", float(noise_mm), rep, dof, int(np.sum(counts > 1)))
    if rep is not None:
        return nf.Floor(rep, "replicates", None, rep, dof, int(np.sum(counts > 1)))
    return nf.Floor(None, None, None, None, dof, 0)


def _screen(problem, fit, rows, floor_m):
    """Rows whose 3D residual is gross (chi-square(3) at 0.01 / N and
    OUTLIER_SIGMAS robust sigma, never below the floor)."""
    from robstiff_drake.identification.robust_fit import robust_scale, threshold

    e = problem.m[rows] - problem.predict(fit, rows)
    L = np.linalg.norm(e, axis=1)
    s = robust_scale(L)
    if floor_m is not None:
        s = max(s, floor_m)
    if s == 0:
        return np.array([], dtype=int)
    return rows[L**2 / s**2 > max(threshold(len(L)), OUTLIER_SIGMAS**2)]


def _term_reports(problem, fit, kept_blocks, rows, groups):
    """Each kept effect in words, with its parameters, 95 % intervals
    (pose-clustered) and plausibility, at the final fit."""
    X, slices, ev = problem.columns(fit, kept_blocks, rows)
    r = (problem.m[rows] - problem.predict(fit, rows, ev)).reshape(-1)
    cv = LinearCV(X, r, [np.arange(len(r))], np.repeat(groups[rows], 3))
    _, cov, G = cv.fit(np.arange(X.shape[1]))
    half = stats.t.ppf(0.975, max(G - 1, 1)) * np.sqrt(np.maximum(np.diag(cov), 0))
    info = {"ev": ev, "c_nom": problem.c_nom}
    out = []
    for b in kept_blocks:
        sl = slices[b.name]
        v = np.array([fit.geo[k, GEOM.index(kind)] for k, kind in b.geo]) if b.frame == "geometry" \
            else fit.coef[b.name]
        ok, why, physical = _checks(b, v, half[sl], problem, info)
        out.append({"name": b.name, "kind": b.kind, "description": b.describe(v, info),
                    "params": {f"{lab} ({u})": float(x * s) for (lab, u, s), x in zip(b.params, v)},
                    "ci95": {f"{lab} ({u})": [float((x - h) * s), float((x + h) * s)]
                             for (lab, u, s), x, h in zip(b.params, v, half[sl])},
                    "plausible": bool(ok and physical), "plausibility": why})
    return out, X, slices


def _verdict(floor, lof, rms_after_mm, trends, leads, unexplained):
    if floor.sigma_mm is None:
        return None, ("no verdict: no noise floor is known (state the instrument's noise per component with "
                      "--noise-mm, or measure some poses twice); the accuracy figures above stand")
    text = (f"held-out RMS {rms_after_mm:.4f} mm per component against a floor of {floor.sigma_mm:.4f} mm "
            f"({floor.source}); lack-of-fit p = {lof.p_value:.2g}")
    if lof.p_value < nf.ALPHA_LACK_OF_FIT:
        lead = ""
        if leads:
            lead = (f"; {leads[0]['name']} would fit more of it (held-out {leads[0]['rms_mm']:.4f} mm) but was not "
                    f"added: {leads[0]['plausibility']}")
        trend = (f"; {', '.join(trends)} (a trend along the file's order, no t_s or seq) was taken out, not as a "
                 "cause" if trends else "")
        return False, (f"the final model does NOT explain the data: {text}; {unexplained:.4f} mm unexplained" + lead
                       + trend)
    if trends:
        return False, (f"not established: {text}, reached only with {', '.join(trends)}: the file has neither t_s nor "
                       "seq, so its order is not known to be the order of measurement; add the time of each row")
    return True, f"the final model explains the data as far as the noise allows: {text}"


def _prepare(robot, campaign, tool_m, w):
    """Units, frame checks and the declared fit: (problem, fit, guess)."""
    guess = _tool_guess_m(campaign, robot, tool_m)
    q = robot.joint_rad(campaign.q_deg)
    nominal_mm = kin.tool_position(robot.dh, q, guess) * 1e3
    unit = position_scale(campaign, nominal_mm)
    if "x" in campaign.units:
        w.add(f"{campaign.path}: positions read in {campaign.units['x']} (from the header) and converted to mm")
    check_geometry(campaign.path, campaign.pos * unit)
    problem = Problem(robot, campaign.q_deg, campaign.pos * unit / 1e3, force_N=campaign.force_N, t_s=campaign.t_s,
                      temp_c=campaign.temp_c, seq=campaign.seq, tool_guess_m=guess)
    rows = np.arange(problem.n)
    fit = _declared_fit(problem, robot, rows, guess)
    problem.set_gravity(gravity_in_base(fit.R))
    rms = _rms3d(problem, fit, rows)
    _check_angles(campaign, robot, problem, rows, guess, rms, w)
    if rms > MAX_REGISTRATION_MM:
        raise InputError(f"{campaign.path}: registered to {robot.name}'s nominal arm ({robot.source}) the points are "
                         f"{rms:.4g} mm RMS off: the robot file does not describe this arm, or q1..q6 are not its "
                         f"controller's angles (refused above {MAX_REGISTRATION_MM:g} mm)")
    if rms > WARN_REGISTRATION_MM:
        w.add(f"registration on the nominal arm leaves {rms:.3g} mm RMS, more than an uncalibrated arm's few mm: "
              "check that the robot file and the angle convention are this arm's")
    return problem, fit, guess


def diagnose_tracker(robot, campaign, **kw):
    """Diagnose an absolute-position campaign (see the module docstring):
    ``tool_m`` (a first guess of the measured point), ``noise_mm`` (the
    floor per component), ``warnings``, ``residual_map`` (try the
    non-parametric map), ``validation`` (another TrackerCampaign of the same
    arm to test on).  Returns a TrackerDiagnosis (its ``report`` is the JSON)."""
    with single_blas_thread():
        return _diagnose_tracker(robot, campaign, **kw)


def _diagnose_tracker(robot, campaign, *, tool_m=None, noise_mm=None, warnings=None, residual_map=True,
                      validation=None):
    from robstiff_drake.io import Warnings

    w = warnings if warnings is not None else Warnings(quiet=True)
    problem, fit0, guess = _prepare(robot, campaign, tool_m, w)
    groups = pose_groups(campaign)
    all_rows = np.arange(problem.n)
    folds = splits(all_rows, groups)
    n_steps = 2 + 12 + 2 * len(folds) + (len(folds) if residual_map else 0)
    with progress(n_steps, None, "tracker diagnosis", unit="step", leave=False) as bar:
        free, not_free, Xgeo = _identifiable(problem, fit0, all_rows, robot)
        cands, skipped = _candidate_blocks(problem, fit0, all_rows, free, Xgeo)
        bar.update(1)
        r0 = (problem.m - problem.predict(fit0, all_rows)).reshape(-1)
        X0, _, ev0 = problem.columns(fit0, [], all_rows)
        tests = [rows_to_eq(test) for _, test in folds]
        cv = LinearCV(np.hstack([X0] + [Z for _, Z in cands]), r0, tests, np.repeat(groups, 3))
        info = {"ev": ev0, "c_nom": problem.c_nom}
        kept, rounds, leads, dropped, rms_decl, rms_lin, _ = _search(cv, np.arange(9), cands, info, bar)
        by_name = {b.name: b for b, _ in cands}
        kept_blocks = [by_name[n] for n in kept]
        fit = problem.gauss_newton(fit0, kept_blocks, all_rows)
        # a second pass linearised at that fit: the first, linearised at the declared model millimetres away,
        # misjudges gains of a few micrometres (second-order terms of the large corrections)
        cv, info = _linearised(problem, fit, cands, all_rows, tests, groups)
        kept, rounds2, leads, dropped2, _, rms_lin, _ = _search(cv, np.arange(9), cands, info, bar, kept)
        rounds += rounds2
        dropped = list(dict.fromkeys(dropped + dropped2))
        kept_blocks = [by_name[n] for n in kept]
        fit = problem.gauss_newton(fit, kept_blocks, all_rows)
        floor = _floor(problem, groups, all_rows, noise_mm)
        flagged = _screen(problem, fit, all_rows, None if floor.sigma_mm is None else floor.sigma_mm * 1e-3)
        rows = np.setdiff1d(all_rows, flagged)
        if len(flagged):
            fit = problem.gauss_newton(fit, kept_blocks, rows)
            folds = splits(rows, groups)
        bar.update(1)
        base_fit = problem.gauss_newton(fit0, [], rows)
        e_before, _ = _heldout(problem, base_fit, [], folds, bar)
        e_after, fold_fits = _heldout(problem, fit, kept_blocks, folds, bar)
        e_map, per_fold, map_kept = None, [], False
        if residual_map and len(rows) >= MIN_ROWS_FOR_MAP:
            e_map, per_fold = _residual_map(problem, fold_fits, folds, e_after)
            better = sum(b < a for a, b in per_fold)
            gain = 1 - np.nanmean(np.linalg.norm(e_map[rows], axis=1)) / np.nanmean(np.linalg.norm(e_after[rows],
                                                                                                    axis=1))
            map_kept = bool(gain >= rmap.MIN_GAIN and better >= rmap.MIN_FOLDS)
            bar.update(len(folds))
    reports, X_final, _ = _term_reports(problem, fit, kept_blocks, rows, groups)
    e_b, e_a = e_before[rows] * 1e3, e_after[rows] * 1e3
    rms_before = float(np.sqrt(np.mean(e_b**2)))
    rms_after = float(np.sqrt(np.mean(e_a**2)))
    lof, unexplained = None, None
    if floor.sigma_mm is not None:
        resid_eq = np.zeros(3 * problem.n)
        resid_eq[rows_to_eq(rows)] = e_after[rows].reshape(-1)
        Xfull = np.zeros((3 * problem.n, X_final.shape[1]))
        Xfull[rows_to_eq(rows)] = X_final
        lof = nf.lack_of_fit(resid_eq, Xfull, folds, rows, groups, floor)
        unexplained = nf.unexplained_mm(rms_after, floor.sigma_mm)
    trends = [b.name for b in kept_blocks if b.kind == "trend"]
    explains, verdict = _verdict(floor, lof, rms_after, trends, leads, unexplained or 0.0)
    if map_kept and explains is not None:
        verdict += (f"; a non-parametric joint-space map of what is left lowers the held-out mean 3D error from "
                    f"{stats3d(e_a)['mean']:.4f} to {stats3d(e_map[rows] * 1e3)['mean']:.4f} mm in "
                    f"{sum(b < a for a, b in per_fold)} of {len(per_fold)} folds: the named effects do not hold all "
                    "of it")
    for r in leads:
        w.add(f"{r['name']} fits the residual (held-out {r['rms_mm']:.4f} mm) but was not added: {r['plausibility']}")
    if len(flagged):
        w.add(f"{len(flagged)} gross outlier row(s) left out (file lines "
              f"{', '.join(str(int(campaign.lines[i])) for i in flagged[:10])}{' ...' if len(flagged) > 10 else ''})")
    confounded = _confounded(X_final, kept_blocks, problem, fit, rows)
    k = np.array(robot.joint_stiffness_Nm_per_rad, dtype=float)
    comp = next((b for b in kept_blocks if b.name == "joint_compliance"), None)
    if comp is not None:
        joints = [int(lab[0][1:]) - 1 for lab in comp.params]
        k[joints] = 1.0 / (fit.coef["joint_compliance"] * problem.c_nom[joints])
    report = {
        "data": campaign.path, "kind": "absolute", "n_measurements": problem.n, "n_used": int(len(rows)),
        "position_unit_mm": campaign.pos_unit_mm,
        "registration": {"rotation": fit.R, "translation_mm": fit.t * 1e3,
                         "rpy_deg": np.rad2deg(kin.rotation_to_rpy(fit.R)),
                         "meaning": "p_instrument = rotation @ p_base + translation"},
        "tool_mm": fit.u * 1e3, "tool_guess_mm": guess * 1e3,
        "error_3d_mm": {"before": stats3d(e_b), "after": stats3d(e_a),
                        "after_with_residual_map": None if e_map is None else stats3d(e_map[rows] * 1e3),
                        "held_out": f"{len(folds)}-fold, grouped by pose, folds seeded {FOLD_SEED}; before: "
                                    "registration and measured point on the nominal arm"},
        "rms_before_mm": rms_before, "rms_after_mm": rms_after,
        "rms_linearised_mm": {"declared": rms_decl * 1e3, "final": rms_lin * 1e3},
        "noise_floor_mm": floor.sigma_mm, "noise_source": floor.source,
        "noise_floor_replicates_mm": floor.replicate_mm, "replicate_dof": floor.replicate_dof,
        "explains_data": explains, "verdict": verdict,
        "lack_of_fit": None if lof is None else {"p_value": lof.p_value, "statistic": lof.statistic,
                                                 "dof": lof.dof, "test": lof.test, "p_below": lof.p_below},
        "unexplained_mm": unexplained,
        "selected_effects": kept, "effects": reports, "dropped": dropped, "leads": leads,
        "identifiable_geometry": [f"{kind}{k_ + 1}" for k_, kind in free],
        "not_identifiable_geometry": [f"{kind}{k_ + 1}" for k_, kind in not_free],
        "not_tried": skipped, "rounds": rounds,
        "residual_map": None if e_map is None else {
            "kept": map_kept, "per_fold_mean_mm": [{"without": a * 1e3, "with": b * 1e3} for a, b in per_fold],
            "rule": f"kept if the held-out mean 3D error drops by {100 * rmap.MIN_GAIN:.0f} % and in at least "
                    f"{rmap.MIN_FOLDS} of {len(folds)} folds"},
        "joint_stiffness_Nm_per_rad": k,
        "outliers": [{"line": int(campaign.lines[i]),
                      "residual_mm": float(np.linalg.norm(problem.m[i] - problem.predict(fit, [i])[0]) * 1e3)}
                     for i in flagged],
        "confounded": confounded, "validation": None, "warnings": None,
        "thresholds": {"k_folds": K_FOLDS, "min_gain": MIN_GAIN, "alpha_per_round": ALPHA,
                       "min_keep_gain": MIN_KEEP_GAIN, "max_registration_mm": MAX_REGISTRATION_MM,
                       "confounded_min": CONFOUNDED_MIN},
    }
    d = TrackerDiagnosis(report, fit, problem, robot, w)
    if validation is not None:
        report["validation"] = validate(d, validation)
    report["warnings"] = list(w)
    return d


def _confounded(X, kept_blocks, problem, fit, rows):
    i, blocks = 9, {"registration": np.arange(0, 6), "measured_point": np.arange(6, 9)}
    for b in kept_blocks:
        n = len(b.params) if b.frame != "geometry" else len(b.geo)
        blocks[b.name] = np.arange(i, i + n)
        i += n
    names = list(blocks)
    geometry = {b.name for b in kept_blocks if b.frame == "geometry"}
    kept = {b.name for b in kept_blocks}
    # the geometry's blocks are one calibration: their parameters correlate as kinematic calibration's do
    pairs = [(a, b) for j, a in enumerate(names) for b in names[j + 1:]
             if (a in kept or b in kept) and not (a in geometry and b in geometry)]
    return confounded_pairs(X, blocks, pairs)


def validate(d, other):
    """3D errors (mm) of another campaign of the same arm under the fitted
    model and registration, and with the registration (6 parameters)
    refitted to it, before (declared model) and after."""
    problem, fit, robot = d.problem, d.fit, d.robot
    q = robot.joint_rad(other.q_deg)
    nominal_mm = kin.tool_position(robot.dh, q, fit.u) * 1e3
    unit = position_scale(other, nominal_mm)
    p2 = Problem(robot, other.q_deg, other.pos * unit / 1e3, force_N=other.force_N, t_s=other.t_s,
                 temp_c=other.temp_c, seq=other.seq, tool_guess_m=fit.u)
    p2.set_gravity(problem.g_base)
    rows = np.arange(p2.n)
    # drift and thermal terms are centred on the fitted campaign's mean time and temperature: the
    # validation file is predicted without them (their origin in another session is not known)
    arm = [b for b in fit.blocks if b.frame != "instrument" and b.name != "thermal_expansion"]
    f_same = fit.copy()
    f_same.blocks = arm
    e_same = (p2.m - p2.predict(f_same, rows)) * 1e3
    base = Fit(fit.R.copy(), fit.t.copy(), fit.u.copy(), np.zeros((6, 5)))
    e_decl = (p2.m - p2.predict(base, rows)) * 1e3

    def reregistered(f0):
        f = f0.copy()
        for _ in range(6):
            X, sl, ev = p2.columns(f, [], rows)
            r = (p2.m - p2.predict(f, rows, ev)).reshape(-1)
            step, *_ = np.linalg.lstsq(X[:, :6], r, rcond=None)
            full = np.zeros(X.shape[1])
            full[:6] = step
            f = p2.apply(f, [], full, sl)
            f.blocks, f.coef, f.geo = f0.blocks, f0.coef, f0.geo
        return (p2.m - p2.predict(f, rows)) * 1e3

    return {"data": other.path, "n_measurements": p2.n,
            "error_3d_mm": {"before": stats3d(e_decl), "after": stats3d(e_same)},
            "error_3d_mm_reregistered": {"before": stats3d(reregistered(base)), "after": stats3d(reregistered(f_same))},
            "note": "after: the fitted arm, measured point and registration; reregistered: the instrument's 6 "
                    "registration parameters refitted to this file (another session, the tracker moved); drift and "
                    "thermal terms are not carried over"}
