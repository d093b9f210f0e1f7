"""The search of identification/tracker/diagnosis.py: forward steps and
the backward check over the effects' blocks on linearised pose-grouped
folds (tracker_fit.LinearCV), the held-out refits by Gauss-Newton and the
joint-space residual map nested in the folds.  Plain numpy + scipy.
"""

import numpy as np
from scipy import stats

from robstiff_drake.identification.diagnosis import plausibility as pl
from robstiff_drake.identification.tracker import residual_map as rmap
from robstiff_drake.identification.diagnosis.cross_validation import wald_p
from robstiff_drake.identification.tracker.fit import LinearCV
from robstiff_drake.identification.tracker.model import GEOM

SETUP_NAMES = ("payload_mass", "payload_com", "gravity_tilt")  # identification/tracker/setup_terms.py's blocks

# An effect must lower the held-out RMS by this much (thousands of rows make a
# 2 % gain certain; the Wald test and the held-out folds guard against overfitting)
MIN_GAIN = 0.02
MIN_KEEP_GAIN = 0.01
ALPHA = 0.01


def _checks(b, values, half, problem, ev_info):
    ok, why = pl.check(b.plausible, values, half, ev_info)  # at the point estimate
    physical = True
    if b.name == "joint_compliance":
        physical = bool(np.all(values > 0))
    return ok, why, physical


MAX_RESTARTS = 3


def sets_of(cands):
    """The hypotheses that are sets of blocks: {set name: [block names]}:
    the arm's kinematic set (every identifiable geometry block: offsets,
    lengths and twists are one calibration) and all joints' periodic errors."""
    out = {"kinematics": [b.name for b, _ in cands if b.frame == "geometry"],
           "periodic_errors": [b.name for b, _ in cands if b.periodic]}
    return {k: v for k, v in out.items() if len(v) >= 2}


def _search(cv, base_cols, cands, info, pbar, kept_init=(), exclude=()):
    """Forward selection, then the backward check, over the candidate blocks
    and the sets of them (``sets_of``: several small effects that together
    explain the data are tried as one hypothesis, with the same tests).
    Forward steps judge a block or a set by its fit only (held-out gain,
    clustered Wald test of all its columns): before the arm's geometry is in,
    the sag or a periodic error absorbs part of the geometry's residual and
    would look non-physical; the backward check then drops whatever no
    longer earns its place (a set added as one is judged as one) or is
    implausible or non-physical at the model's final fit, and the forward
    search resumes without the implausible ones (they are leads).  Returns
    (kept, rounds, leads, dropped, declared RMS, final RMS (m, linearised),
    {name: columns}).  ``exclude``: names not tried in this pass."""
    cols_of = {}
    i = len(base_cols)
    for b, Z in cands:
        cols_of[b.name] = np.arange(i, i + Z.shape[1])
        i += Z.shape[1]
    by_name = {b.name: b for b, _ in cands}
    sets = sets_of(cands)
    kept, rounds, leads, dropped, banned = list(kept_init), [], {}, [], set(exclude)  # exclude: not tried
    units = [[n] for n in kept]  # what was added together is judged together

    def cols(names):
        return np.concatenate([base_cols] + [cols_of[n] for n in names])

    def judge(names, group):
        """(p of the group's columns, all plausible and physical, the first reason) with ``names`` fitted."""
        order = [n for n in names if n not in group] + list(group)
        c = cols(order)
        coef, cov, G = cv.fit(c)
        width = sum(len(cols_of[n]) for n in group)
        pos = np.arange(len(c) - width, len(c))  # the group's columns come last
        p = wald_p(coef, cov, pos, G)  # is it different from the declared model's value?
        half_all = stats.t.ppf(0.975, max(G - 1, 1)) * np.sqrt(np.maximum(np.diag(cov), 0))
        ok_all, why_all, k = True, "", pos[0]
        for name in group:
            b = by_name[name]
            sl = np.arange(k, k + len(cols_of[name]))
            k += len(cols_of[name])
            ok, why, physical = _checks(b, b.start + coef[sl], half_all[sl], None, info)
            if not physical:
                why = (why + "; " if why else "") + "non-physical (a negative compliance)"
            if not (ok and physical) and ok_all:
                ok_all, why_all = False, (f"{name}: {why}" if len(group) > 1 else why)
        return p, ok_all, why_all

    current = cv.heldout_rms(cols(kept))
    rms_declared = current
    for _ in range(MAX_RESTARTS + 1):
        while True:
            pool = [[b.name] for b, _ in cands if b.name not in kept and b.name not in banned]
            pool += [[n for n in members if n not in kept and n not in banned] for members in sets.values()]
            pool = [g for g in pool if g]
            seen, uniq = set(), []
            for g in pool:
                if tuple(g) not in seen:
                    seen.add(tuple(g))
                    uniq.append(g)
            pool = uniq
            if not pool:
                break
            results = []
            for group in pool:
                rms = cv.heldout_rms(cols(kept + group))
                r = {"name": "+".join(group) if len(group) > 1 else group[0], "rms_mm": rms * 1e3,
                     "p_grouped": None, "members": group}
                if rms <= (1 - MIN_GAIN) * current:
                    r["p_grouped"] = judge(kept + group, group)[0]
                results.append(r)
            rounds.append([{k: v for k, v in r.items() if k != "members"} for r in results])
            if pbar is not None:
                pbar.update(1)
            fits = [r for r in results if r["p_grouped"] is not None and r["p_grouped"] < ALPHA / len(results)]
            if not fits:
                break
            best = min(fits, key=lambda r: r["rms_mm"])
            kept += best["members"]
            units.append(list(best["members"]))
            current = best["rms_mm"] / 1e3
        gone = []
        while kept:
            weak = []
            for unit in units:
                rest = [n for n in kept if n not in unit]
                gain = 1 - current / cv.heldout_rms(cols(rest))
                p, ok, why = judge(kept, unit)
                if not ok:
                    # the implausible member goes, the rest of its set stays
                    bad = why.split(":", 1)[0] if len(unit) > 1 else unit[0]
                    weak.append((0, -gain, bad, why.split(": ", 1)[1] if len(unit) > 1 else why))
                elif gain < MIN_KEEP_GAIN or p > ALPHA / len(units):
                    weak.append((1, gain, tuple(unit), None))
            if not weak:
                break
            _, _, what, why = min(weak, key=lambda w: (w[0], w[1]))
            names = [what] if isinstance(what, str) else list(what)
            for name in names:
                kept.remove(name)
                dropped.append(name)
            units = [[n for n in u if n not in names] for u in units]
            units = [u for u in units if u]
            if why is not None:  # implausible or non-physical at the final fit: a lead, not tried again
                gone += names
                for name in names:
                    leads[name] = {"name": name, "rms_mm": current * 1e3, "plausibility": why,
                                   "round": len(rounds)}
            current = cv.heldout_rms(cols(kept))
        if not gone:
            break
        banned |= set(gone)
    for name in list(leads):  # a lead's own fit with the final model, for the report
        if name in kept:
            leads.pop(name)
            continue
        leads[name]["rms_mm"] = cv.heldout_rms(cols(kept + [name])) * 1e3
        leads[name]["plausibility"] = judge(kept + [name], [name])[2] or leads[name]["plausibility"]
    # a lead matters only if it fits better than the final model
    out = [leads[n] for n in leads if leads[n]["rms_mm"] < current * 1e3]
    dropped = [n for n in dict.fromkeys(dropped) if n not in kept]
    return kept, rounds, sorted(out, key=lambda r: r["rms_mm"]), dropped, rms_declared, current, cols_of


def periodic_candidates(problem, fit, cands, rows, tests):
    """[(Block, columns)] of the joints' periodic errors found in what ``fit``
    leaves and no other candidate could hold (tracker_periodic.search, with
    the columns of the registration, the measured point and every candidate
    block refitted with each term), and the scans."""
    from robstiff_drake.identification.tracker import periodic as tpd
    from robstiff_drake.identification.tracker.terms import periodic_block

    # (the setup mistakes' sag patterns, setup_terms.py, are smooth in the angles: not among what a periodic
    # term must not be; left out, the periods found do not depend on whether they are tried)
    every = [b for b, _ in cands if not b.periodic and b.name not in SETUP_NAMES]
    fit_all = fit.copy()
    for b in every:
        if b.frame != "geometry" and b.name not in fit_all.coef:
            fit_all.coef[b.name] = np.full(len(b.params), b.start)
    X, _, ev = problem.columns(fit_all, every, rows)
    r = problem.m[rows] - problem.predict(fit, rows)
    Jv = np.einsum("ij,njk->nik", fit.R, ev.Jv)  # the levers in the instrument's axes, as the residual
    found, scans = tpd.search(problem.q_ctrl[rows], Jv, problem.G, r, X, tests)
    out = []
    for J in sorted({t["joint"] for t in found}):
        b = periodic_block(J, [t for t in found if t["joint"] == J])
        out.append((b, np.zeros((3 * len(rows), len(b.params)))))
    return out, found, scans


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
    cv = LinearCV(X[:, np.concatenate(order)], r, tests, np.repeat(groups[rows], 3), copy=False)
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
        a, b = np.linalg.norm(e_after[test], axis=1), np.linalg.norm(e_map[test], axis=1)
        per_fold.append({"without": float(a.mean()), "with": float(b.mean()),
                         "rms_without": float(np.sqrt(np.mean(a**2))), "rms_with": float(np.sqrt(np.mean(b**2))),
                         "max_without": float(a.max()), "max_with": float(b.max()),
                         "outside_domain": float(np.mean(mp.weight(problem.q_ctrl[test]) < 1))})
    return e_map, per_fold


def map_kept(per_fold, e_after, e_map, rows):
    """The residual map is kept when it lowers the held-out mean and RMS 3D error in every fold, raises no fold's
    largest error by more than residual_map.MAX_GROWTH, and lowers the mean by residual_map.MIN_GAIN overall."""
    every = all(f["with"] < f["without"] and f["rms_with"] < f["rms_without"]
                and f["max_with"] <= rmap.MAX_GROWTH * f["max_without"] for f in per_fold)
    gain = 1 - np.nanmean(np.linalg.norm(e_map[rows], axis=1)) / np.nanmean(np.linalg.norm(e_after[rows], axis=1))
    return bool(every and gain >= rmap.MIN_GAIN)
