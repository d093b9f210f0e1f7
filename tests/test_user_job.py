"""A user's own CAM job on the shipped face_contour_fanuc machine
(tests/data/plate_job_fusion.nc: two face passes at Z-1, a contour at Z-2
with a G2 half circle, zero at the plate's front-left corner, posted with
G28 G91 Z0., T1 M6, G43 H1, M8, M01): what it is told before it runs (its
placement, its coverage of the plate, its corners), the feed plan that is
used only when predicted better than the program, the advised program
written as the post wrote it, and the cut itself: compensated not worse
than uncompensated in the default mode."""

import copy
from pathlib import Path

import numpy as np
import pytest

from robstiff_drake.diagrams import feed_plan as feed_planner
from robstiff_drake.diagrams.job_checks import corners, job_warnings
from robstiff_drake.diagrams.scenario import load_scenario
from robstiff_drake.errors import InputError
from robstiff_drake.model import feed_plan as fp
from robstiff_drake.model.gcode.program import read_program_file

ROOT = Path(__file__).resolve().parents[1]
MACHINE = ROOT / "diagrams" / "face_contour_fanuc.yaml"
JOB = ROOT / "tests" / "data" / "plate_job_fusion.nc"
# the plate of face_contour_fanuc.yaml is X 1540..1660, Y -40..40, top 703 mm: its front-left corner
CORNER_OFFSET = "1540,-40,703"


def _load(**kw):
    return load_scenario(MACHINE, toolpath=str(JOB), **kw)


def test_the_job_is_told_where_it_is_placed_and_what_it_covers():
    """Without --work-offset the scenario's own offset is said, and the job,
    then mostly beside the plate, gets both extents; placed at the plate's
    corner, neither line."""
    text = " | ".join(job_warnings(_load()))
    assert "own work offset (1600, 0, 703 mm" in text and "--work-offset" in text
    assert "of the program's cutting length lies over the workpiece" in text
    assert "the workpiece X 1540..1660, Y -40..40 mm" in text and "its cuts span X 1555" in text
    placed = job_warnings(_load(work_offset=CORNER_OFFSET))
    assert not any("own work offset" in w or "lies over the workpiece" in w for w in placed), placed


def test_corners_name_the_preview_mode_under_the_plain_one():
    """The plain compensator on a path with corners: one line naming them
    (block numbers and file lines) and controller.mode: preview; in preview
    mode, no such line."""
    sc = _load(work_offset=CORNER_OFFSET)
    found = dict(corners(sc._program))
    # the face passes' 90-degree turns (N75, N80), the contour's (N110) and its line/arc junctions (N115, N120)
    lines = {n for n, text in enumerate(JOB.read_text().splitlines(), start=1)
             for tag in ("N75 ", "N80 ", "N110 ", "N115 ", "N120 ") if text.startswith(tag)}
    assert lines <= set(found), (lines, found)
    (w,) = [w for w in job_warnings(sc) if "corner" in w]
    assert "controller.mode: preview" in w and "N75 (line" in w
    sc.controller.mode = "preview"
    assert not any("corner" in w for w in job_warnings(sc))


def test_stock_gives_the_workpiece():
    sc = _load(work_offset="0,0,703", stock="-10,130,-5,85,703")
    assert sc.workpiece.boxes_mm == [[-10.0, 130.0, -5.0, 85.0, 703.0]]
    assert not any("lies over the workpiece" in w for w in job_warnings(sc))
    for bad, word in (("1,2,3", "expected X0,X1,Y0,Y1,TOP"), ("5,1,0,1,0", "X0 < X1"), ("0,1,0,x,0", "Y1 'x'"),
                      ("0,1,0,1,1e9", "TOP")):
        with pytest.raises(InputError, match=word):
            _load(stock=bad)


def test_advised_program_keeps_a_posted_program_as_it_is():
    """The advised program of a posted program: its G28 G91 Z0., T1 M6,
    G43 H1, M8, M01, M9 lines as they were, the slowed move split at its
    block number, and the reader takes the result; a cutting move in G91 is
    refused with its line."""
    text = JOB.read_text()
    prog = read_program_file(JOB)
    fp.check_rewritable(text, prog.moves)
    line = next(n for n, t in enumerate(text.splitlines(), start=1) if t.startswith("N110 "))
    move = next(m for m in prog.moves if m.line == line)
    length = float(np.linalg.norm(np.subtract(move.end_mm, move.start_mm)))
    out = fp.rewrite_program(text, prog.moves, {line: [(0.0, length - 10.0, 1200.0), (length - 10.0, length, 400.0)]})
    for kept in ("N20 G28 G91 Z0.", "N30 T1 M6", "N45 M8", "N55 G43 Z15. H1", "M01", "N125 M9"):
        assert kept in out.splitlines(), kept
    assert "N110 G1 X90. Y80. Z-2. F1200." in out and "G1 X100. Y80. Z-2. F400." in out
    again = read_program_file_from_text(out)
    assert len(again.moves) == len(prog.moves) + 1
    assert fp.block_numbers(text)[line] == "N110"
    with pytest.raises(ValueError, match="line 3: a cutting move in incremental"):
        fp.check_rewritable("G90 G0 X0 Y0 Z5\nG91\nG1 X10. F100\n")
    fp.check_rewritable("G90 G0 X0 Y0 Z5\nG28 G91 Z0.\nG90\nG1 X10. F100\n")


def read_program_file_from_text(text):
    import tempfile

    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / "advised.nc"
        p.write_text(text)
        return read_program_file(p)


def _scripted(monkeypatch, largest_by_call):
    """predicted_errors replaced by a script: call k predicts the largest
    error largest_by_call[k] (mm), one error beyond the tolerance at the
    path's middle while it exceeds it."""
    calls = []

    def predicted(sc, robot, overrides, tol, factors):
        k = min(len(calls), len(largest_by_call) - 1)
        calls.append(overrides)
        largest = largest_by_call[k]
        s_mid = 0.5 * feed_planner.planned_path(sc).total_length
        errs = [(s_mid, largest, "corner")] if largest > tol else []
        return errs, largest, factors[0]

    monkeypatch.setattr(feed_planner, "predicted_errors", predicted)
    return calls


@pytest.fixture(scope="module")
def placed():
    from robstiff_drake.diagrams.scenario import scenario_robot

    sc = _load(work_offset=CORNER_OFFSET)
    sc.path.tolerance_mm = 0.05
    return sc, scenario_robot(sc)


def test_a_feed_plan_predicted_worse_is_not_used(monkeypatch, placed):
    """As the user's run: 0.372 mm predicted as programmed, the slower feeds
    predicted at 1.058 mm: the plan is reported, with the lines and their
    block numbers, and not used (no override, the program's cycle time)."""
    sc, robot = placed
    _scripted(monkeypatch, [0.372, 1.058])
    plan = feed_planner.plan_feeds(copy.deepcopy(sc), robot)
    assert not plan.adopted and plan.overrides == {} and plan.windows == []
    assert plan.predicted_after_max_abs_mm == plan.predicted_max_abs_mm == pytest.approx(0.372)
    assert plan.cycle_time_s == pytest.approx(plan.program_cycle_time_s)
    assert any("feed plan not used" in n and "1.058" in n for n in plan.notes), plan.notes
    assert plan.advice and all(a["feed_mm_per_min"] == a["programmed_feed_mm_per_min"] for a in plan.advice)
    assert all(a["block"].startswith("N") for a in plan.advice), plan.advice


def test_a_feed_plan_takes_the_best_windows_it_predicted(monkeypatch, placed):
    """Better at the first try, worse later: the plan is the first try's
    windows, with its prediction (not the last iteration's)."""
    sc, robot = placed
    calls = _scripted(monkeypatch, [0.372, 0.2, 0.5, 0.6, 0.7, 0.8])
    plan = feed_planner.plan_feeds(copy.deepcopy(sc), robot)
    assert plan.adopted and plan.predicted_after_max_abs_mm == pytest.approx(0.2)
    assert plan.overrides == fp.line_ranges(feed_planner.planned_path(sc), plan.windows)
    assert plan.overrides == calls[1]  # the windows the 0.2 mm came from
    assert plan.cycle_time_s > plan.program_cycle_time_s


def test_the_users_job_is_not_made_worse_by_compensation():
    """The job at the plate's corner in the scenario's default mode (plain):
    compensated, its surface error is not worse than uncompensated (mean
    and RMS), and no warning says it was."""
    from robstiff_drake.commands.simulate import simulate
    from robstiff_drake.io import Warnings

    w = Warnings()
    sc, results = simulate(scenario=str(MACHINE), toolpath=str(JOB), work_offset=CORNER_OFFSET, warnings=w)
    assert sc.controller.mode == "plain"
    off, on = (r.surface_error_mm for r in results)
    assert abs(on["mean"]) <= abs(off["mean"]) and on["rms"] <= off["rms"], (off, on)
    assert not any("made the surface worse" in x for x in w), list(w)


def test_a_worse_cut_says_why_at_corners():
    """The line appended to 'compensation made the surface worse' on a job
    with corners: the path's dynamics and the servo, not force deflection,
    and what would help (preview under the plain mode); nothing without a
    program."""
    from robstiff_drake.diagrams.job_checks import worse_reason

    sc = _load(work_offset=CORNER_OFFSET)
    why = worse_reason(sc, sc._program)
    assert "the path's own dynamics and the servo's lag, not force deflection" in why
    assert "controller.mode: preview" in why and "path.zone_mm" in why
    sc.controller.mode = "preview"
    assert "controller.mode: preview" not in worse_reason(sc, sc._program)
    assert worse_reason(sc, None) == ""


def test_a_bad_stock_is_one_line_before_anything_runs(capsys, tmp_path):
    from robstiff_drake.commands.main import main

    code = main(["simulate", str(MACHINE), "--toolpath", str(JOB), "--stock", "0,10,5,1,703", "--out",
                 str(tmp_path / "run")])
    err = capsys.readouterr().err.strip()
    assert code == 2 and err.count("\n") == 0 and "--stock" in err and "Y0 < Y1" in err, err
    assert not (tmp_path / "run").exists()
