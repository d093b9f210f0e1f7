"""No gouge where the path turns: the face-and-contour job
(diagrams/face_and_contour.yaml + .nc: a 75 mm face mill, a plunge at the
plate's edge, one face pass along X, a 90-degree corner, a contour back
with R20 arcs over the face pass; F1200, S3600, z5), and the same program
as a finishing pass (Z-1., F2400) with a tighter tolerance, where the feed
planner has work to do.

Each row: the surface error along the path's scan (mean, RMS, largest |e|,
mm, + = cut more) and the cycle time (the path's duration, s).  The
compensator on the identified model (what a user would have: the
scenario's default) and on the exact model (model.source: nominal: the
bound).  "+ feed plan": the compensated cut on the feed planner's path
(diagrams/feed_plan.py: the feeds lowered where the compensator's own model
predicts more than the tolerance).

    python studies/face_and_contour.py     # about 10 minutes on a quiet 2-core machine
    python studies/face_and_contour.py --posted    # the posted program of docs/toolpaths.md, each mode
    python studies/face_and_contour.py --finishing # only the finishing pass (about 5 minutes)

prints the tables of docs/results.md.
"""

import copy
import sys
import tempfile
from pathlib import Path

from robstiff_drake.diagrams.experiment import run_cut
from robstiff_drake.diagrams.feed_plan import plan_feeds
from robstiff_drake.diagrams.scenario import load_scenario
from robstiff_drake.model.robot import load_robot

ROOT = Path(__file__).resolve().parents[1]
SCENARIO = ROOT / "diagrams" / "face_and_contour.yaml"
POSTED = ROOT / "diagrams" / "face_contour_fanuc.yaml"


def finishing_scenario(folder):
    """The same program as a finishing pass: 1 mm deep at F2400 (the same
    spindle power), tolerance 0.02 mm."""
    text = (ROOT / "diagrams" / "face_and_contour.nc").read_text()
    prog = Path(folder) / "face_and_contour_finish.nc"
    prog.write_text(text.replace("Z-3.", "Z-1.").replace("F1200.", "F2400."))
    sc = load_scenario(SCENARIO, toolpath=prog)
    sc.path.tolerance_mm = 0.02
    return sc


def row(label, model, sc, robot, compensation, plan=None):
    sc = copy.deepcopy(sc)
    if plan is not None:
        sc._feed_overrides = plan.overrides
    res = run_cut(sc, robot, compensation=compensation)
    s = res.surface_error_mm
    print(f"  done: {label}, {model}", file=sys.stderr, flush=True)
    return label, model, s["mean"], s["rms"], s["max_abs"], res.cell.path.duration_s


def table(name, base, robot):
    rows = [row("uncompensated", "-", base, robot, False)]
    for source, model in (("identified", "identified"), ("nominal", "exact (bound)")):
        for mode in ("plain", "predictive", "preview"):
            sc = copy.deepcopy(base)
            sc.model.source = source
            sc.controller.mode = mode
            rows.append(row(mode, model, sc, robot, True))
        sc = copy.deepcopy(base)
        sc.model.source = source
        sc.controller.mode = "preview"
        plan = plan_feeds(sc, robot)
        rows.append(row(f"preview + feed plan ({plan.tolerance_mm:g} mm)", model, sc, robot, True, plan))
        if source == "identified":
            advice = plan.advice
    print(f"\n{name}")
    print("| run | compensator's model | mean (mm) | RMS (mm) | max abs (mm) | cycle time (s) |")
    print("|---|---|---|---|---|---|")
    program = rows[0][5]
    for label, model, mean, rms, mx, t in rows:
        print(f"| {label} | {model} | {mean:+.3f} | {rms:.3f} | {mx:.3f} | {t:.2f} ({100 * (t / program - 1):+.1f} %) |")
    if advice:
        print("advice (identified model): " + "; ".join(
            f"line {a['line']}: {a['error_mm']:.3f} mm predicted, {a['cause']}, F{a['feed_mm_per_min']:.0f} "
            f"(programmed F{a['programmed_feed_mm_per_min']:.0f})" for a in advice))
    else:
        print("advice (identified model): no line's predicted error exceeds the tolerance")


def posted_table(robot):
    """The posted program of docs/toolpaths.md (diagrams/face_contour_fanuc.yaml: a Fusion 360-style Fanuc
    post's face-and-contour job, run unchanged; its scenario's compensator is plain) through each mode."""
    base = load_scenario(POSTED)
    rows = [row("uncompensated", "-", base, robot, False)]
    for mode in ("plain", "predictive", "preview"):
        sc = copy.deepcopy(base)
        sc.controller.mode = mode
        rows.append(row(mode, "identified", sc, robot, True))
    sc = copy.deepcopy(base)
    sc.controller.mode = "preview"
    sc.model.source = "nominal"
    rows.append(row("preview", "exact (bound)", sc, robot, True))
    print("\nface_contour_fanuc.nc (the posted program, unchanged; F1200, 2 mm)")
    print("| run | compensator's model | mean (mm) | RMS (mm) | max abs (mm) | cycle time (s) |")
    print("|---|---|---|---|---|---|")
    for label, model, mean, rms, mx, t in rows:
        print(f"| {label} | {model} | {mean:+.3f} | {rms:.3f} | {mx:.3f} | {t:.2f} |")


def main():
    robot = load_robot()
    if "--posted" in sys.argv[1:]:
        posted_table(robot)
        return
    if "--finishing" not in sys.argv[1:]:
        table("face_and_contour.nc (F1200, 3 mm, tolerance 0.05 mm)", load_scenario(SCENARIO), robot)
    with tempfile.TemporaryDirectory() as folder:
        table("the same program as a finishing pass (F2400, 1 mm, tolerance 0.02 mm)", finishing_scenario(folder), robot)


if __name__ == "__main__":
    main()
