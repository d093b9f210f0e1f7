"""Offline compensation (robstiff compensate-program): the correction split
within the chord tolerance, the program written again in its own words and
read back, the clamp, the RAPID module read back by a small reader of our
own, and bad inputs refused with nothing written."""

import json
import re
from pathlib import Path

import numpy as np
import pytest

from robstiff_drake.model import program_correction as pc
from robstiff_drake.model import rapid_writer as rw
from robstiff_drake.model.gcode.program import read_program
from robstiff_drake.model.gcode.writer import rewrite_corrected

ROOT = Path(__file__).resolve().parents[1]

SHORT = """%
O0001 (SHORT FACE PASS WITH AN ARC)
N10 G21 G17 G90 G40 G49 G80 G94
N20 G54
N30 S3600 M3
N40 G0 X0. Y40. Z10.
N50 G1 Z-3. F1200. (PLUNGE)
N60 X40. M8
N70 G3 X60. Y60. R20.
N80 G1 Y70.
N90 G0 Z20.
N100 M9
N110 M30
%
"""


# ---------------------------------------------------------------- a small RAPID reader of our own

_ROBTARGET = r"\[\[([^\]]*)\],\[([^\]]*)\],\[([^\]]*)\],\[([^\]]*)\]\]"


def read_rapid(text):
    """The module read as RAPID's grammar has the features we write: a
    MODULE with declarations (PERS tooldata / wobjdata, CONST speeddata /
    zonedata) and one PROC main of MoveL / MoveC to inline robtargets.
    Returns (module name, {declared name: type}, [(instruction, [targets],
    speed, zone, tool, wobj)]); AssertionError on anything else."""
    lines = [ln.strip() for ln in text.splitlines() if ln.strip() and not ln.strip().startswith("!")]
    m = re.fullmatch(r"MODULE ([A-Za-z][A-Za-z0-9_]{0,31})", lines[0])
    assert m, lines[0]
    assert lines[-1] == "ENDMODULE"
    declared, moves, in_proc = {}, [], False
    for ln in lines[1:-1]:
        if ln == "PROC main()":
            in_proc = True
            continue
        if ln == "ENDPROC":
            in_proc = False
            continue
        assert ln.endswith(";"), ln
        if not in_proc:
            d = re.fullmatch(r"(PERS|CONST) (tooldata|wobjdata|speeddata|zonedata) ([A-Za-z][A-Za-z0-9_]{0,31}) := "
                             r"(\[.*\]);", ln)
            assert d, ln
            declared[d.group(3)] = d.group(2)
            continue
        mv = re.fullmatch(r"(MoveL|MoveC) (.*),([A-Za-z][A-Za-z0-9_]*),([A-Za-z][A-Za-z0-9_]*),"
                          r"([A-Za-z][A-Za-z0-9_]*)\\WObj:=([A-Za-z][A-Za-z0-9_]*);", ln)
        assert mv, ln
        targets = []
        for pos, quat, conf, extax in re.findall(_ROBTARGET, mv.group(2)):
            targets.append((np.array([float(v) for v in pos.split(",")]),
                            np.array([float(v) for v in quat.split(",")]),
                            [int(v) for v in conf.split(",")], extax))
        assert len(targets) == (2 if mv.group(1) == "MoveC" else 1), ln
        moves.append((mv.group(1), targets, mv.group(3), mv.group(4), mv.group(5), mv.group(6)))
    return m.group(1), declared, moves


def check_rapid(text):
    name, declared, moves = read_rapid(text)
    for kind, targets, speed, zone, tool, wobj in moves:
        assert declared.get(speed) == "speeddata" and declared.get(tool) == "tooldata"
        assert declared.get(wobj) == "wobjdata" and (zone == "fine" or declared.get(zone) == "zonedata")
        for pos, quat, conf, extax in targets:
            assert pos.shape == (3,) and np.all(np.isfinite(pos))
            assert abs(np.linalg.norm(quat) - 1.0) < 1e-6
            assert len(conf) == 4 and 0 <= conf[3] <= 7
            assert extax == ",".join(["9E9"] * 6)
    return name, declared, moves


# ---------------------------------------------------------------- the correction's geometry


def _line(length, line=60):
    from robstiff_drake.model.gcode.moves import Move

    return Move("line", (0.0, 0.0, 0.0), (length, 0.0, 0.0), 1200.0, 3600.0, line)


def test_a_long_move_is_split_within_the_chord():
    move = _line(100.0)
    frac = np.linspace(0.0, 1.0, 1001)
    base = pc.move_points(move, frac)
    delta = np.column_stack([0 * frac, 0.2 * np.sin(3 * np.pi * frac), 0.1 * frac])
    pieces = pc.split_move(move, base[0] + delta[0], base, delta, 0.005, 1e-4)
    assert 5 < len(pieces) < 200
    ends = np.array([p.end_mm for p in pieces])
    assert np.allclose(ends[-1], base[-1] + delta[-1], atol=1e-4)
    # every sample of the corrected path lies within the chord (and the rounding) of the written polyline
    poly = np.vstack([base[0] + delta[0], ends])
    target = base + delta
    dist = [min(np.linalg.norm(pc._line_deviation(p[None], a, b)) for a, b in zip(poly[:-1], poly[1:]))
            for p in target]
    assert max(dist) <= 0.005 + 2e-4
    # a correction constant along the move is one block
    const = np.tile([0.0, 0.3, -0.1], (len(frac), 1))
    assert len(pc.split_move(move, base[0] + const[0], base, const, 0.005, 1e-4)) == 1


def test_arc_pieces_are_arcs_on_their_circles():
    prog = read_program(SHORT, "short.nc")
    arc = next(m for m in prog.moves if m.kind == "arc")
    frac = np.linspace(0.0, 1.0, 301)
    base = pc.move_points(arc, frac)
    delta = np.column_stack([0.1 * frac, -0.2 * frac ** 2, 0.05 * np.sin(np.pi * frac)])
    pieces = pc.split_move(arc, base[0] + delta[0], base, delta, 0.005, 1e-4)
    assert len(pieces) > 1
    start = base[0] + delta[0]
    for p in pieces:
        c = np.asarray(p.center_mm)
        assert abs(np.hypot(*(start[:2] - c)) - np.hypot(*(p.end_mm[:2] - c))) < 2e-3
        start = p.end_mm


def _corrections(prog, delta_of, chord=0.005, clamp=1.0):
    def samples(idx, frac, before, after):
        m = prog.moves[idx]
        base = pc.move_points(m, frac)
        return base, delta_of(base)

    return pc.correct_moves(prog.moves, samples, chord_mm=chord, max_correction_mm=clamp, round_mm=1e-4,
                            is_cutting=lambda m: m.kind != "rapid", label="short.nc")


def test_the_program_is_written_in_its_own_words_and_reads_back():
    prog = read_program(SHORT, "short.nc")
    corr = _corrections(prog, lambda p: np.column_stack([0.1 + 0.002 * p[:, 0], -0.2 + 0 * p[:, 0],
                                                         0.05 * np.sin(p[:, 0] / 10.0)]))
    text, added = rewrite_corrected(SHORT, prog.moves, corr, ["HEADER (WITH PARENS)"])
    back = read_program(text, "corrected.nc")
    assert back.warnings == []
    assert added > 0 and len(back.moves) == len(prog.moves) + added
    lines = text.splitlines()
    assert lines[2] == "(HEADER [WITH PARENS])"  # after the program number
    # line numbers, comments, other words and the rapids are kept, in order
    assert [ln.split()[0] for ln in lines if ln.startswith("N")] == [f"N{n}" for n in range(10, 120, 10)]
    assert "N40 G0 X0. Y40. Z10." in lines and "N90 G0 Z20." in lines and "N100 M9" in lines
    assert any(ln.startswith("N50 G1") and "F1200." in ln and "(PLUNGE)" in ln for ln in lines)
    assert any(ln.startswith("N60 X") and "M8" in ln for ln in lines)
    assert any(ln.startswith("N70 G3") and " R" in ln for ln in lines)
    # every written point within the clamp (here 0.1 + 0.12 + 0.2 + 0.05 mm) of the programmed move it belongs to
    k = 0
    frac = np.linspace(0, 1, 2001)
    for orig in prog.moves:
        n = len(corr[orig.line].pieces) if orig.line in corr else 1
        for m in back.moves[k:k + n]:
            d = np.min(np.linalg.norm(pc.move_points(orig, frac) - np.asarray(m.end_mm), axis=1))
            assert d <= 0.471  # (a rapid's unnamed axes stay where the corrected cut left them)
            if orig.kind == "rapid":
                assert m.end_mm[2] == orig.end_mm[2]
        k += n
    assert k == len(back.moves)


def test_rapids_and_moves_left_alone_are_untouched():
    prog = read_program(SHORT, "short.nc")
    corr = _corrections(prog, lambda p: np.tile([0.0, 0.0, 0.2], (len(p), 1)))
    text, added = rewrite_corrected(SHORT, prog.moves, corr)
    written = text.splitlines()
    for line in SHORT.splitlines():
        if not any(w in line for w in ("G1", "G3", "X40")):  # rapids, set-up and end lines: as they were
            assert line in written
    assert len(written) == len(SHORT.splitlines()) + added
    # a correction constant along a move between corrected moves adds no block
    assert len(corr[8].pieces) == 1 and len(corr[10].pieces) == 1


def test_a_correction_beyond_the_clamp_names_the_line():
    prog = read_program(SHORT, "short.nc")
    with pytest.raises(pc.CorrectionError, match=r"short\.nc:8: the predicted correction is 1\.500 mm at [\d.]+ mm along the "
                       r"move's [\d.]+ mm, more than --max-correction-mm 1"):
        _corrections(prog, lambda p: np.column_stack([0 * p[:, 0], 0 * p[:, 0], 1.5 * (p[:, 0] >= 39.0)]))


def test_incremental_corrected_lines_are_refused():
    from robstiff_drake.model.gcode.writer import ProgramWriteError

    text = SHORT.replace("N60 X40. M8", "N60 G91 X40. M8").replace("N70 G3", "N70 G90 G3")
    prog = read_program(text, "inc.nc")
    corr = _corrections(prog, lambda p: np.tile([0.0, 0.0, 0.1], (len(p), 1)))
    with pytest.raises(ProgramWriteError, match="line 8: incremental"):
        rewrite_corrected(text, prog.moves, corr)


def test_the_rapid_module_reads_back():
    q = rw.quaternion(np.diag([-1.0, 1.0, -1.0]))
    targets = [rw.Target("line", np.array([0.0, 40.0, 10.0]), q, (0, 0, 0, 1), 100.0, True, 6),
               rw.Target("line", np.array([40.1, 39.8, -2.9]), q, (0, -1, 0, 1), 20.0, False, 8),
               rw.Target("arc", np.array([60.0, 60.0, -2.9]), q, (0, -1, 0, 1), 20.0, False, 9,
                         np.array([54.1, 45.9, -2.9]), q, (0, -1, 0, 1))]
    text = rw.module_text("short_compensated", targets, tool_mm=[0, 0, 250], payload_mass_kg=40.0,
                          payload_com_mm=[0, 0, 120], wobj_mm=[1600, -40, 700], wobj_quat=[1, 0, 0, 0], zone_mm=5.0)
    name, declared, moves = check_rapid(text)
    assert name == "short_compensated"
    assert [m[0] for m in moves] == ["MoveL", "MoveL", "MoveC"]
    assert np.allclose(moves[1][1][0][0], [40.1, 39.8, -2.9]) and moves[1][1][0][2] == [0, -1, 0, 1]
    assert declared["zProg"] == "zonedata" and declared["tSpindle"] == "tooldata"


# ---------------------------------------------------------------- the command, on a short job


def short_job(folder, program=SHORT):
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "short.nc").write_text(program)
    text = (ROOT / "diagrams" / "face_and_contour.yaml").read_text()
    text = text.replace("program: face_and_contour.nc", "program: short.nc").replace("source: identified",
                                                                                        "source: nominal")
    (folder / "short.yaml").write_text(text)
    return folder / "short.yaml"


@pytest.fixture(scope="module")
def written(tmp_path_factory):
    from robstiff_drake.commands.main import main

    folder = tmp_path_factory.mktemp("job")
    job = short_job(folder)
    out = folder / "corrected"
    code = main(["compensate-program", str(job), "--out", str(out), "--json", str(folder / "s.json"),
                 "--no-simulate"])
    return code, job, out, json.loads((folder / "s.json").read_text())


def test_the_command_writes_a_program_simulate_reads(written):
    from robstiff_drake.diagrams.scenario import load_scenario

    code, job, out, summary = written
    assert code == 0
    files = sorted(p.name for p in out.iterdir())
    assert {"short_compensated.nc", "short_compensated.mod", "joint_reference.csv"} <= set(files)
    assert set(summary) >= {"program", "predicted_error_mm", "segments_added", "max_correction_mm", "simulated"}
    assert set(summary["predicted_error_mm"]["before"]) == {"mean", "max_abs"}
    assert 0 < summary["max_correction_mm"] <= 1.0 and summary["simulated"] is None
    sc = load_scenario(job, toolpath=out / "short_compensated.nc")  # simulate's reader: no warning, same feeds
    assert sc._program.warnings == [] and sc._program.feeds_mm_per_min() == [1200.0]
    text = (out / "short_compensated.nc").read_text()
    assert "PREDICTED SURFACE ERROR" in text and "N40 G0 X0. Y40. Z10." in text
    # the joint reference is the format compensate --reference reads
    from robstiff_drake.commands.compensate import read_reference
    from robstiff_drake.diagrams.scenario import scenario_robot

    t, q = read_reference(out / "joint_reference.csv", scenario_robot(sc))
    assert len(t) > 100 and np.shape(q)[1] == 6
    # marked on its first line as a corrected reference (compensate --reference refuses it with online
    # compensation: the deflection corrected twice; tests/test_compensate_corrected_reference.py)
    from robstiff_drake.cell.reference_file import corrected_mark

    first = (out / "joint_reference.csv").read_text().splitlines()[0]
    assert corrected_mark(out / "joint_reference.csv") == (1, first)
    assert first.startswith("# corrected_reference: ") and "compensate-program" in first
    assert "model of short.yaml" in first and "--reference-is-corrected" in first


def test_the_job_is_checked_for_chatter_before_it_is_corrected(written):
    """The corrected program leaves the cut's forces as they are: the summary carries the chatter check of the
    job (diagrams/chatter_check.py, as simulate's) and its warning when the cut would chatter."""
    from robstiff_drake.diagrams.chatter_check import chatter_check
    from robstiff_drake.diagrams.scenario import load_scenario, scenario_robot

    _, job, _, summary = written
    sc = load_scenario(job)
    direct = chatter_check(sc, scenario_robot(sc))
    got = summary["chatter_check"]
    assert got is not None and direct is not None
    assert got["stable"] == direct["stable"] and got["poses_checked"] == direct["poses_checked"] > 0
    assert got["growth_per_s"] == pytest.approx(direct["growth_per_s"], rel=1e-9, abs=1e-9)
    assert any(w.startswith("chatter:") for w in summary["warnings"]) == (not got["stable"])


def test_the_rapid_module_follows_the_program_with_the_preview_correction(written, tmp_path):
    """The RAPID targets turn the tool, so they take the preview's six-axis
    correction as it is: block for block the program written with no floor
    refinement (--refine-rounds 0), not the refined G-code."""
    from robstiff_drake.commands.main import main

    _, job, out, summary = written
    assert summary["refinement_rounds"] == 2 and len(summary["predicted_error_by_round_mm"]) == 3
    assert main(["compensate-program", str(job), "--out", str(tmp_path / "plain"), "--no-simulate",
                 "--refine-rounds", "0"]) == 0
    _, _, moves = check_rapid((out / "short_compensated.mod").read_text())
    prog = read_program((tmp_path / "plain" / "short_compensated.nc").read_text(), "c.nc")
    refined = read_program((out / "short_compensated.nc").read_text(), "r.nc")
    z, z_refined = (np.array([m.end_mm[2] for m in p.moves if m.kind != "rapid" and m.end_mm[2] < 0.0])
                    for p in (prog, refined))  # the written floor (the cut 3 mm deep)
    assert len(z) and len(z_refined) and abs(np.mean(z) - np.mean(z_refined)) > 1e-3  # the G-code's floor is refined
    assert len(moves) == len(prog.moves) + 1  # (first the program's start point)
    assert np.allclose(moves[0][1][0][0], prog.start_mm)
    quats = [t[1] for _, targets, *_ in moves for t in targets]
    assert min(float(a @ b) for a, b in zip(quats[:-1], quats[1:])) > 0.99  # no sign flips along the path
    for (kind, targets, *_), m in zip(moves[1:], prog.moves):
        assert (kind == "MoveC") == (m.kind == "arc")
        assert np.allclose(targets[-1][0], m.end_mm, atol=1e-3)


def _refused(capsys, argv, out):
    from robstiff_drake.commands.main import main

    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    errors = [ln for ln in err if ln.startswith("robstiff: error:")]
    assert len(errors) == 1 and err[-1] == errors[0], err  # one line (after the progress lines), no traceback
    assert not out.exists()
    return errors[0]


def test_bad_inputs_exit_2_with_nothing_written(tmp_path, capsys):
    job = short_job(tmp_path / "a", SHORT.replace("N60 X40. M8", "N60 G41 D1 X40. M8"))
    line = _refused(capsys, ["compensate-program", str(job), "--out", str(tmp_path / "o1")], tmp_path / "o1")
    assert "short.nc:8" in line and "G41" in line
    job = short_job(tmp_path / "b")
    before = (tmp_path / "b" / "short.nc").read_text()
    line = _refused(capsys, ["compensate-program", str(job), "--out", str(tmp_path / "o2"),
                             "--max-correction-mm", "0.01"], tmp_path / "o2")
    assert "--max-correction-mm 0.01" in line and re.search(r"short\.nc:\d+:", line)
    # an output folder that holds an input
    line = _refused(capsys, ["compensate-program", str(job), "--out", str(tmp_path / "b")], tmp_path / "nothing")
    assert "--out" in line
    assert (tmp_path / "b" / "short.nc").read_text() == before


def test_a_corrected_point_out_of_reach_is_refused(tmp_path, capsys, monkeypatch):
    from robstiff_drake.model import ik

    job = short_job(tmp_path / "c")
    real = ik.solve_for

    def solve_for(robot, pose, tool, q_ref_rad=None):  # a tilted tool cannot reach below the plate's top
        tilted = np.abs(pose[:3, 2] - [0.0, 0.0, -1.0]).max() > 1e-12
        if tilted and pose[2, 3] < 0.699:
            raise ik.IKError("tool point out of reach")
        return real(robot, pose, tool, q_ref_rad=q_ref_rad)

    import robstiff_drake.diagrams.offline_compensation  # noqa: F401 (imports ik before the patch)

    monkeypatch.setattr(ik, "solve_for", solve_for)
    line = _refused(capsys, ["compensate-program", str(job), "--out", str(tmp_path / "o3"), "--no-simulate"],
                    tmp_path / "o3")
    assert "out of the robot's reach" in line and re.search(r"short\.nc:\d+:", line)


def test_a_posted_program_keeps_its_posted_words():
    """A generic Fanuc post's program (G28 G91 Z0., T1 M6, G43 H1, M8 / M9,
    a blank line) written again with a correction varying along it: the
    reader takes it without a warning and every posted line is still there."""
    text = (ROOT / "diagrams" / "face_contour_fanuc.nc").read_text()
    prog = read_program(text, "posted.nc")
    corr = _corrections(prog, lambda p: np.column_stack([0.05 * np.sin(p[:, 0] / 15.0), -0.1 + 0 * p[:, 0],
                                                         0.03 * np.cos(p[:, 1] / 10.0)]))
    out, added = rewrite_corrected(text, prog.moves, corr, ["HEADER"])
    back = read_program(out, "posted_compensated.nc")
    assert back.warnings == [] and added > 0 and len(back.moves) == len(prog.moves) + added
    written = out.splitlines()
    for line in ("N20 G28 G91 Z0.", "N30 T1 M6", "N45 M8", "N55 G43 Z15. H1", "N100 M9", ""):
        assert line in written
    assert sum(1 for ln in written if ln.startswith("N65 G1") and "F300." in ln) == 1


def test_the_rapid_module_runs_back_through_the_plan(tmp_path):
    """The proof's RAPID run (diagrams/rapid_proof.py): the module read
    back, its joint references on the plan of the program it was written
    from (the same tool points), turned as its targets are; a module that
    does not follow that program is refused."""
    from robstiff_drake.commands.main import main
    from robstiff_drake.diagrams.milling_cell import planned_path
    from robstiff_drake.diagrams.rapid_proof import rapid_reference
    from robstiff_drake.diagrams.scenario import load_scenario, scenario_robot
    from robstiff_drake.model import kinematics as kin
    from robstiff_drake.model.rapid_reader import read_moves, rotation

    job = short_job(tmp_path / "job")
    out = tmp_path / "out"
    assert main(["compensate-program", str(job), "--out", str(out), "--no-simulate", "--refine-rounds", "0"]) == 0
    sc = load_scenario(job)
    robot = scenario_robot(sc)
    tool = robot.tool_point(where="test")
    module = (out / "short_compensated.mod").read_text()
    program = out / "short_compensated.nc"
    t, q = rapid_reference(sc, robot, module, program, tool)
    _, t_plan, q_plan = planned_path(load_scenario(job, toolpath=program), robot, tool)
    assert np.allclose(t, t_plan)
    assert np.max(np.abs(kin.tool_position(robot.dh, q, tool) - kin.tool_position(robot.dh, q_plan, tool))) < 1e-6
    # the tool turned as the targets say: at the sample nearest each target its orientation (a 1e-4 rad tolerance:
    # the plan passes a target within its zone, not at it)
    R_plan = np.array([kin.tool_pose(robot.dh, qk, tool)[:3, :3] for qk in q])
    p_plan = kin.tool_position(robot.dh, q, tool) * 1e3
    tilts = []
    for m in read_moves(module)[1:]:
        p, quat = m.targets[-1]
        k = int(np.argmin(np.linalg.norm(p_plan - (p + np.asarray(sc.toolpath.work_offset_mm)), axis=1)))
        R = rotation(quat)
        tilts.append(np.arccos(np.clip(R[:, 2] @ np.array([0.0, 0.0, -1.0]), -1, 1)))
        assert np.arccos(np.clip((np.trace(R.T @ R_plan[k]) - 1) / 2, -1, 1)) < 1e-4
    assert max(tilts) > 1e-5  # the module does turn the tool
    lines = module.splitlines()
    k = next(i for i, ln in enumerate(lines) if ln.strip().startswith("MoveL") and "vFeed" in ln)
    moved = lines[k].split("[[", 1)  # its target moved 0.5 mm in x
    x = moved[1].split(",", 1)
    lines[k] = moved[0] + "[[" + f"{float(x[0]) + 0.5:g}," + x[1]
    with pytest.raises(ValueError, match="not the program's block end"):
        rapid_reference(sc, robot, "\n".join(lines), program, tool)


def test_a_fanuc_job_is_told_the_rapid_module_is_abbs():
    """A FANUC user got pocket_compensated.mod (RAPID robtargets with an ABB
    configuration) beside the corrected G-code without a word."""
    from robstiff_drake.commands.compensate_program import rapid_note
    from robstiff_drake.model.robot import load_robot

    note = rapid_note(load_robot("r2000ic_165f"), "pocket_compensated.mod")
    assert note and note.startswith("pocket_compensated.mod is an ABB RAPID module") and "FANUC" in note
    assert "--reference-is-corrected" in note
    assert rapid_note(load_robot("irb6400"), "x.mod") is None
