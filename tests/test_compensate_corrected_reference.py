"""A corrected reference (compensate-program's joint_reference.csv, marked
on its first line: the model's deflection correction already in its joint
references) is never streamed with online compensation on top (the
deflection corrected twice: +0.078 / 0.228 mm mean / largest on the plant,
docs/offline_compensation.md): `compensate --reference` refuses it in one
line, exit 2, before any socket; `--reference-is-corrected` streams it with
the online correction held at zero (cell/loop_settings.LoopSettings.
correction_off), and refuses a file without the mark."""

import csv
import json
import math
import os
import time

import numpy as np
import pytest

import cell_helpers as h
from robstiff_drake.cell.compensate import CompensatorLoop, LoopSettings, Reference
from robstiff_drake.cell.link import Message
from robstiff_drake.cell.reference_file import corrected_mark
from robstiff_drake.commands import compensate as compensate_cmd
from robstiff_drake.commands.main import main
from robstiff_drake.identification.runs.logs import corrected_mark_line
from robstiff_drake.model.robot import load_robot

Q0 = [0.0, 7.008, 29.517, 0.0, 53.476, 0.0]
MARK = corrected_mark_line("robstiff compensate-program", "identified model (seed 7) of short.yaml")


@pytest.fixture
def inputs(tmp_path, monkeypatch):
    """(model, payload, an unmarked reference, the same reference marked); any link or sensor opened fails the test."""
    robot = load_robot()
    model, payload, reference, _ = h.write_inputs(str(tmp_path), robot, duration_s=0.4)
    marked = tmp_path / "joint_reference.csv"
    marked.write_text(MARK + open(reference).read())

    def no_socket(*a, **k):
        raise AssertionError("a socket was opened")

    monkeypatch.setattr(compensate_cmd, "_link", no_socket)
    monkeypatch.setattr("robstiff_drake.cell.rdt.NetFTReader", no_socket)
    return model, payload, reference, str(marked)


def _compensate(model, payload, reference, *extra):
    return main(["compensate", "--egm-port", str(h.free_udp_port()), "--netft", "127.0.0.1", "--model", model,
                 "--payload", payload, "--reference", reference, *extra])


def test_the_mark_is_found_before_the_header_only(tmp_path):
    body = "t_s,q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg\n0,0,0,0,0,0,0\n"
    f = tmp_path / "r.csv"
    f.write_text("# run_id: x\n" + MARK + body)
    assert corrected_mark(f)[0] == 2
    f.write_text(body + MARK)  # (after the header: not the file's mark)
    assert corrected_mark(f) is None
    f.write_text("# a reference\n" + body)
    assert corrected_mark(f) is None


def test_a_marked_reference_is_refused_before_any_socket(inputs, capsys):
    model, payload, _, marked = inputs
    for extra in ([], ["--mode", "preview", "--job", os.path.join(h.ROOT, "diagrams", "face_and_contour.yaml")]):
        code = _compensate(model, payload, marked, *extra)
        err = capsys.readouterr().err
        assert code == 2 and err.count("\n") == 1, err
        assert f"--reference {marked}:1: a corrected reference" in err, err
        assert "corrects the deflection twice" in err and "+0.078 mm mean, 0.228 mm" in err, err
        assert "docs/offline_compensation.md" in err and "--reference-is-corrected" in err, err


def test_the_option_is_refused_on_an_unmarked_file_and_with_preview(inputs, capsys):
    model, payload, reference, marked = inputs
    code = _compensate(model, payload, reference, "--reference-is-corrected")
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1, err
    assert "carries no corrected-reference mark" in err and "not compensated at all" in err, err
    code = _compensate(model, payload, marked, "--reference-is-corrected", "--mode", "preview", "--job",
                       os.path.join(h.ROOT, "diagrams", "face_and_contour.yaml"))
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "--mode preview would have nothing to add" in err, err
    code = main(["compensate", "--egm-port", "1", "--netft", "127.0.0.1", "--model", model, "--payload", payload,
                 "--reference-is-corrected"])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "give the corrected reference with it" in err, err


class _Recorded(h.ScriptedLink):
    def __init__(self, batches):
        super().__init__(batches)
        self.targets = []

    def send_targets(self, msg, target, env):
        self.targets.append(list(target))


@pytest.mark.parametrize("off", [None, "a corrected reference"])
def test_the_loop_holds_the_correction_at_zero(off):
    """A cutting force on the sensor: the loop corrects (None) or, with
    ``correction_off``, sends the reference itself every cycle."""
    robot = load_robot()
    w = (h.hold_wrench(robot, np.radians(Q0))(0.0) + [250.0, -150.0, 300.0, 0.0, 0.0, 0.0]).tolist()
    ref = Reference(period_s=0.004)
    ref.hold(Q0)
    link = _Recorded([[Message(k, (k - 1) * 4, Q0, echo=k)] for k in range(2, 60)])
    loop = CompensatorLoop(h.hold_compensator(robot, w), link, h.HeldSensor(w), ref, robot,
                           # (the force held from the first message: the start's check off, explicitly)
                           LoopSettings(max_jump_Nm=350.0, correction_off=off, start_tolerance_N=math.inf), log=None,
                           out=open("/dev/null", "w"))
    loop.run((Message(1, 0, Q0, echo=1), time.monotonic()))
    moved_deg = np.abs(np.asarray(link.targets) - Q0).max()
    assert len(link.targets) == 59
    if off is None:
        assert moved_deg > 0.01, moved_deg  # (0.040 deg here; before the change: the only behaviour)
    else:
        assert moved_deg == 0.0 and loop.stats()["fault_onsets"] == 0


def test_a_marked_reference_streams_with_zero_correction_against_the_cell(tmp_path):
    pytest.importorskip("pynetft", reason="the cell tests need pynetft (pip install '.[test]')")
    cp, stats, log = h.run_compensate_against_cell(tmp_path, duration_s=1.0, stream_reference=True,
                                                   wrench=h.cutting_wrench(t0=0.3, ramp_s=0.2),
                                                   extra=["--reference-is-corrected"], reference_first_line=MARK)
    assert cp.returncode == 0, cp.stderr
    assert "the online correction is held at zero for the whole run" in cp.stderr, cp.stderr
    with open(os.path.join(log, "summary.json")) as f:
        summary = json.load(f)
    assert summary["correction_held_at_zero"].startswith("--reference reference.csv is a corrected reference")
    assert summary["cycles"]["answered"] > 100 and summary["loop_check"]["pose"].startswith("--reference")
    with open(os.path.join(log, "timeseries_compensated.csv")) as f:
        rows = list(csv.reader(line for line in f if not line.startswith("#")))
    ts = {k: np.array([float(r[i]) if r[i] else np.nan for r in rows[1:]]) for i, k in enumerate(rows[0])}
    corr = np.column_stack([ts[f"correction_q{j}_rad"] for j in range(1, 7)])
    assert len(corr) > 100 and np.all(corr == 0.0)
    assert np.nanmax(np.abs(ts["raw_fx_N"])) > 100  # (the cut was on the sensor: the correction held, not idle)
    with open(os.path.join(log, "events.csv")) as f:
        assert "held at zero" in f.read()
