"""Deciding between candidate fixes from verification cuts: each candidate
fix is a compensator settings file; a verification cut is the same pass
cut with one of them; the decision reads the cuts' settings (to know which
candidate each cut ran) and their measured scans, nothing else.  Plain
numpy; no Drake, no simulation, no machine parameters.

Rule (stated in every report): the cut with the lowest mean-square surface
error wins over another only when their mean squares differ by more than
the noise floor squared (a difference smaller than the floor decides
nothing) and by more than DECIDE_Z standard errors of the scanner's noise
(identification/scan_statistics.mean_square_difference).  A winner must
also beat the first cut (the compensator as it was) by the same rule, or
no fix is chosen.
"""

import numpy as np

from robstiff_drake.errors import InputError
from robstiff_drake.identification.runs import scan_statistics as ss

DECIDE_Z = 3.0
AS_SET = "as set (no change)"


def match_cuts(candidates, original, cuts):
    """Which candidate each verification cut ran: ``candidates`` [(name,
    CompensatorSettings)], ``original`` the first cut's settings, ``cuts``
    [RunFiles].  Returns [(name, RunFiles)]; a cut whose settings are none
    of them is refused (InputError naming its settings file)."""
    out = []
    for cut in cuts:
        name = next((n for n, s in candidates if cut.settings.same_as(s)), None)
        if name is None and cut.settings.same_as(original):
            name = AS_SET
        if name is None:
            names = ", ".join(n for n, _ in candidates) or "none"
            raise InputError(f"{cut.settings.path}: these settings are none of the candidate fixes ({names}) nor "
                             "the first cut's; a verification cut runs one candidate's compensator.yaml unchanged")
        out.append((name, cut))
    return out


def _better(e_best, e_other, floor_mm):
    """(whether ``e_best`` is better than ``e_other`` by the rule, the
    mean-square difference, its noise standard error) (mm^2)."""
    diff, se = ss.mean_square_difference(e_best, e_other, floor_mm)
    return bool(diff > floor_mm**2 and diff > DECIDE_Z * se), diff, se


def decide(before, cuts, floor_mm, cutter_diameter_mm):
    """The verdict from measured scans: ``before`` the first cut's Scan,
    ``cuts`` [(candidate name, Scan)].  Returns a dict: each cut's surface
    figures, the chosen candidate (or None), whether the cuts decided, and
    why, in words."""
    rows = []
    for name, scan in cuts:
        segs = ss.segments(scan.x_mm, scan.y_mm)
        rows.append({"candidate": name, "scan": scan.path,
                     "surface_error_mm": ss.surface_stats(scan.x_mm, scan.y_mm, scan.error_mm, segs,
                                                                       cutter_diameter_mm)})
    order = sorted(range(len(cuts)), key=lambda i: rows[i]["surface_error_mm"]["rms"])
    best = order[0]
    e_best = cuts[best][1].error_mm
    ties = []
    for i in order[1:]:
        ok, diff, se = _better(e_best, cuts[i][1].error_mm, floor_mm)
        rows[i]["vs_best"] = {"mean_square_difference_mm2": diff, "noise_se_mm2": se, "worse": ok}
        if not ok:
            ties.append(cuts[i][0])
    improved, diff, se = _better(e_best, before.error_mm, floor_mm)
    name = cuts[best][0]
    verdict = {"cuts": rows, "best": name, "tied_with": ties,
               "vs_first_cut": {"mean_square_difference_mm2": diff, "noise_se_mm2": se, "better": improved},
               "rule": (f"lowest mean-square surface error; a difference counts when the mean squares differ by "
                        f"more than the noise floor squared ({floor_mm:.4f} mm)^2 and by {DECIDE_Z:g} standard "
                        "errors of the scan noise; the winner must beat the first cut by the same rule")}
    if not improved or name == AS_SET:
        verdict.update(chosen=None, decided=improved or name == AS_SET,
                       reason=f"no candidate's cut is better than the first cut by more than the noise allows "
                              f"(best: {name}, rms {rows[best]['surface_error_mm']['rms']:.4f} mm)")
    elif ties:
        verdict.update(chosen=None, decided=False,
                       reason=f"{name} and {', '.join(ties)} leave surfaces that differ by less than the noise "
                              "allows: the verification cuts cannot tell them apart (either fix does as well on "
                              "this pass)")
    else:
        verdict.update(chosen=name, decided=True,
                       reason=f"{name}'s cut is the best by more than the noise allows "
                              f"(rms {rows[best]['surface_error_mm']['rms']:.4f} mm)")
    return verdict


def verification_plan(candidates, run_scan, differ, floor_mm):
    """What to cut and how it is decided: ``candidates`` [(name, settings
    file (relative), change in words)], ``run_scan`` the first cut's Scan,
    ``differ`` (x mm, y mm, difference mm) where the candidates' predictions
    on this pass differ most (or None)."""
    segs = ss.segments(run_scan.x_mm, run_scan.y_mm)
    if all(np.ptp(run_scan.y_mm[g]) < 1e-9 for g in segs):
        where_scan = "the same scan line(s), y = " + ", ".join(f"{v:g}" for v in sorted(
            {round(float(v), 3) for v in run_scan.y_mm})) + " mm"
    else:
        where_scan = (f"the same scan line(s), point for point ({len(segs)} piece(s), from x, y = "
                      f"{run_scan.x_mm[0]:.1f}, {run_scan.y_mm[0]:.1f} mm)")
    if len(candidates) == 1:
        where = ("one candidate: its cut shows whether the fix removes the error (it must beat the first cut); "
                 "a repeat of the first cut's settings (compensator.yaml of the run) is a useful reference")
    elif differ is None or differ[2] < floor_mm:
        where = ("the candidates predict the same face on this pass to within the noise floor: cuts of this pass "
                 "will likely not tell them apart; a pass where the load changes sign or size (reversed feed, "
                 "another depth) would")
    else:
        where = (f"the candidates' predictions differ most at x = {differ[0]:.1f} mm, y = {differ[1]:.1f} mm "
                 f"(by {differ[2] * 1e3:.1f} um)")
    return {
        "cut": "the same pass (same program, depth and material: a fresh face, or the same part after a skim "
               "cut), once per candidate, with that candidate's compensator.yaml loaded unchanged",
        "scan": f"{where_scan}, at the same resolution, written as scan.csv (docs/run_files.md)",
        "candidates": [{"name": n, "settings": f, "change": c} for n, f, c in candidates],
        "where": where,
        "decides": f"the cut with the lowest mean-square surface error, when it beats the others and the first cut "
                   f"by more than the noise floor squared ({floor_mm:.4f} mm)^2 and {DECIDE_Z:g} standard errors "
                   "of the scan noise; otherwise undecided",
        "command": "robstiff diagnose-run RUN_DIR --verify CUT_DIR [CUT_DIR ...]  (each CUT_DIR a run folder "
                   "with at least compensator.yaml, scan.csv and RUN_ID)",
    }


def plan_markdown(plan):
    """The verification plan as Markdown."""
    out = ["# Verification cuts", "", f"**Cut:** {plan['cut']}.", "", f"**Scan:** {plan['scan']}.", "",
           "| candidate | settings | change |", "|---|---|---|"]
    out += [f"| {c['name']} | {c['settings']} | {c['change']} |" for c in plan["candidates"]]
    out += ["", f"**Where they differ:** {plan['where']}.", "", f"**What decides:** {plan['decides']}.", "",
            f"**Then:** `{plan['command']}`", ""]
    return "\n".join(out)


