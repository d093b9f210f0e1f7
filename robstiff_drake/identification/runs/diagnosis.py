"""Residual diagnosis of a machining run (``robstiff diagnose-run RUN_DIR``):
from what a cell records (docs/run_files.md: the wrist sensor's raw log, the
controller's joint angles and correction, the compensator's and the servo's
settings and the scan of the machined face) find what the compensated
surface error is, trace it to a cause, write each candidate fix as
compensator settings with a verification-cut plan, and decide from the
verification cuts' scans.  Nothing here reads the simulation's truth
(``sim_*`` files) or runs a simulation: a cell's own logs and the robot's
model are enough.  Plain numpy and scipy; the robot controller's model of
the arm (its weight, inertia and modes: diagrams/run_arm.ArmModel, Drake)
comes in as an object.

The joint (diagrams/station.py): the gear between the motor and the link
carries the total torque, weight + inertia + cut; the controller's gravity
model and a touch-off at the first path point put the tool where commanded
at rest; the correction reaches the motor after the servo's dead time
(``servo.interpolator_delay_ms``) through the position loop.

Signals (identification/runs/arm_response.py).  The wrench log, gravity removed
with the settings' payload calibration and moved to the tool point (base
frame), is the process load W(t) (smoothed over SMOOTH_MM of feed); the
arm's time is the program's delayed by the dead time.  A linear model of
the joints (gears at the model's stiffness, the weight's stiffness, assumed
DAMPING_RATIO, the motor-side servo), linearised every SEGMENT_S, gives:
  the arm's own motion error (the path's acceleration through the soft
    gears and the servo, the gravity model's twist rate that gets no
    feed-forward): known, not a cause;
  the loop's tracking error: the logged correction through the servo plus
    the measured load through the gears (the payload's inertia taken out of
    the sensor's reading), the model's lost motion and coupling added.
The tool's vertical deviation is the sum of these and the causes' columns.

The loop's tracking error, scaled by a (1: as predicted, 0-1.5), is always
in the model; it is reported apart (``loop_lag``), with its fix (plain ->
predictive) offered when it moves the face by at least the floor.  Causes
(each a deviation dz(t) per unit parameter, beyond the model as set):
  stiffness_error_jN     r_N J_z,N c_N (tau_N - tau_inertia_N): joint N's
                         compliance off by r_N (the controller's gravity
                         model is calibrated on the arm: the weight's part
                         is not this cause's)
  lost_motion            sum_N J_z,N d_N(t; b_N), the compensator's
                         hysteretic law (model/play_hysteresis.py, the
                         plant's too): gear N stays on the flank it last
                         pressed until the total torque T_N it carries
                         (weight + inertia - J^T W) passes its friction
                         T_c,N the other way (the compensator's fallback,
                         1.5 % of the rated torque of the model's
                         stiffness: model/transmission.gap_friction_Nm),
                         and its link then crosses the gap with its twist
                         inertia (link in series with motor) under the
                         torque beyond T_c,N; d_N = -(p_N(t) - p_N at the
                         touch-off), p_N in [-b_N, b_N].  Not linear in b
                         (a wider gap takes longer to cross): fitted first
                         with the relay (b -> 0), then refitted with the
                         columns at the fitted b (causes.REBUILDS).
                         Bounded by 2 mrad, a worn-out reducer; named
                         beyond the catalogue's 1 arcmin with a warning
                         (a worn gear or a loose joint), not refused.
                         Joints 1-6 (where T keeps within +-T_c or the
                         joint cannot move the tool vertically, there is
                         no data)
  joint_coupling         c23 of the total torque's change since the touch-off
  force_bias             -sum_a F_a J_z C J^T w_a, w_a a unit force along the
                         sensor's axis a (the compensator corrected for a
                         force the cut did not exert: a drifted bias or a
                         payload weight off): Fx, Fy, Fz within 20 N
  setup_offset           a constant (tool length, workpiece height)
The surface at a scan point is the lowest the cutter's face went while it
covered the point (the envelope), so the error predicted there is
base(x) - min over covering t of (z_nom(t) + dz(t)).

Statistics (thresholds in the report): the noise floor is the scan noise,
stated (--noise-mm, or scan.csv's noise_mm) or estimated from the scan
(identification/runs/scan_statistics.py), both reported.  Forward selection on
top of the loop: a cause is named when its nested F-test with the effective
number of independent points gives p < ALPHA, it moves the fitted face by
at least SIZE_FACTOR x the floor (RMS over the scan) from the smaller
model's, and it needs no parameter at a plausibility bound.  A fit that
extends a model starts from that model's solution (it is never worse); a
parameter that cannot move the surface by NO_DATA x the floor over its
whole range has no data in this run and is dropped.  Each test's n_eff is
that of the residual with the cause in (a cause that explains the face
leaves the scan's white noise: n_eff near n); the report's own n_eff is the
final model's.  Causes whose fits
differ by less than the floor (mean square) are alike: one pass cannot tell
them apart, and verification cuts decide (identification/runs/verification.py:
scans and settings only).

Where it lives: the signals in identification/runs/signals.py, the causes,
fits and tests in identification/runs/causes.py; here the fixes, the
diagnosis of a run folder and its report.
"""

import copy

import numpy as np

from robstiff_drake.errors import InputError
from robstiff_drake.identification.runs import files as rf
from robstiff_drake.identification.runs import tables as rt
from robstiff_drake.identification.runs import verification as rv
from robstiff_drake.identification.runs import scan_statistics as ss
from robstiff_drake.identification.runs.causes import (
    ALIKE, ALPHA, EXPLAIN_ALPHA, LOOP, LOST_MOTION_CATALOGUE_RAD, MAX_CAUSES, NO_DATA, SIZE_FACTOR, Envelope, Fit,
    alternatives, candidates,
    cause_params, fit_model, loop_lag_ms, noise_floor, rms, si_params, trace, try_cause, without,
)
from robstiff_drake.identification.runs.damping import profile_damping
from robstiff_drake.identification.runs.signals import (  # noqa: F401 (run_signals, servo_of: the names callers use)
    DAMPING_RATIO, run_context, run_signals, servo_of, signals_at,
)


def fixed_settings(settings, causes):
    """The settings with the causes ({name: {param: SI value}}) added to the
    compensator: (settings, [changes in words], [causes with no compensator fix])."""
    s = copy.deepcopy(settings)
    s.path = ""
    changes, none = [], []
    for name, p in causes.items():
        if name == "loop_lag":
            if s.mode == "plain":
                s.mode = "predictive"
                changes.append("mode: plain -> predictive (the force model ahead of the measured force: no lag)")
            else:
                none.append("loop_lag: the predictive compensator still lags (check its force model scale and "
                            "its delay)")
        elif name.startswith("stiffness_error_j"):
            j = int(name[-1]) - 1
            k = list(s.joint_stiffness_Nm_per_rad)
            old = k[j]
            k[j] = old / (1.0 + p[f"r{j + 1}"])
            s.joint_stiffness_Nm_per_rad = k
            changes.append(f"joint {j + 1}'s model stiffness {old:.4g} -> {k[j]:.4g} N*m/rad")
        elif name == "lost_motion":
            b = list(s.lost_motion_rad)
            for j in range(6):
                b[j] = b[j] + p.get(f"b{j + 1}", 0.0)
            s.lost_motion_rad = b
            changes.append("lost motion in the model: " + ", ".join(f"{v * 1e6:.1f}" for v in b)
                           + " urad (joints 1-6)")
        elif name == "joint_coupling":
            s.coupling_c23_rad_per_Nm = s.coupling_c23_rad_per_Nm + p["c23"]
            changes.append(f"joint 2-3 coupling in the model: {s.coupling_c23_rad_per_Nm:.3g} rad/(N*m)")
        elif name == "force_bias":
            s.payload = dict(s.payload)
            old = np.asarray(s.payload.get("force_bias_N") or [0.0, 0.0, 0.0], dtype=float)
            new = old + np.array([p.get(f"F{a}", 0.0) for a in "xyz"])
            s.payload["force_bias_N"] = new.tolist()
            changes.append("the sensor's force bias in the model: (" + ", ".join(f"{v:.2f}" for v in old) + ") -> ("
                           + ", ".join(f"{v:.2f}" for v in new) + ") N (or zero the sensor again, the tool free, "
                           "before the cut)")
        elif name == "setup_offset":
            none.append(f"setup_offset: no compensator change; the face sits {p['offset'] * 1e3:+.4f} mm off "
                        "(+ = cut more): check the tool length and the workpiece height")
    return s, changes, none


def _fix_causes(fit, loop_fix):
    """The causes of a fit whose fixes a candidate carries: its named causes,
    and the loop's lag when its fix (predictive mode) is offered."""
    return [c.name for c in fit.causes if c.name != LOOP] + ([LOOP] if loop_fix else [])


def _model_name(fit, loop_fix):
    return " + ".join(_fix_causes(fit, loop_fix))


def _where_they_differ(env, scan, fits):
    """(x mm, y mm, difference mm) where the candidates' predicted surfaces
    differ most on this pass, or None with one candidate."""
    if len(fits) < 2:
        return None
    preds = np.array([env.surface(f.columns() @ f.theta) for f in fits])
    spread = preds.max(axis=0) - preds.min(axis=0)
    i = int(np.argmax(spread))
    xs, ys = scan.x_mm[env.covered], scan.y_mm[env.covered]
    return float(xs[i]), float(ys[i]), float(spread[i]) * 1e3


def _slug(name):
    return name.replace(" + ", "+")


def diagnose_run(run_dir, robot, arm, *, noise_mm=None, verify=(), scan=None):
    """Trace a run's surface error; with ``verify`` (run folders of
    verification cuts), decide between the candidate fixes from their scans.
    Reads only the cell files (identification/runs/files.py); ``robot``: the
    run's robot, ``arm``: the controller's model of it (a callable of the
    robot: diagrams/run_arm.ArmModel).  Returns (report dict, extras:
    candidate settings texts, plan, data for the plot)."""
    files = rf.load_run_files(run_dir, scan=scan)  # (scan: a file made outside the run, diagnose-run --scan)
    cuts = [rf.load_run_files(c, names=(rt.SETTINGS, rt.SCAN)) for c in verify]
    if noise_mm is not None and not (np.isfinite(noise_mm) and noise_mm > 0):
        raise InputError(f"--noise-mm: must be a positive number (mm), got {noise_mm}")
    warnings = []
    settings, scan = files.settings, files.scan
    D = settings.cutter_diameter_mm
    servo_of(settings)  # refused before any computation when the file does not state it
    if settings.mode == "preview":
        # the preview's correction comes from its own model of the arm's dynamics along the planned path, which
        # the run folder does not hold: its tracking error cannot be predicted from the logs
        raise InputError(f"{settings.path}: compensator.mode: preview: diagnose-run predicts the loop of plain and "
                         "predictive compensation only; cut the same pass with mode: plain or predictive to "
                         "diagnose it")
    model_of_arm = arm(robot)
    run_ctx = run_context(files, robot, model_of_arm)
    sig = signals_at(run_ctx, model_of_arm, DAMPING_RATIO)
    env = Envelope(scan, sig, D)
    if env.covered.sum() < rt.MIN_ROWS[rt.SCAN]:
        raise InputError(f"{scan.path}: only {int(env.covered.sum())} scan points lie under the logged pass "
                         f"(cutter {D:g} mm): the scan and the logs are not of the same cut")
    if not env.covered.all():
        warnings.append(f"{int((~env.covered).sum())} scan points lie outside the logged pass and are left out")
    x_c, y_c = scan.x_mm[env.covered], scan.y_mm[env.covered]
    segs = ss.segments(x_c, y_c)
    y = scan.error_mm[env.covered] * 1e-3
    floor_mm, source, stated, estimated = noise_floor(scan, ss.segments(scan.x_mm, scan.y_mm), noise_mm, warnings)
    floor = floor_mm * 1e-3
    ctx = {"segs": segs, "length_mm": ss.scan_length_mm(x_c, y_c, segs), "cutter_mm": D}
    empty = Fit([], [], np.zeros(0), float(y @ y), -y)

    def traced(sig_, env_):
        loop_, *cands_ = candidates(sig_)
        loop_row_, loop_fit_ = try_cause(env_, empty, loop_, y, floor, ctx)
        return (loop_, cands_, loop_row_, loop_fit_, *trace(env_, cands_, y, floor, ctx,
                                                              loop_fit_ if loop_fit_ is not None else empty))

    loop, cands, loop_row, loop_fit, rounds, final = traced(sig, env)
    # the arm's damping, from how well the traced model fits the face at each ratio; re-traced at the
    # best one when the run decides it
    damping = profile_damping(run_ctx, model_of_arm, scan, D, y, floor, ctx, final)
    if damping["ratio"] is not None and damping["ratio"] != DAMPING_RATIO:
        sig = signals_at(run_ctx, model_of_arm, damping["ratio"], damping)
        env = Envelope(scan, sig, D)
        loop, cands, loop_row, loop_fit, rounds, final = traced(sig, env)
    sig.damping = damping
    model = [c for c in final.causes if c.name != LOOP]
    alts = alternatives(env, cands, y, floor, ctx, final) if model else []
    n_eff, tau = ss.effective_points(final.residual * 1e3, segs, ctx["length_mm"], D)
    rms_after = rms(final.residual) * 1e3
    named = cause_params(final)
    sizes = {}
    for i, c in enumerate(final.causes):
        sizes[c.name] = rms(env.surface(final.columns() @ final.theta)
                             - env.surface(final.columns() @ without(final, i))) * 1e3
    if model and loop_fit is not None:  # the loop's test given the causes named with it
        rest = fit_model(env, model, [k for c, k in zip(final.causes, final.keep) if c.name != LOOP], y)
        loop_row, _ = try_cause(env, rest, loop, y, floor, ctx)
    loop_fix = bool(loop_row.get("named")) and settings.mode == "plain"
    report = {
        "run_dir": str(run_dir), "run_id": files.run_id,
        "noise_floor_mm": floor_mm, "noise_source": source, "noise_stated_mm": stated,
        "noise_estimated_mm": estimated,
        "n_scan_points": int(y.size), "scan_length_mm": ctx["length_mm"], "n_effective": n_eff,
        "thresholds": {"alpha": ALPHA, "size_factor": SIZE_FACTOR, "no_data_fraction": NO_DATA,
                       "alike_mean_square_floors": ALIKE, "explains_alpha": EXPLAIN_ALPHA,
                       "max_causes": MAX_CAUSES, "smooth_hz": sig.smooth_hz, "damping_ratio": sig.damping_ratio,
                       "candidates_per_round": len(cands),
                       "rule": (f"a cause is named when its nested F-test on the effective number of independent "
                                f"scan points gives p < {ALPHA:g} ({len(cands)} candidates tried in the first "
                                f"round), it changes the surface by at least {SIZE_FACTOR:g} x the noise floor "
                                "(RMS) and needs no parameter at its plausibility bound; the arm's own motion "
                                "error and the loop's tracking error, both predicted from the logs, are in the "
                                "model before any cause")},
        "loop_lag_ms": loop_lag_ms(sig),
        "damping": sig.damping or {"used": sig.damping_ratio, "source": "given"},
        "motion_error_mm": rms(env.surface(np.zeros_like(sig.t_s))) * 1e3,
        "loop_lag": _loop_report(loop_row, named.get(LOOP), sizes.get(LOOP), settings.mode, loop_fix),
        "rms_before_mm": rms(y) * 1e3, "rms_after_mm": rms_after,
        "unexplained_mm": float(np.sqrt(max(rms_after**2 - floor_mm**2, 0.0))),
        "explains_data": ss.consistent_with_floor(final.residual * 1e3, floor_mm, n_eff, EXPLAIN_ALPHA),
        "causes": [{"name": c.name, "size_mm": sizes[c.name], "params": named[c.name], "what": c.what}
                   for c in model],
        "also_consistent_with": [r["name"] for r, _ in alts],
        "alternatives": [{"name": r["name"], "instead_of": r["instead_of"], "rms_mm": r["rms_mm"],
                          "size_mm": r["size_mm"], "params": r["params"]} for r, _ in alts],
        "rounds": rounds, "candidates": [],
        "surface_error_before_mm": ss.surface_stats(scan.x_mm, scan.y_mm, scan.error_mm,
                                                    ss.segments(scan.x_mm, scan.y_mm), D),
    }
    extras = {"scan": scan, "covered": env.covered, "model_mm": env.surface(final.columns() @ final.theta) * 1e3
              if final.causes else env.surface(np.zeros_like(sig.t_s)) * 1e3,
              "settings": {}, "plan": None, "cut_scans": []}
    # candidate fixes: compensator settings each
    cand_settings, plan_rows, sets = [], [], []
    if model or loop_fix:
        for f in [final] + [f for _, f in alts]:
            name = _model_name(f, loop_fix)
            si = {k: v for k, v in si_params(f).items() if k != LOOP or loop_fix}
            s, changes, none = fixed_settings(settings, si)
            params = {k: v for k, v in cause_params(f).items() if k != LOOP or loop_fix}
            entry = {"name": name, "params": params, "changes": changes, "not_in_compensator": none}
            same = next((n for n, other in cand_settings if s.same_as(other)), None)
            if same is not None:  # the same compensator change: one cut cannot tell these apart
                entry["same_settings_as"] = same
            elif changes:
                rel = f"candidates/{_slug(name)}/{rt.SETTINGS}"
                entry["settings"] = rel
                cand_settings.append((name, s))
                plan_rows.append((name, rel, "; ".join(changes)))
                extras["settings"][rel] = s
                sets.append(f)
            report["candidates"].append(entry)
        if plan_rows:
            differ = _where_they_differ(env, scan, sets) if len(sets) > 1 else None
            extras["plan"] = rv.verification_plan(plan_rows, scan, differ, floor_mm)
            report["verification_plan"] = extras["plan"]
    report["fix"] = _fix(report)
    if cuts:
        matched = rv.match_cuts(cand_settings, settings, cuts)
        verdict = rv.decide(scan, [(n, c.scan) for n, c in matched], floor_mm, D)
        for row, (_, c) in zip(verdict["cuts"], matched):
            row["run_dir"] = str(c.folder)
        report["verification"] = verdict
        extras["cut_scans"] = [(n, c.scan) for n, c in matched]
        report["fix"] = _verified_fix(report, verdict)
    warnings.extend(_beyond_catalogue(si_params(final)))
    report["warnings"] = warnings
    return report, extras


def _beyond_catalogue(causes):
    """Warning lines for a lost motion named beyond an RV gear's catalogued
    1 arcmin (LOST_MOTION_CATALOGUE_RAD): a finding about the gear, which
    the fit does not refuse (causes.LOST_MOTION_LIMIT_RAD gives why)."""
    out = []
    for name, v in causes.get("lost_motion", {}).items():
        if v > LOST_MOTION_CATALOGUE_RAD:
            j = name[1:]
            out.append(f"lost motion {name} = {v * 1e6:.0f} urad on joint {j}: beyond an RV gear's catalogued lost "
                       f"motion ({LOST_MOTION_CATALOGUE_RAD * 1e6:.0f} urad, 1 arcmin): a worn gear or a loose "
                       f"joint; check it with a lost-motion test of joint {j}: the joint loaded both ways to +-3 % "
                       "of its rated torque, the link's angle measured (a dial gauge on the link or a laser tracker at the "
                       "tool), as reducer makers measure it")
    return out


def _loop_report(row, params, size_mm, mode, fix):
    """The ``loop_lag`` key: the loop's tracking error (predicted from the
    logs, scaled by a): its size in the final model, its test against the
    model of the named causes without it (``gain_mm``: how far it moves that
    model's face; p), and its fix."""
    out = {"what": row["what"], "status": row["status"]}
    if row["status"] != "ok":
        return out
    out.update(params=params or row["params"], size_mm=size_mm if size_mm is not None else row["size_mm"],
               gain_mm=row["size_mm"], p_value=row["p_value"], f_stat=row["f_stat"],
               significant=bool(row["named"]), why_not=row["why_not"])
    if fix:
        out["fix"] = "mode: plain -> predictive"
    elif row["named"]:
        out["fix"] = None
        out["note"] = ("the predictive loop's own tracking error: no settings change removes it (check the force "
                       "model's scale and the controller's dead time)")
    return out


def _fix(report):
    """The ``fix`` key before verification."""
    if not report["candidates"]:
        return None
    cands = report.get("candidates", [])
    with_settings = [c for c in cands if "settings" in c]
    if not with_settings:
        return {"status": "no compensator change", "candidate": cands[0]["name"] if cands else None,
                "changes": [], "settings": None, "notes": sum((c["not_in_compensator"] for c in cands), [])}
    if len(with_settings) == 1:
        c = with_settings[0]
        return {"status": "to verify with one cut", "candidate": c["name"], "changes": c["changes"],
                "settings": c["settings"], "notes": c["not_in_compensator"]}
    return {"status": "undecided: the run cannot tell the candidates apart; verification cuts decide",
            "candidate": None, "changes": [], "settings": None,
            "candidates": [c["name"] for c in with_settings]}


def _verified_fix(report, verdict):
    chosen = verdict["chosen"]
    cands = {c["name"]: c for c in report.get("candidates", [])}
    if chosen is None:
        tied = [verdict["best"]] + verdict["tied_with"]
        # the best cut must beat the first cut before anything counts as verified
        better = bool(verdict.get("vs_first_cut", {}).get("better", True))
        out = {"status": "undecided" if better and not verdict["decided"] else "no fix better than the first cut",
               "candidate": None, "changes": [], "settings": None, "reason": verdict["reason"], "tied": tied}
        if better and not verdict["decided"] and all(t in cands for t in tied):
            # the tied cuts share a cause: its fix is verified, the rest is not
            common = set.intersection(*(set(cands[t]["params"]) for t in tied))
            if common:
                out["status"] = "verified in part: " + ", ".join(sorted(common)) + " (the rest undecided)"
                out["verified_causes"] = sorted(common)
        return out
    c = cands[chosen]
    # a cut wins only against the cuts made: a candidate the run could not tell from it, left uncut, may do as well
    made = {row["candidate"] for row in verdict["cuts"]}
    not_cut = [n for n, x in cands.items() if "settings" in x and n not in made] if len(cands) > 1 else []
    if not_cut:
        return {"status": "better than the first cut, not verified: " + ", ".join(not_cut) + " fit the first cut as "
                "well and " + ("was" if len(not_cut) == 1 else "were") + " not cut (cut " + ("it" if len(not_cut) == 1
                else "them") + " to decide which cause it is)", "candidate": chosen, "changes": c["changes"],
                "settings": c["settings"], "reason": verdict["reason"], "not_cut": not_cut}
    return {"status": "verified", "candidate": chosen, "changes": c["changes"], "settings": c["settings"],
            "reason": verdict["reason"]}
