"""``robstiff diagnose`` (and ``identify``) on an absolute-position campaign
(a laser tracker's: q1..q6 and x, y, z): the accuracy before and after,
the effects found, the corrected robot file (``--write-robot``) and the
test on a second file (``--validate``).  See
identification/tracker/diagnosis.py."""

from pathlib import Path

import numpy as np

from robstiff_drake.errors import InputError
from robstiff_drake.identification.tracker.campaign import read_tracker_campaign
from robstiff_drake.identification.tracker.diagnosis import diagnose_tracker
from robstiff_drake.io import RunFolder, Warnings, emit_json, staged_outputs, write_atomic
from robstiff_drake.progress import wrote


def _g(v, fmt=".4f"):
    return "-" if v is None else format(v, fmt)


def format_report(rep, markdown=False):
    h = "## " if markdown else ""
    e = rep["error_3d_mm"]
    r = rep.get("robot")
    with_robot = "" if r is None else (f" with the robot {r['name']} ({r['file']}"
                                       + ("; the default: no --robot given" if r["default"] else "") + ")")
    lines = [(f"# Tracker campaign diagnosis of {rep['data']}" if markdown else f"diagnosis of {rep['data']} "
              "(absolute positions)") + with_robot, "",
             f"{rep['n_measurements']} measured poses" + (f" ({len(rep['outliers'])} gross outlier row(s) left out)"
                                                          if rep["outliers"] else "")
             + f"; 3D error held out ({e['held_out']}):",
             "                                       mean        rms        max   (mm)"]
    rows = [("declared (the robot file's arm)", e["before"]), ("final model (the effects below)", e["after"])]
    if e.get("after_with_outliers") is not None:
        rows.append(("final model, outlier rows included", e["after_with_outliers"]))
    if e["after_with_residual_map"] is not None:
        kept = rep["residual_map"]["kept"]
        rows.append(("+ joint-space map" + ("" if kept else " (not kept)"), e["after_with_residual_map"]))
    for name, s in rows:
        lines.append(f"  {name:34s} {s['mean']:9.4f}  {s['rms']:9.4f}  {s['max']:9.4f}")
    f = rep["noise_floor_mm"]
    lines += [f"held-out RMS per component: {rep['rms_before_mm']:.4f} -> {rep['rms_after_mm']:.4f} mm; noise floor: "
              + ("none stated or measured" if f is None else f"{f:.4f} mm ({rep['noise_source']})"), "",
              f"{h}verdict" if markdown else "verdict:", rep["verdict"], ""]
    reg = rep["registration"]
    lines += ["registration (instrument = rotation @ base + translation): translation "
              + ", ".join(f"{v:.3f}" for v in reg["translation_mm"]) + " mm, roll/pitch/yaw "
              + ", ".join(f"{v:.4f}" for v in reg["rpy_deg"]) + " deg",
              "measured point on the flange (tool): " + ", ".join(f"{v:.3f}" for v in rep["tool_mm"]) + " mm"
              + (" (the file's guess: " + ", ".join(f"{v:.3f}" for v in rep["tool_guess_mm"]) + ")"), "",
              "effects found: " + (", ".join(rep["selected_effects"]) or "none")]
    if rep.get("setup_findings"):  # (identification/tracker/setup_terms.py) before the effects: check these first
        at = lines.index("effects found: " + (", ".join(rep["selected_effects"]) or "none"))
        block = ["setup findings (the declared payload or vertical; check these first):"]
        for f in rep["setup_findings"]:
            block.append(f"  {f['text']}")
            block.append("    held out: " + "; ".join(f"{a['model']}: {a['heldout_rms_mm']:.4f} mm"
                                                     for a in f["alternatives"]))
        lines[at:at] = block + [""]
    for t in rep["effects"]:
        lines.append(f"  {t['name']}: {t['description']}")
        lines.append(f"    {'plausible' if t['plausible'] else 'IMPLAUSIBLE'}: {t['plausibility']}"
                     + ("; a trend, not a cause" if t["kind"] == "trend" else ""))
    if rep.get("periodic_errors"):
        lines.append(f"periodic joint errors ({len(rep['periodic_errors'])}, largest first; "
                     "periods searched by a periodogram per joint, 95 % intervals):")
        lines += [f"  {e['text']}" + ("  BEYOND TYPICAL" if e["beyond_typical"] else "")
                  for e in rep["periodic_errors"]]
    if rep.get("hypothesis_sets"):
        lines.append("tried as sets too: " + "; ".join(f"{k} ({', '.join(v)})" for k, v in
                                                       rep["hypothesis_sets"].items()))
    if rep["leads"]:
        lines.append("fit the residual but not added (not physical or not plausible):")
        lines += [f"  {r['name']} (held-out {r['rms_mm']:.4f} mm): {r['plausibility']}" for r in rep["leads"]]
    if rep["dropped"]:
        lines.append("dropped by the backward check: " + ", ".join(rep["dropped"]))
    lines.append("confounded (correlation of the estimates; |r| >= 0.8): " + ("none" if not rep["confounded"] else
                 ", ".join(f"{c['terms'][0]} / {c['terms'][1]} {c['correlation']:+.2f}" for c in rep["confounded"])))
    lines.append("geometry identifiable: " + ", ".join(rep["identifiable_geometry"]))
    lines.append("not identifiable (the registration, the measured point or the others take them): "
                 + (", ".join(rep["not_identifiable_geometry"]) or "none"))
    if rep["not_tried"]:
        lines.append("not tried: " + "; ".join(f"{s['name']} ({s['reason']})" for s in rep["not_tried"]))
    if rep["residual_map"] is not None:
        rm = rep["residual_map"]
        lines.append(f"joint-space residual map: {'kept' if rm['kept'] else 'not kept'} ({rm['rule']}; "
                     f"{rm['domain']}); per fold mean (max) "
                     + ", ".join(f"{p['without']:.4f}->{p['with']:.4f} ({p['max_without']:.3f}->{p['max_with']:.3f})"
                                 for p in rm["per_fold_mm"]) + " mm")
    lines.append("joint stiffness (N*m/rad): " + ", ".join(f"{k:.4g}" for k in rep["joint_stiffness_Nm_per_rad"]))
    if rep["outliers"]:
        lines.append("outlier rows: " + ", ".join(f"line {o['line']} ({o['residual_mm']:.3f} mm)"
                                                  for o in rep["outliers"][:20]))
    v = rep["validation"]
    if v is not None:
        ve, vr = v["error_3d_mm"], v["error_3d_mm_reregistered"]
        lines += ["", f"validation on {v['data']} ({v['n_measurements']} poses), 3D error mean / rms / max (mm):",
                  f"  robot file's arm, same registration  {ve['before']['mean']:.4f} / {ve['before']['rms']:.4f} / "
                  f"{ve['before']['max']:.4f}",
                  f"  fitted model, same registration      {ve['after']['mean']:.4f} / {ve['after']['rms']:.4f} / "
                  f"{ve['after']['max']:.4f}",
                  f"  fitted model, registration refitted  {vr['after']['mean']:.4f} / {vr['after']['rms']:.4f} / "
                  f"{vr['after']['max']:.4f}  (nominal: {vr['before']['mean']:.4f} / {vr['before']['rms']:.4f} / "
                  f"{vr['before']['max']:.4f})"]
        if v.get("transfer"):
            lines.append("  what carries over (each group left out in turn, registration refitted):")
            lines += [f"    {t['text']}" for t in v["transfer"]]
    return "\n".join(lines)


def plots(d, folder):
    """The 3D error before/after along each joint angle, and its distribution."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    P, fit = d.problem, d.fit
    rows = np.arange(P.n)
    e_after = np.linalg.norm(P.m - P.predict(fit, rows), axis=1) * 1e3
    fig, axes = plt.subplots(2, 3, figsize=(12, 6.5), constrained_layout=True)
    for j, ax in enumerate(axes.ravel()):
        ax.plot(np.rad2deg(P.q_ctrl[:, j]), e_after, ".", ms=2)
        ax.set_xlabel(f"q{j + 1} (deg)")
        ax.set_ylabel("3D error, final model (mm)")
    fig.suptitle("what the final model leaves, against each joint angle (all rows, fitted)")
    folder.save_figure("error_vs_joint_angles.png", fig, dpi=90)
    return ["error_vs_joint_angles.png"]


def shared_rows(campaign, other):
    """How many of ``other``'s rows are rows of ``campaign``: the same joint
    angles (to 1e-6 deg) and measured point (to 1e-6 mm)."""
    def rows(c):
        unit = c.pos_unit_mm if c.pos_unit_mm is not None else 1.0
        return [tuple(np.round(np.r_[c.q_deg[i], c.pos[i] * unit], 6)) for i in range(len(c))]

    mine = set(rows(campaign))
    return sum(r in mine for r in rows(other))


def run(*, data, tool_m, noise_mm, robot, json_out=None, report=None, plots_dir=None, validate=None,
        write_robot=None, warnings=None, robot_given=True):
    w = warnings if warnings is not None else Warnings()
    campaign = read_tracker_campaign(data, robot)
    other = read_tracker_campaign(validate, robot) if validate is not None else None
    if other is not None:
        n_shared = shared_rows(campaign, other)
        if n_shared:
            w.add(f"--validate {validate}: {n_shared} of its {len(other)} rows are rows of {data} (the same joint "
                  "angles and measured point): the validation is not independent of the fit; validate on poses "
                  "measured apart from the campaign")
    d = diagnose_tracker(robot, campaign, tool_m=tool_m, noise_mm=noise_mm, warnings=w, validation=other)
    rep = d.report
    # the robot the campaign was diagnosed with, named in the report's first line (the default one said so)
    from robstiff_drake.paths import MODELS_DIR

    library = Path(robot.source).resolve().parent == MODELS_DIR.resolve()
    rep["robot"] = {"name": robot.name, "file": "the library's" if library else str(robot.source),
                    "default": not robot_given}
    with staged_outputs():  # the corrected robot file, the JSON, the report and the views, all or none
        if write_robot is not None:
            from robstiff_drake.identification.tracker.robot_writer import write_corrected_robot

            err = write_corrected_robot(write_robot, robot, d.fit, rep, data, d.problem.q)
            rep["corrected_robot"] = {"path": str(write_robot), "fk_check_mm": err * 1e3}
        rep["warnings"] = list(w)
        if json_out is not None:
            emit_json(rep, json_out)
        if report is not None:
            write_atomic(report, format_report(rep, markdown=True) + "\n")
        if plots_dir is not None:
            with RunFolder(plots_dir) as folder:
                plots(d, folder)
    if json_out != "-":
        print(format_report(rep))
    stderr = json_out == "-"  # a "wrote" line for every output, as the stiffness diagnosis gives
    if write_robot is not None:
        wrote(write_robot, "the corrected robot file (its forward kinematics reproduce the fitted model to "
                           f"{rep['corrected_robot']['fk_check_mm']:.2g} mm)", to_stderr=stderr)
    wrote(json_out, to_stderr=stderr)
    wrote(report, "the report (Markdown)", to_stderr=stderr)
    wrote(plots_dir, "the residual views, one PNG each", folder=True, to_stderr=stderr)
    return 0


def check_tracker_options(tracker, validate, write_robot):
    if not tracker and (validate is not None or write_robot is not None):
        raise InputError("--validate and --write-robot are for absolute-position campaigns (q1..q6 and x, y, z; a "
                         "laser tracker's); this file is a stiffness campaign (dx, dy, dz)")
