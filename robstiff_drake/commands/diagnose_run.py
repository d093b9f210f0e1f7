"""``robstiff diagnose-run RUN_DIR [--noise-mm SIGMA] [--verify CUT_DIR ...]``:
a machining run as a measurement.  From the run folder's cell files
(docs/run_files.md) find the compensated surface error's cause, write each
candidate fix as compensator settings with a verification-cut plan, and,
given the verification cuts' run folders, decide from their scans."""

from pathlib import Path

import numpy as np

from robstiff_drake.identification.runs.diagnosis import diagnose_run
from robstiff_drake.errors import InputError
from robstiff_drake.identification.runs.files import load_run_files
from robstiff_drake.identification.runs.settings import read_settings, settings_text
from robstiff_drake.identification.runs.tables import SETTINGS, run_file
from robstiff_drake.identification.runs.folder_checks import check_run
from robstiff_drake.identification.runs.verification import plan_markdown
from robstiff_drake.identification.runs.scan_statistics import along_mm, segments
from robstiff_drake.io import RunFolder, Warnings, check_outputs, emit_json, json_text
from robstiff_drake.model.robot import load_robot
from robstiff_drake.progress import wrote


def _damping_line(d):
    """The arm's damping the model used, and where it comes from."""
    if d.get("ratio") is not None:
        return (f"the arm's damping from the run: {d['ratio']:.0%} of critical on every mode (the face fits as well "
                f"from {d['interval'][0]:.0%} to {d['interval'][1]:.0%})")
    if d.get("source") == "given":
        return f"the arm's damping: {d['used']:.0%} of critical on every mode (given)"
    return f"the arm's damping: {d['source']}; a tap test on the spindle would decide it"


def plot(rep, extras, title):
    """The first cut's measured surface error, the traced model's, and each verification cut's."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(10, 5.5), constrained_layout=True)
    scan = extras["scan"]
    along_x = all(np.ptp(scan.y_mm[g]) < 1e-9 for g in segments(scan.x_mm, scan.y_mm))

    def position(sc):  # x for lines along x, else the distance along the scan
        return sc.x_mm if along_x else along_mm(sc.x_mm, sc.y_mm)

    s = rep["surface_error_before_mm"]
    ax.plot(position(scan), scan.error_mm, ".", ms=2, color="0.5",
            label=f"first cut (measured): mean {s['mean']:+.3f}, rms {s['rms']:.3f} mm")
    known = "the arm's motion error and the loop's tracking error (predicted from the logs)"
    ax.plot(position(scan)[extras["covered"]], extras["model_mm"], "k-", lw=1.2,
            label="traced: " + ", ".join([known] + [c["name"] for c in rep["causes"]]))
    for name, cut in extras["cut_scans"]:
        e = cut.error_mm
        ax.plot(position(cut), e, ".", ms=2, label=f"cut with {name}: mean {np.mean(e):+.3f}, "
                                                   f"rms {np.sqrt(np.mean(e**2)):.3f} mm")
    ax.axhline(0, color="k", lw=0.6)
    ax.set_xlabel("x along the pass (mm)" if along_x else "distance along the scan (mm)")
    ax.set_ylabel("surface error (mm), + = cut more")
    ax.set_title(title, fontsize=10)
    ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.13), ncol=2)
    return fig


def _params(p):
    return ", ".join(f"{k} = {v:.3g}" for k, v in p.items())


def format_report(rep):
    t = rep["thresholds"]
    lines = [f"run {rep['run_dir']} ({rep['run_id']}): {rep['n_scan_points']} scan points over "
             f"{rep['scan_length_mm']:.0f} mm, effective {rep['n_effective']:.1f} independent",
             f"noise floor {rep['noise_floor_mm']:.4f} mm, {rep['noise_source']}; stated "
             + (f"{rep['noise_stated_mm']:.4f}" if rep["noise_stated_mm"] is not None else "-")
             + ", from the scan " + (f"{rep['noise_estimated_mm']:.4f}" if rep["noise_estimated_mm"] is not None
                                     else "-") + " mm",
             f"rule: {t['rule']}",
             f"surface error rms {rep['rms_before_mm']:.4f} mm with the compensator as set",
             f"known from the logs: the arm's own motion error leaves {rep['motion_error_mm']:.4f} mm rms on the face",
             _damping_line(rep["damping"])]
    lag = rep["loop_lag"]
    if lag["status"] == "ok":
        verdict = ("significant" if lag["significant"] else f"not significant: {lag['why_not']}")
        fix = (f"; fix: {lag['fix']}" if lag.get("fix") else f"; {lag['note']}" if lag.get("note") else "")
        lines.append(f"the loop's tracking error ({_params(lag['params'])}; lag {rep['loop_lag_ms']:.0f} ms) moves "
                     f"the face by {lag['size_mm']:.4f} mm rms (p = {lag['p_value']:.2g}, {verdict}){fix}")
    else:
        lines.append(f"the loop's tracking error: {lag['status']}")
    if rep["causes"]:
        traced = ", then ".join(f"{c['name']} ({_params(c['params'])}; changes the surface by {c['size_mm']:.4f} "
                                "mm rms)" for c in rep["causes"])
        if rep["also_consistent_with"]:
            # several causes fit alike: the best fit is not a verdict
            lines.append(f"cause not decided: the best fit is {traced}; as good on this run (their fits differ by "
                         f"less than the noise floor): {', '.join(rep['also_consistent_with'])}; verification "
                         "cuts decide")
        else:
            lines.append("cause traced: " + traced)
    else:
        lines.append("no cause named")
    verdict = "explains the data (the residual is consistent with the noise floor)" if rep["explains_data"] else \
        f"leaves {rep['unexplained_mm']:.4f} mm unexplained above the noise floor"
    lines.append(f"residual rms {rep['rms_after_mm']:.4f} mm: the model {verdict}")
    first = rep["rounds"][0] if rep["rounds"] else []
    if first:
        lines.append("candidate (first round)   rms (mm)   size (mm)   F_eff        p    status")
        for r in first:
            if r["status"] != "ok":
                lines.append(f"  {r['name']:24s} {r['status']}")
                continue
            st = "named" if r["named"] else r["why_not"]
            lines.append(f"  {r['name']:24s} {r['rms_mm']:8.4f}   {r['size_mm']:8.4f}  {r['f_stat']:8.3g} "
                         f"{r['p_value']:8.2g}    {st}")
    for c in rep.get("candidates", []):
        what = "; ".join(c["changes"] + c["not_in_compensator"])
        lines.append(f"candidate fix {c['name']}: {what}" + (f" -> {c['settings']}" if "settings" in c else ""))
    if "verification" in rep:
        v = rep["verification"]
        lines.append("verification cuts (surface error mm: mean / rms / max|e| / edges max|e|):")
        for row in v["cuts"]:
            s = row["surface_error_mm"]
            lines.append(f"  {row['candidate']:28s} {s['mean']:+.4f} / {s['rms']:.4f} / {s['max_abs']:.4f} / "
                         f"{s['edges_max_abs']:.4f}   ({row['run_dir']})")
        lines.append(f"decision: {v['reason']}")
        lines.append(f"rule: {v['rule']}")
    fix = rep["fix"]
    if fix is None:
        lines.append("fix: none (no cause named)")
    else:
        lines.append(f"fix: {fix['status']}" + (f": {fix['candidate']}" if fix.get("candidate") else "")
                     + (f" ({'; '.join(fix['changes'])})" if fix.get("changes") else ""))
    return "\n".join(lines)


def run_robot(run_dir, robot_yaml=None, warnings=None):
    """The RobotModel of a run (see run_robot_and_file)."""
    return run_robot_and_file(run_dir, robot_yaml, warnings)[0]


def run_robot_and_file(run_dir, robot_yaml=None, warnings=None):
    """The robot of a run: the one its compensator.yaml names, a robot file
    relative to it (a simulated run's kept copy, inputs/NAME.yaml) or a
    library name (the kept copy inputs/NAME.yaml when the run has one: the
    robot as it ran).  --robot must agree with it; it stands in for a robot
    file the folder names but lacks (with a warning).  Returns (RobotModel,
    the robot file's path or None for the default robot)."""
    import os

    from robstiff_drake.diagrams.run_inputs import INPUTS_DIR
    from robstiff_drake.model.robot import resolve_robot, same_robot_file
    from robstiff_drake.paths import library_robots

    settings_path = run_file(run_dir, SETTINGS)
    spec = None
    if settings_path.is_file():
        _, settings = read_settings(settings_path)
        if settings.robot in library_robots():
            kept = run_file(run_dir, f"{INPUTS_DIR}/{settings.robot}.yaml")
            spec = str(kept) if kept.is_file() else settings.robot
        elif settings.robot:
            spec = str(settings_path.parent / settings.robot)
            if not os.path.exists(spec):
                if robot_yaml is None:
                    raise InputError(f"{settings_path}: robot: {settings.robot}: the run folder has no such file; "
                                     "give the robot file the run was made with, --robot PATH.yaml (runs simulated "
                                     f"now keep it in {INPUTS_DIR}/)")
                if warnings is not None:
                    warnings.add(f"{settings_path} names the robot file {settings.robot}, which the run folder lacks: "
                                 f"taking --robot {robot_yaml}")
                spec = None
    if robot_yaml is not None and spec is not None and not same_robot_file(spec, robot_yaml):
        raise InputError(f"--robot {robot_yaml} disagrees with the robot of {settings_path} (robot: {spec}); "
                         "drop --robot or use the run's own robot")
    chosen = robot_yaml if robot_yaml is not None else spec
    return load_robot(chosen), (None if chosen is None else resolve_robot(chosen))


def _candidate_robot(settings, robot_file, candidate_path):
    """A candidate fix's settings, its ``robot:`` naming the run's robot file
    relative to where the candidate is written (a library name stays)."""
    import dataclasses
    import os

    from robstiff_drake.paths import library_robots

    if robot_file is None or not settings.robot or settings.robot in library_robots():
        return settings
    rel = os.path.relpath(Path(robot_file).resolve(), Path(candidate_path).parent.resolve())
    return dataclasses.replace(settings, robot=rel)


def run(*, run_dir, json_out=None, out=None, noise_mm=None, verify=None, robot_yaml=None, scan=None):
    out = Path(out) if out else Path(run_dir) / "diagnosis"
    verify = list(verify or [])
    check_outputs(inputs=[run_dir, *verify, scan], files={"--json": json_out}, folders={"--out": out})
    warnings = Warnings()
    robot, robot_file = run_robot_and_file(run_dir, robot_yaml, warnings)
    check_run(load_run_files(run_dir, scan=scan), robot)  # logs in other units, or of another robot: one line, before the fit
    from robstiff_drake.diagrams.run_arm import ArmModel

    rep, extras = diagnose_run(run_dir, robot, ArmModel, noise_mm=noise_mm, verify=verify, scan=scan)
    warnings.extend_from(rep["warnings"])
    rep["warnings"] = list(warnings)
    with RunFolder(out) as folder:
        note = f"candidate fix written by robstiff diagnose-run {run_dir} (run {rep['run_id']})"
        for rel, s in extras["settings"].items():
            folder.write(rel, settings_text(_candidate_robot(s, robot_file, out / rel), folder.run_id, [note]))
        if extras["plan"]:
            folder.write("verification_plan.md", plan_markdown(extras["plan"]))
        title = f"{Path(run_dir).name}: traced " + (", ".join(c["name"] for c in rep["causes"]) or "no cause")
        if rep.get("verification"):
            fix = rep["fix"]
            title += f"; from the verification cuts: {fix['status']}" + (f" ({fix['candidate']})"
                                                                          if fix.get("candidate") else "")
        folder.save_figure("diagnosis.png", plot(rep, extras, title), dpi=100)
        rep["out"] = str(out)
        folder.write("diagnosis.json", json_text(dict(rep, diagnosis_run_id=folder.run_id)))
    if json_out is not None:
        emit_json(rep, json_out)
    if json_out != "-":
        print(format_report(rep))
    wrote(out, "diagnosis.json, diagnosis.png" + (", verification_plan.md, candidates/" if extras["plan"] else ""),
          folder=True, to_stderr=json_out == "-")
    wrote(json_out, to_stderr=json_out == "-")
    return 0
