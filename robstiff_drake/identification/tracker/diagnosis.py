"""Diagnosis of an absolute-position (laser tracker) campaign: what the
robot file's nominal arm gets wrong, traced to named effects, with the
accuracy a tracker user reports (mean, rms, max of the 3D error, held out).
Plain numpy + scipy; no Drake.

1. Units and frame: positions without a unit in the header are told from
   the arm's reach (tracker_campaign.position_scale); points on one line,
   fewer than 4 poses, or a registration that leaves more than
   MAX_REGISTRATION_MM (another arm, other angles) are refused.
2. The declared model: the robot file's arm (its kinematics, and its sag
   under the file's masses through the file's compliances), the
   instrument's registration (closed form, then Gauss-Newton) and the
   measured point on the flange.
3. Identifiability: of the chain's parameters (theta, d, a, alpha; beta
   between nearly parallel axes), those whose columns of the identification
   Jacobian add rank to the registration's, the measured point's and the
   ones kept before them (as kinematic calibration does); a block of another
   effect that adds less than its rank is not tried, with the reason.
4. Search: forward steps over the effects of tracker_terms.py on 5
   pose-grouped folds (linearised at the declared fit, fold Gram matrices):
   an effect is added when it lowers the held-out RMS by MIN_GAIN, passes a
   pose-clustered Wald test at ALPHA / (effects tried in the round), is of
   physical size (tracker_terms' ranges, judged at the estimate: an
   interval that merely reaches them is not enough) and keeps every joint's compliance positive; one that fits but
   is not physical or plausible is a lead.  A backward check drops what no
   longer earns its place.
5. The final model by Gauss-Newton on all rows (a gross-error screen, then
   once more without the flagged rows); held-out errors by Gauss-Newton in
   each fold from its training rows only, before (registration and measured
   point on the robot file's arm) and after.
6. What is left: a non-parametric joint-space map (residual_map.py), kept
   only if it generalises (held out, nested).
7. The verdict against the noise floor (stated, or from repeated poses),
   confounded effects (correlation of the estimates), and with a second file
   the validation: its 3D errors under the fitted model and registration,
   and with the registration refitted to it.
"""

from dataclasses import dataclass, field

import numpy as np

from robstiff_drake.errors import InputError
from robstiff_drake.identification.diagnosis import noise_floor as nf
from robstiff_drake.identification.tracker import angle_readings
from robstiff_drake.identification.tracker import residual_map as rmap
from robstiff_drake.identification.tracker import periodic as tpd
from robstiff_drake.identification.diagnosis.confounding import CONFOUNDED_MIN
from robstiff_drake.identification.diagnosis.cross_validation import FOLD_SEED, K_FOLDS, pose_groups, splits
from robstiff_drake.identification.tracker.registration import check_geometry, register
from robstiff_drake.identification.threads import single_blas_thread
from robstiff_drake.identification.tracker.campaign import UnmatchedSpread, position_scale
from robstiff_drake.identification.tracker.fit import Fit, LinearCV, Problem, independent_columns, rows_to_eq
from robstiff_drake.identification.tracker.loads import load_blocks
from robstiff_drake.identification.tracker.model import GEOM, geometry_jacobian, geometry_params, gravity_in_base
from robstiff_drake.identification.tracker.report import (_confounded, _floor, _screen, _term_reports, _verdict,
                                                          periodic_report, stats3d, validate)
from robstiff_drake.identification.tracker.search import (ALPHA, MIN_GAIN, MIN_KEEP_GAIN, SETUP_NAMES, _heldout,
                                                          _linearised,
                                                          _residual_map, _search, periodic_candidates, sets_of)
from robstiff_drake.identification.tracker.search import map_kept as map_kept_rule
from robstiff_drake.identification.tracker.terms import blocks as all_blocks
from robstiff_drake.identification.tracker import setup_terms
from robstiff_drake.identification.tracker.setup_terms import setup_blocks
from robstiff_drake.model import kinematics as kin
from robstiff_drake.progress import progress

MAX_REGISTRATION_MM = 25.0  # 3D RMS left by registration on the nominal arm: beyond, another arm or other angles
WARN_REGISTRATION_MM = 10.0
MIN_ROWS_FOR_MAP = 200


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
    pl = robot.payload
    if getattr(pl, "measured_point_m", None) is not None:  # a corrected file's tracker target (--write-robot)
        return pl.measured_point_m
    return pl.tool_point_m if pl.tool_point_m is not None else np.zeros(3)


def _declared_fit(problem, robot, rows, guess):
    T6 = kin.frames(robot.dh, problem.q[rows])[:, 6, :3, :].copy()  # (the flange's pose only: not 7 frames held
    # through the fit)
    R, t, u = register(T6[:, :, 3], T6[:, :, :3], problem.m[rows], guess)
    del T6
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


def _candidate_blocks(problem, fit, rows, free, Xgeo, extra=()):
    """The blocks the campaign can be searched for, their columns at the
    declared fit, and [(name, reason)] of those it cannot."""
    problem.geo_free = free
    at, cache = problem.evaluate(fit, rows), {}  # (one evaluation and geometry Jacobian for every block)
    ev = at[0]
    out, skipped = [], []
    for b in list(all_blocks(ev, free)) + setup_blocks(ev) + list(extra):
        why = b.needs(ev) if b.needs else None
        if why:
            skipped.append({"name": b.name, "reason": why})
            continue
        X, sl, _ = problem.columns(fit, [b], rows, at=at, cache=cache)
        Z = X[:, sl[b.name]].copy()  # (a view would keep the whole 3N x (9 + p) array alive per block)
        X = None
        if b.frame != "geometry":
            kept = independent_columns(np.hstack([Xgeo, Z]), list(range(Xgeo.shape[1] + Z.shape[1])))
            if len(kept) < Xgeo.shape[1] + Z.shape[1]:
                skipped.append({"name": b.name, "reason": "not identifiable: its columns add less than their "
                                "rank to the registration's, the measured point's and the geometry's"})
                continue
        out.append((b, Z))
    return out, skipped


def _prepare(robot, campaign, tool_m, w):
    """Units, frame checks and the declared fit: (problem, fit, guess)."""
    guess = _tool_guess_m(campaign, robot, tool_m)
    q = robot.joint_rad(campaign.q_deg)
    nominal_mm = kin.tool_position(robot.dh, q, guess) * 1e3

    def registered(q_deg):  # a joint column misread? (angle_readings.py) the points registered at those angles
        alt = Problem(robot, q_deg, campaign.pos * (campaign.pos_unit_mm or 1.0) / 1e3)
        return _rms3d(alt, _declared_fit(alt, robot, np.arange(alt.n), guess), np.arange(alt.n))
    try:
        unit = position_scale(campaign, nominal_mm)
    except UnmatchedSpread as e:
        raise InputError(str(e) + angle_readings.hint(campaign.q_deg, registered, np.inf, MAX_REGISTRATION_MM))
    if "x" in campaign.units and unit != 1.0:  # only a conversion is worth a line (a header in mm is not)
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
                         f"controller's angles (refused above {MAX_REGISTRATION_MM:g} mm)"
                         + angle_readings.hint(campaign.q_deg, registered, rms, MAX_REGISTRATION_MM))
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
        cands, skipped = _candidate_blocks(problem, fit0, all_rows, free, Xgeo,
                                           load_blocks(robot, campaign, fit0.u))
        bar.update(1)
        X0, _, ev0 = problem.columns(fit0, [], all_rows)
        r0 = (problem.m - problem.predict(fit0, all_rows, ev0)).reshape(-1)
        tests = [rows_to_eq(test) for _, test in folds]
        # the columns side by side, each block's freed once copied (the columns are then in cv: the search
        # needs only their count)
        X = np.empty((len(X0), X0.shape[1] + sum(Z.shape[1] for _, Z in cands)))
        X[:, :X0.shape[1]], i = X0, X0.shape[1]
        X0 = None
        for j, (b, Z) in enumerate(cands):
            X[:, i:i + Z.shape[1]] = Z
            i += Z.shape[1]
            cands[j] = (b, np.empty((0, Z.shape[1])))
        Z = None
        cv = LinearCV(X, r0, tests, np.repeat(groups, 3), copy=False)
        X = None
        info = {"ev": ev0, "c_nom": problem.c_nom}
        # the setup mistakes (setup_terms.py) are tried in the second pass only, against the arm's own model (its
        # geometry, sag and periodic errors): the first pass and the periods found are as without them
        kept, rounds, leads, dropped, rms_decl, rms_lin, _ = _search(cv, np.arange(9), cands, info, bar,
                                                                     exclude=SETUP_NAMES)
        by_name = {b.name: b for b, _ in cands}
        kept_blocks = [by_name[n] for n in kept]
        fit = problem.gauss_newton(fit0, kept_blocks, all_rows)
        # the joints' periodic errors, of periods searched in what that model leaves
        per_cands, periodic_found, _ = periodic_candidates(problem, fit, cands, all_rows, tests)
        cands = cands + per_cands
        by_name = {b.name: b for b, _ in cands}
        bar.update(1)
        # a second pass linearised at that fit: the first, linearised at the declared model millimetres away,
        # misjudges gains of a few micrometres (second-order terms of the large corrections)
        cv = None  # (freed before the next one is built)
        cv, info = _linearised(problem, fit, cands, all_rows, tests, groups)
        kept, rounds2, leads, dropped2, _, rms_lin, cols_of = _search(cv, np.arange(9), cands, info, bar, kept)
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
        setup = setup_terms.findings(cv, lambda names: np.concatenate([np.arange(9)] + [cols_of[n] for n in names]),
                                     kept, cands, fit, info)  # (the estimates the effects report: the final fit's)
        bar.update(1)
        base_fit = problem.gauss_newton(fit0, [], rows)
        e_before, _ = _heldout(problem, base_fit, [], folds, bar)
        e_after, fold_fits = _heldout(problem, fit, kept_blocks, folds, bar)
        e_map, per_fold, map_kept = None, [], False
        if residual_map and len(rows) >= MIN_ROWS_FOR_MAP:
            e_map, per_fold = _residual_map(problem, fold_fits, folds, e_after)
            map_kept = map_kept_rule(per_fold, e_after, e_map, rows)
            bar.update(len(folds))
    reports, X_final, _ = _term_reports(problem, fit, kept_blocks, rows, groups)
    e_b, e_a = e_before[rows] * 1e3, e_after[rows] * 1e3
    rms_before = float(np.sqrt(np.mean(e_b**2)))
    rms_after = float(np.sqrt(np.mean(e_a**2)))
    lof, unexplained = None, None
    if floor.sigma_mm is not None:
        resid_eq = np.zeros(3 * problem.n)
        resid_eq[rows_to_eq(rows)] = e_after[rows].reshape(-1)
        if np.array_equal(rows, np.arange(problem.n)):  # every row used: the final columns are the full ones
            Xfull = X_final
        else:
            Xfull = np.zeros((3 * problem.n, X_final.shape[1]))
            Xfull[rows_to_eq(rows)] = X_final
        lof = nf.lack_of_fit(resid_eq, Xfull, folds, rows, groups, floor)
        Xfull = None
        unexplained = nf.unexplained_mm(rms_after, floor.sigma_mm)
    trends = [b.name for b in kept_blocks if b.kind == "trend"]
    explains, verdict = _verdict(floor, lof, rms_after, trends, leads, unexplained or 0.0)
    if map_kept and explains is not None:
        verdict += (f"; a non-parametric joint-space map of what is left lowers the held-out mean 3D error from "
                    f"{stats3d(e_a)['mean']:.4f} to {stats3d(e_map[rows] * 1e3)['mean']:.4f} mm in "
                    f"every one of the {len(per_fold)} folds: the named effects do not hold all of it")
    for f in setup:
        w.add(f["text"])
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
                        "after_with_outliers": None if not len(flagged) else stats3d(np.vstack(
                            [e_a, (problem.m[flagged] - problem.predict(fit, flagged)) * 1e3])),
                        "after_with_residual_map": None if e_map is None else stats3d(e_map[rows] * 1e3),
                        "held_out": f"{len(folds)}-fold, grouped by pose, folds seeded {FOLD_SEED}; before: "
                                    "registration and measured point on the robot file's arm (its kinematics, "
                                    "and its sag with the file's masses and stiffness)"},
        "rms_before_mm": rms_before, "rms_after_mm": rms_after,
        "rms_linearised_mm": {"declared": rms_decl * 1e3, "final": rms_lin * 1e3},
        "noise_floor_mm": floor.sigma_mm, "noise_source": floor.source,
        "noise_floor_replicates_mm": floor.replicate_mm, "replicate_dof": floor.replicate_dof,
        "explains_data": explains, "verdict": verdict,
        "lack_of_fit": None if lof is None else {"p_value": lof.p_value, "statistic": lof.statistic,
                                                 "dof": lof.dof, "test": lof.test, "p_below": lof.p_below},
        "unexplained_mm": unexplained,
        "selected_effects": kept, "effects": reports, "setup_findings": setup, "dropped": dropped, "leads": leads,
        "periodic_errors": periodic_report(fit, kept_blocks, reports),
        "hypothesis_sets": sets_of(cands),
        "periodic_search": {"found": len(periodic_found), "min_period_deg": tpd.MIN_PERIOD_DEG,
                            "false_alarm_max": tpd.ALPHA, "min_step_gain": tpd.MIN_STEP_GAIN,
                            "note": "periods searched on all rows (a periodogram per joint, then harmonics); their "
                                    "amplitudes refitted in each held-out fold from its training rows"},
        "identifiable_geometry": [f"{kind}{k_ + 1}" for k_, kind in free],
        "not_identifiable_geometry": [f"{kind}{k_ + 1}" for k_, kind in not_free],
        "not_tried": skipped, "rounds": rounds,
        "residual_map": None if e_map is None else {
            "kept": map_kept,
            "per_fold_mean_mm": [{"without": f["without"] * 1e3, "with": f["with"] * 1e3} for f in per_fold],
            "per_fold_mm": [{k: (v if k == "outside_domain" else v * 1e3) for k, v in f.items()} for f in per_fold],
            "domain": f"applies within the training poses' joint-space domain: shrinks to zero from their "
                      f"{100 * rmap.DOMAIN_QUANTILE:.0f} % nearest-neighbour spacing to {rmap.DOMAIN_FAR:g}x it",
            "rule": f"kept if the held-out mean and rms 3D error drop in every one of the {len(folds)} folds, no "
                    f"fold's max grows by more than {rmap.MAX_GROWTH:g}x, and the mean drops by "
                    f"{100 * rmap.MIN_GAIN:.0f} % overall"},
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


