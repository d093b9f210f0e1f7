"""``robstiff diagnose-run RUN_DIR``: a machining run as a measurement: find
the compensated surface error's cause from the run's force history, joint
angles and scan, add the cause to the compensator (or switch on predictive
compensation), run again, and report before and after."""

from pathlib import Path

import yaml

from robstiff_drake.diagrams.run_diagnosis import diagnose_run
from robstiff_drake.diagrams.scenario import Scenario, scenario_robot
from robstiff_drake.io import emit_json, save_figure_atomic


def run_robot(run_dir, robot_yaml=None):
    """The robot of a run folder: the one its scenario.yaml names (--robot
    must agree with it); the scenario itself is checked by diagnose_run."""
    path = Path(run_dir) / "scenario.yaml"
    try:
        doc = yaml.safe_load(path.read_text()) if path.is_file() else {}
    except (OSError, UnicodeDecodeError, yaml.YAMLError):
        doc = {}
    spec = doc.get("robot", "") if isinstance(doc, dict) else ""
    return scenario_robot(Scenario(robot=str(spec or ""), source=str(path)), robot_yaml)


def plot(before, after, path, title):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(10, 4), constrained_layout=True)
    for res, lab in ((before, "before"), (after, "after")):
        if res is None:
            continue
        line = res.scans[0]
        s = res.surface_error_mm
        ax.plot(line.x_m * 1e3, line.error_m * 1e3, label=f"{lab}: mean {s['mean']:+.3f}, max |e| {s['max_abs']:.3f} mm")
    ax.axhline(0, color="k", lw=0.6)
    ax.set_xlabel("x along the pass (mm)")
    ax.set_ylabel("surface error (mm), + = cut more")
    ax.set_title(title)
    ax.legend()
    save_figure_atomic(fig, path, dpi=100)


def format_report(rep):
    lines = [f"run {rep['run_dir']}: compensated surface error, held-out RMS as the compensator stands "
             f"{rep['held_out_rms_before_mm']:.4f} mm"]
    if rep["selected"]:
        lines.append("cause traced: " + ", then ".join(
            f"{n} ({', '.join(f'{k} = {v:.3g}' for k, v in rep['params'][n].items())})" for n in rep["selected"])
            + f"; held-out RMS with it {rep['held_out_rms_after_mm']:.4f} mm")
        if rep["also_consistent_with"]:
            lines.append("also consistent with this run (within 10 % of the best): "
                         + ", ".join(rep["also_consistent_with"]) + " -- a single pass cannot tell them apart")
    else:
        lines.append("no cause explains the residual better than the noise")
    if len(rep.get("trials", [])) > 1:
        lines.append("the fix of each consistent cause, tried on a second cut (surface error mm: mean / rms):")
        for tr in rep["trials"]:
            s = tr["surface_error_mm"]
            lines.append(f"  {tr['cause']:22s} {s['mean']:+.3f} / {s['rms']:.3f}   ({tr['fix']})")
        lines.append(f"the second cut points to: {rep['cause']}")
    lines.append(f"fix: {rep['fix']}")
    lines.append("")
    lines.append("surface error (mm)   mean     rms   max|e|  entry   exit")
    for key, lab in (("surface_error_before_mm", "before"), ("surface_error_after_mm", "after")):
        if key in rep:
            s = rep[key]
            lines.append(f"  {lab:8s}       {s['mean']:+7.3f}  {s['rms']:6.3f}  {s['max_abs']:6.3f}  "
                         f"{s['entry_max_abs']:6.3f}  {s['exit_max_abs']:6.3f}")
    return "\n".join(lines)


def run(*, run_dir, json_out=None, out=None, robot_yaml=None):
    robot = run_robot(run_dir, robot_yaml)
    rep, before, after = diagnose_run(run_dir, robot)
    out = Path(out) if out else Path(run_dir) / "diagnosis"
    plot(before, after, out / "before_after.png", f"{Path(run_dir).name}: fix = {rep['fix']}")
    emit_json(rep, out / "diagnosis.json")
    if json_out is not None:
        emit_json(rep, json_out)
    if json_out != "-":
        print(format_report(rep))
        print(f"wrote {out / 'before_after.png'} and {out / 'diagnosis.json'}")
    return 0
