"""The files a ``robstiff simulate`` run writes beside the cell's own
(commands/simulate.py's write_outputs puts them in the run folder): the
controller-rate time series, the true machined surface, the scenario as
run, the surface-error figure and the diagram.  What each column means is
in the files' own header lines and docs/run_files.md."""

import csv
import io
import shutil
import subprocess
from pathlib import Path

import numpy as np

from robstiff_drake.model import kinematics as kin


def label(compensation):
    return "compensated" if compensation else "uncompensated"


def timeseries_csv(res, robot, run_id=""):
    """Controller-rate time series: raw and filtered wrench (sensor frame),
    estimated tool wrench, dq, correction, actual and commanded tool point."""
    t, filt = res.logs["filtered_wrench"]
    ts, state = res.logs["state"]
    tr, raw = res.logs["raw_wrench"]
    cols = {}
    cols["t_s"] = t
    raw_i = np.clip(np.searchsorted(tr, t), 0, len(tr) - 1)
    st_i = np.clip(np.searchsorted(ts, t), 0, len(ts) - 1)
    for prefix, data, names in (
        ("raw", raw[raw_i], ("fx_N", "fy_N", "fz_N", "mx_Nm", "my_Nm", "mz_Nm")),
        ("filtered", filt, ("fx_N", "fy_N", "fz_N", "mx_Nm", "my_Nm", "mz_Nm")),
        ("tool_wrench", res.logs["tool_wrench"][1], ("fx_N", "fy_N", "fz_N", "mx_Nm", "my_Nm", "mz_Nm")),
        ("dq", res.logs["dq"][1], tuple(f"q{i}_rad" for i in range(1, 7))),
        ("correction", res.logs["correction"][1], tuple(f"q{i}_rad" for i in range(1, 7))),
    ):
        for j, n in enumerate(names):
            cols[f"{prefix}_{n}"] = data[: len(t), j]
    q = state[st_i, :6]
    # the joint angles the controller commands (motor side: what a robot's encoders report)
    q_ref = np.column_stack([np.interp(t, res.cell.q_ref_times, res.cell.q_ref[:, j]) for j in range(6)])
    corr = res.logs["correction"][1][: len(t)] if res.compensation else 0.0
    q_cmd = q_ref + corr
    q_cmd_deg = robot.controller_deg(q_cmd)  # the controller's convention
    for j in range(6):
        cols[f"q{j + 1}_deg"] = q_cmd_deg[:, j]
    T = kin.frames(robot.dh, q)[:, 6]
    p = T[:, :3, 3] + T[:, :3, :3] @ res.cell.tool_m
    p_cmd = res.cell.path.positions(t)
    for j, ax in enumerate("xyz"):
        cols[f"tool_{ax}_mm"] = p[:, j] * 1e3
    for j, ax in enumerate("xyz"):
        cols[f"commanded_{ax}_mm"] = p_cmd[:, j] * 1e3
    buf = io.StringIO()
    buf.write(f"# run_id: {run_id}\n")
    buf.write(f"# robstiff simulate: {res.cell.scenario.source}, {label(res.compensation)}; sampled every controller "
              "period. Wrenches: raw/filtered in the sensor frame (what the payload exerts on the sensor), "
              "tool_wrench = the gravity-free estimate at the tool point in the base frame. q*_deg: the joint "
              "angles the controller commands (motor side). tool_*: the actual tool point (the simulation's "
              "truth, which a real cell does not measure); commanded_*: the planned one.\n")
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(cols.keys())
    for row in zip(*cols.values()):
        w.writerow([f"{v:.6g}" for v in row])
    return buf.getvalue()


def plot_surfaces(results, sc):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(len(results), 1, figsize=(11, 3.2 * len(results)), squeeze=False, layout="constrained")
    along_path = results[0].scans and results[0].scans[0].s_m is not None
    for ax, res in zip(axes[:, 0], results):
        for line in res.scans:
            if along_path:
                ax.plot(line.s_m * 1e3, line.error_m * 1e3, lw=1, label=f"along the path, offset {line.offset_m * 1e3:+.1f} mm")
            else:
                ax.plot(line.x_m * 1e3, line.error_m * 1e3, lw=1, label=f"scan at y = {line.y_m * 1e3:.1f} mm")
        s = res.surface_error_mm
        ax.axhline(0, color="k", lw=0.6)
        ax.set_title(f"{label(res.compensation)}: mean {s['mean']:+.3f} mm, rms {s['rms']:.3f}, "
                     f"max |e| {s['max_abs']:.3f}, PV {s['pv']:.3f} mm")
        ax.set_xlabel("arc length along the path (mm); gaps: no material" if along_path
                      else "x along the pass (mm); gaps: no material")
        ax.set_ylabel("surface error (mm)\n+ = cut more")
    # one key for both runs (the same scan lines), below the axes: it covers no curve, and no title
    # (beside them, at the top, it covered the end of a long figure title)
    handles, labels = axes[0, 0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside lower center", ncol=min(len(labels), 3), fontsize=8)
    fig.suptitle(f"{sc.name}: machined surface from the cutter's envelope (laser line scan)")
    return fig


def write_diagram(cell, run):
    """diagram.dot always; diagram.svg too when Graphviz's `dot` is installed."""
    dot_text = cell.diagram.GetGraphvizString(max_depth=1)
    run.write("diagram.dot", dot_text)
    if shutil.which("dot") is None:
        return ["diagram.dot (install Graphviz for diagram.svg)"]
    svg = subprocess.run(["dot", "-Tsvg"], input=dot_text.encode(), capture_output=True, check=False)
    if svg.returncode == 0:
        run.write("diagram.svg", svg.stdout)
        return ["diagram.dot", "diagram.svg"]
    return ["diagram.dot (dot failed to render the SVG)"]


def surface_csv(res, run_id=""):
    """The true machined surface of one run (the simulation's truth, without
    the scanner's noise): x, y, commanded and machined height, error (mm)."""
    buf = io.StringIO()
    buf.write(f"# run_id: {run_id}\n")
    buf.write(f"# robstiff simulate: the true machined surface (simulation only; scan.csv is what the scanner "
              f"measures), {label(res.compensation)}; error = commanded - machined "
              "(positive: cut more); empty where there is no machined face.\n")
    buf.write("x_mm,y_mm,commanded_mm,machined_mm,error_mm,s_mm\n")  # s_mm: arc length along the path (path scans)
    for line in res.scans:
        s_mm = line.s_m * 1e3 if line.s_m is not None else np.full(line.x_m.shape, np.nan)
        for x, y, c, m, e, s in zip(line.x_m, line.y_at, line.commanded_m, line.machined_m, line.error_m, s_mm):
            vals = [x * 1e3, y * 1e3, c * 1e3, m * 1e3, e * 1e3, s]
            buf.write(",".join("" if not np.isfinite(v) else f"{v:.6f}" for v in vals) + "\n")
    return buf.getvalue()


def scenario_text(sc, run_id="", kept=None):
    """The scenario as run (YAML): its file references name the run folder's
    kept copies (``kept``, diagrams/run_inputs.py), else made absolute."""
    import copy

    from pydrake.common.yaml import yaml_dump_typed

    from robstiff_drake.diagrams.run_inputs import scenario_as_kept
    from robstiff_drake.diagrams.scenario import resolve, robot_spec
    from robstiff_drake.diagrams.scenario_schema import Scenario

    if kept is not None:
        sc = scenario_as_kept(sc, kept)
    else:
        sc = copy.deepcopy(sc)
        for attr in ("identified_json", "payload_yaml"):
            if getattr(sc.model, attr):
                setattr(sc.model, attr, str(resolve(sc, getattr(sc.model, attr)).resolve()))
        if sc.toolpath.program:
            sc.toolpath.program = str(resolve(sc, sc.toolpath.program).resolve())
        spec = robot_spec(sc)
        if spec is not None and spec != sc.robot:  # a robot file: make its path absolute
            sc.robot = str(Path(spec).resolve())
    source, sc.source = sc.source, ""
    body = "".join(line for line in yaml_dump_typed(sc, schema=Scenario).splitlines(keepends=True)
                   if not line.startswith("source:"))  # set by the loader, not a key of the file
    return (f"# run_id: {run_id}\n# the scenario of this run (from {source}), with its plant: the simulation's "
            "truth, which diagnose-run never reads\n" + body)
