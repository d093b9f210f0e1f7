"""The reliability contract, one test per class of failure: an input is never
destroyed, bad input is one line and exit status 2 before any long
computation, outputs are whole and keep the user's permissions, legal files
that are not what they claim are refused or warned about, JSON is always
JSON, and an interrupted command leaves nothing behind."""

import errno
import hashlib
import json
import os
import signal
import stat
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from robstiff_drake.commands.main import main
from robstiff_drake.identification.stiffness import synth
from robstiff_drake.io import RUN_ID_FILE, RunFolder, Warnings, emit_json, json_text, write_atomic
from robstiff_drake.model.robot import load_robot

ROOT = Path(__file__).parents[1]
SHORT = ROOT / "tests" / "data" / "short_block.yaml"
ROBOT = load_robot()


def cli(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def one_line_error(code, err):
    assert code == 2, err
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("robstiff") and "error:" in lines[0], err
    assert "Traceback" not in err


def digest(path):
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


@pytest.fixture
def campaign(tmp_path):
    c = synth.stiffness_campaign(ROBOT, n=36, seed=3)
    p = tmp_path / "v.csv"
    p.write_text(synth.stiffness_csv(c, robot=ROBOT, noise_mm=0.01, seed=3, force_N=300.0, tool_m=np.zeros(3),
                                     how="test"))
    return p


@pytest.fixture
def payload(tmp_path):
    c = synth.payload_campaign(ROBOT, n=15, seed=0)
    p = tmp_path / "p.csv"
    p.write_text(synth.payload_csv(c, noise_N=1.0, noise_Nm=0.1, seed=0, how="test"))
    return p


# ------------------------------------------------------------------ outputs


@pytest.mark.parametrize("argv", [
    ["identify", "{v}", "--json", "{v}"],
    ["identify", "{v}", "--plot", "{v}"],
    ["diagnose", "{v}", "--report", "{v}"],
    ["calibrate-payload", "{p}", "--yaml", "{p}"],
    ["calibrate-payload", "{p}", "--json", "{p}"],
    ["simulate", "{s}", "--json", "{s}"],
    ["simulate", "{s}", "--out", "{sdir}"],
    ["identify", "{v}", "--json", "{vlink}"],
])
def test_an_output_that_is_an_input_is_refused(capsys, tmp_path, campaign, payload, argv):
    scen = tmp_path / "sd" / "scenario.yaml"
    scen.parent.mkdir()
    scen.write_text(SHORT.read_text())
    link = tmp_path / "link.csv"
    link.symlink_to(campaign)
    names = {"v": campaign, "p": payload, "s": scen, "sdir": scen.parent, "vlink": link}
    before = {k: digest(v) for k, v in names.items() if Path(v).is_file()}
    code, _, err = cli(capsys, *[a.format(**names) for a in argv])
    one_line_error(code, err)
    assert "input" in err
    assert {k: digest(v) for k, v in names.items() if Path(v).is_file()} == before


def test_bad_output_places_are_refused_before_computing(capsys, tmp_path, campaign):
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    ro = tmp_path / "ro.json"
    ro.write_text("{}")
    ro.chmod(0o444)
    afile = tmp_path / "a.txt"
    afile.write_text("x")
    cases = [
        (["identify", campaign, "--json", tmp_path], "is a folder"),
        (["identify", campaign, "--json", "/dev/null"], "is a device"),
        (["identify", campaign, "--json", fifo], "is a FIFO"),
        (["identify", campaign, "--json", ro], "read-only"),
        (["identify", campaign, "--json", afile / "x.json"], "is a file, not a folder"),
        (["simulate", SHORT, "--out", afile], "is a file, not a folder"),
        (["synth", "stiffness", "/dev/full"], "is a device"),
    ]
    for argv, message in cases:
        t0 = time.perf_counter()
        code, _, err = cli(capsys, *argv)
        one_line_error(code, err)
        assert message in err, (argv, err)
        assert time.perf_counter() - t0 < 5.0  # refused up front, not after the simulation
    assert ro.read_text() == "{}" and afile.read_text() == "x"


def test_a_folder_that_is_not_a_run_folder_is_never_replaced(capsys, tmp_path):
    mine = tmp_path / "thesis"
    mine.mkdir()
    (mine / "chapter1.tex").write_text("precious")
    code, _, err = cli(capsys, "simulate", SHORT, "--out", mine)
    one_line_error(code, err)
    assert "not a robstiff run folder" in err
    assert (mine / "chapter1.tex").read_text() == "precious"


def test_writes_go_through_symlinks_and_keep_the_umask_and_modes(tmp_path):
    old = os.umask(0o022)
    try:
        target = tmp_path / "real.json"
        target.write_text("old")
        target.chmod(0o640)
        link = tmp_path / "link.json"
        link.symlink_to(target)
        emit_json({"a": 1}, link)
        assert link.is_symlink() and json.loads(target.read_text()) == {"a": 1}
        assert stat.S_IMODE(target.stat().st_mode) == 0o640  # an existing file keeps its mode
        new = tmp_path / "new.csv"
        write_atomic(new, "x\n")
        assert stat.S_IMODE(new.stat().st_mode) == 0o644  # a new file gets the umask's
        with RunFolder(tmp_path / "run") as run:
            run.write("a.csv", "1\n")
        assert stat.S_IMODE((tmp_path / "run").stat().st_mode) == 0o755
        assert stat.S_IMODE((tmp_path / "run" / "a.csv").stat().st_mode) == 0o644
    finally:
        os.umask(old)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["link.json", "new.csv", "real.json", "run"]


def test_a_full_disk_is_one_line_and_leaves_no_temporary_file(capsys, tmp_path, campaign, monkeypatch):
    import robstiff_drake.io as rio

    def full(fd):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(rio.os, "fsync", full)
    out = tmp_path / "out.json"
    code, _, err = cli(capsys, "identify", campaign, "--json", out)
    one_line_error(code, err)
    assert "No space left on device" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["v.csv"]


def test_a_run_folder_is_written_as_a_whole(capsys, tmp_path):
    out = tmp_path / "run"
    assert cli(capsys, "simulate", SHORT, "--out", out)[0] == 0
    first = (out / RUN_ID_FILE).read_text().strip()
    assert (out / "sim_timeseries_uncompensated.csv").exists()
    assert cli(capsys, "simulate", SHORT, "--compensation", "on", "--out", out)[0] == 0
    second = (out / RUN_ID_FILE).read_text().strip()
    assert second != first
    assert not (out / "sim_timeseries_uncompensated.csv").exists()  # nothing of the first run is left beside it
    for name in ("sim_timeseries_compensated.csv", "sim_surface_compensated.csv", "sim_scenario.yaml",
                 "wrench_log.csv", "joint_log.csv", "compensator.yaml", "scan.csv"):
        assert f"# run_id: {second}" in (out / name).read_text().splitlines()[0]
    assert json.loads((out / "summary.json").read_text())["run_id"] == second
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]  # no temporary folder


def test_an_interrupted_run_folder_leaves_the_old_one_and_no_temporary(tmp_path):
    out = tmp_path / "run"
    with RunFolder(out) as run:
        run.write("a.txt", "first")
    with pytest.raises(KeyboardInterrupt):
        with RunFolder(out) as run:
            run.write("a.txt", "second")
            raise KeyboardInterrupt
    assert (out / "a.txt").read_text() == "first"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]


# --------------------------------------------------------- legal, but wrong


def _rows(path):
    lines = Path(path).read_text().splitlines()
    comments = [ln for ln in lines if ln.startswith("#")]
    body = [ln for ln in lines if ln and not ln.startswith("#")]
    return comments, body[0], body[1:]


def test_copies_of_a_row_are_not_new_measurements(capsys, tmp_path, campaign):
    comments, header, rows = _rows(campaign)
    same = tmp_path / "same.csv"
    same.write_text("\n".join([header] + [rows[0]] * 20) + "\n")
    code, _, err = cli(capsys, "identify", same)
    one_line_error(code, err)
    assert "1 measurement rows once 19 copies of other rows are set aside" in err
    rep = tmp_path / "rep.csv"
    rep.write_text("\n".join(comments + [header] + rows + rows[:5]) + "\n")
    code, out, err = cli(capsys, "identify", rep, "--json", "-")
    assert code == 0
    res = json.loads(out)
    assert res["n_measurements"] == len(rows)
    assert any("5 row(s) repeat an earlier row" in w for w in res["warnings"])
    assert "robstiff: warning:" in err


def _map_columns(path, out, names, fn):
    comments, header, rows = _rows(path)
    cols = header.split(",")
    new = []
    for r in rows:
        v = r.split(",")
        for n in names:
            v[cols.index(n)] = fn(v[cols.index(n)])
        new.append(",".join(v))
    out.write_text("\n".join(comments + [header] + new) + "\n")
    return out


def test_radians_sign_flips_and_zeros_are_refused(capsys, tmp_path, campaign):
    rad = _map_columns(campaign, tmp_path / "rad.csv", [f"q{i}" for i in range(1, 7)],
                       lambda v: repr(float(np.deg2rad(float(v)))))
    code, _, err = cli(capsys, "identify", rad)
    one_line_error(code, err)
    assert "look like radians" in err
    flip = _map_columns(campaign, tmp_path / "flip.csv", ["dx", "dy", "dz"], lambda v: repr(-float(v)))
    for cmd in ("identify", "diagnose"):
        code, _, err = cli(capsys, cmd, flip)
        one_line_error(code, err)
        assert "look sign-flipped" in err
    zero = _map_columns(campaign, tmp_path / "zero.csv", ["dx", "dy", "dz"], lambda v: "0.0")
    code, _, err = cli(capsys, "diagnose", zero)
    one_line_error(code, err)
    assert "all displacements dx,dy,dz are zero" in err


def test_payload_in_other_units_and_absurd_cells(capsys, tmp_path, payload):
    kn = _map_columns(payload, tmp_path / "kn.csv", ["fx", "fy", "fz", "mx", "my", "mz"],
                      lambda v: repr(float(v) / 1000.0))
    code, _, err = cli(capsys, "calibrate-payload", kn)
    one_line_error(code, err)
    assert "look like kN" in err
    huge = tmp_path / "huge.csv"
    comments, header, rows = _rows(payload)
    huge.write_text("\n".join([header, rows[0].replace(rows[0].split(",")[6], "1e308", 1)] + rows[1:]) + "\n")
    code, _, err = cli(capsys, "calibrate-payload", huge)
    one_line_error(code, err)
    assert "outside the plausible range" in err


@pytest.mark.parametrize("variant", ["excel_bom", "tab", "semicolon", "latin1", "utf16", "crlf"])
def test_spreadsheet_variants_read_the_same(capsys, tmp_path, campaign, variant):
    code, out, _ = cli(capsys, "identify", campaign, "--json", "-")
    ref = json.loads(out)["joint_stiffness_Nm_per_rad"]
    comments, header, rows = _rows(campaign)
    comments = comments + ["# operator: Jürgen, 20 °C"]
    lines = comments + [header] + rows
    if variant in ("tab", "semicolon"):
        d = "\t" if variant == "tab" else ";"
        lines = comments + [ln.replace(",", d) for ln in [header] + rows]
    text = "\n".join(lines) + "\n"
    raw = {"excel_bom": b"\xef\xbb\xbf" + text.encode("utf-8"), "latin1": text.encode("latin-1"),
           "utf16": text.encode("utf-16"), "crlf": text.replace("\n", "\r\n").encode()}.get(variant, text.encode())
    p = tmp_path / f"{variant}.csv"
    p.write_bytes(raw)
    code, out, err = cli(capsys, "identify", p, "--json", "-")
    assert code == 0, err
    np.testing.assert_allclose(json.loads(out)["joint_stiffness_Nm_per_rad"], ref, rtol=1e-12)


@pytest.mark.parametrize("cell, message", [
    ("١٢", "is not a number in ASCII digits"), ("１２", "is not a number in ASCII digits"),
    ("1_000", "'1_000' is not a number"), ("0,5", "decimal comma"), ("1e999", "too large"),
])
def test_numbers_only_in_ascii(capsys, tmp_path, campaign, cell, message):
    comments, header, rows = _rows(campaign)
    cols = header.split(",")
    v = rows[2].split(",")
    v[cols.index("fx")] = f'"{cell}"' if "," in cell else cell
    p = tmp_path / "u.csv"
    p.write_text("\n".join(comments + [header] + rows[:2] + [",".join(v)] + rows[3:]) + "\n", encoding="utf-8")
    code, _, err = cli(capsys, "identify", p)
    one_line_error(code, err)
    assert message in err and "(fx)" in err


def test_an_xlsx_workbook_is_named(capsys, tmp_path):
    p = tmp_path / "book.csv"
    p.write_bytes(b"PK\x03\x04" + bytes(range(256)))
    code, _, err = cli(capsys, "identify", p)
    one_line_error(code, err)
    assert "xlsx" in err


# ------------------------------------------------------------- scenarios


def _scenario(tmp_path, text, name="s.yaml"):
    p = tmp_path / name
    p.write_text(text)
    return p


def test_model_files_a_scenario_names_are_checked(capsys, tmp_path):
    (tmp_path / "ident.json").write_text('{"joint_stiffness_Nm_per_rad": [1.5e6, NaN, 8e5, 3e5, 3e5, 2e5]}')
    s = _scenario(tmp_path, SHORT.read_text().replace("model:\n", "model:\n  identified_json: ident.json\n"))
    code, _, err = cli(capsys, "simulate", s, "--out", tmp_path / "o")
    one_line_error(code, err)
    assert "expected six finite stiffnesses" in err
    (tmp_path / "pay.yaml").write_text("payload_calibration:\n  mass_kg: -40.0\n  com_mm: [0, 0, 180]\n")
    s = _scenario(tmp_path, SHORT.read_text().replace("model:\n", "model:\n  payload_yaml: pay.yaml\n"))
    code, _, err = cli(capsys, "simulate", s, "--out", tmp_path / "o")
    one_line_error(code, err)
    assert "pay.yaml:2: payload_calibration.mass_kg: -40 is outside the allowed range" in err
    assert not (tmp_path / "o").exists()


def test_a_sensor_the_guard_always_rejects_is_reported(capsys, tmp_path):
    s = _scenario(tmp_path, SHORT.read_text().replace("  seed: 1", "  seed: 1\n  dropout_probability: 1.0"))
    code, out, err = cli(capsys, "simulate", s, "--json", "-", "--out", tmp_path / "o")
    assert code == 0, err
    res = json.loads(out)
    assert any("rejected" in w for w in res["warnings"]), res["warnings"]
    assert any("compensation removed less than 10 %" in w for w in res["warnings"]), res["warnings"]
    assert "robstiff: warning:" in err


@pytest.mark.parametrize("argv, message", [
    (["plan-poses", "1000000000"], "outside the allowed range [6, 500]"),
    (["kg-study", "--grid", "1000"], "outside the allowed range [1, 20]"),
    (["synth", "stiffness", "x.csv", "--n", "100000000"], "outside the allowed range [6, 100000]"),
    (["synth", "stiffness", "x.csv", "--seed", "-1"], "outside the allowed range [0, 4.29497e+09]"),
    (["synth", "stiffness", "x.csv", "--force-N", "inf"], "outside the allowed range"),
    (["synth", "stiffness", "x.csv", "--noise-mm", "nan"], "outside the allowed range"),
    (["stiffness", "0", "0", "0", "0", "30", "0", "--tool", "1e200,0,0"], "outside the allowed range [-5000, 5000]"),
    (["sweep", str(SHORT), "--period-ms", "1e200"], "outside the allowed range [0.1, 1000] ms"),
    (["stiffness-map", "--force-N", "1e200"], "outside the allowed range"),
])
def test_sizes_and_numbers_that_cannot_finish_are_refused(capsys, tmp_path, monkeypatch, argv, message):
    monkeypatch.chdir(tmp_path)
    t0 = time.perf_counter()
    code, _, err = cli(capsys, *argv)
    one_line_error(code, err)
    assert message in err
    assert time.perf_counter() - t0 < 5.0
    assert list(tmp_path.iterdir()) == []


# ------------------------------------------------------------------- JSON


def test_json_is_always_json():
    text = json_text({"a": float("nan"), "b": [1.0, float("inf")], "c": np.float64("-inf"), "warnings": []})

    def refuse(token):
        raise ValueError(token)

    data = json.loads(text, parse_constant=refuse)
    assert data["a"] is None and data["b"] == [1.0, None] and data["c"] is None
    assert "not finite, written as null: a, b[1], c" in data["warnings"][0]


def test_warnings_are_one_line_each(capsys):
    w = Warnings()
    w.add("two\nlines")
    w.add("two\nlines")
    assert list(w) == ["two lines"]
    assert capsys.readouterr().err == "robstiff: warning: two lines\n"


# ------------------------------------------------------------- processes


def test_a_sweep_run_that_fails_makes_the_sweep_incomplete(monkeypatch):
    from robstiff_drake.diagrams import experiment, sweep

    def no_memory(*a, **k):
        raise MemoryError()

    monkeypatch.setattr(experiment, "run_cut", no_memory)
    rows = sweep.run_sweep(SHORT, sweep.combinations([4.0], [1], [2.0], ["plain"]), workers=1, predict=False)
    assert rows[0]["stable"] is False and "MemoryError" in rows[0]["error"]


def _marked(marker):
    """The ids of the processes whose command line holds ``marker``."""
    return subprocess.run(["pgrep", "-f", marker], capture_output=True, text=True).stdout.split()


def test_sigterm_stops_a_sweep_and_its_workers(tmp_path):
    scen = tmp_path / "sigterm_marker_scenario.yaml"
    scen.write_text((ROOT / "diagrams" / "cylinder_head.yaml").read_text())
    out = tmp_path / "sweep.json"
    proc = subprocess.Popen([sys.executable, "-m", "robstiff_drake", "sweep", str(scen), "--period-ms",
                             "4,8,12,16,24,32,48,64", "--cutoff-hz", "2,3,4,5", "--workers", "2", "--json", str(out)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=tmp_path)
    # until its two workers run (the sweep and its forked workers carry this scenario's path in their command line:
    # this test's own, whatever else runs on the machine), however
    # long this machine takes to start them (before: 6 s, on a loaded machine possibly before the workers came)
    t_end = time.monotonic() + 300.0  # a hang guard only
    while len(_marked(str(scen))) < 3 and proc.poll() is None and time.monotonic() < t_end:
        time.sleep(0.1)
    assert proc.poll() is None, "the sweep ended before it could be interrupted"
    assert len(_marked(str(scen))) >= 3, "the sweep's two workers never ran"
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 143, err
    # the last line says so; before it only the job's warnings (the cylinder head's chatter check: at the edge)
    lines = err.strip().splitlines()
    assert lines[-1] == "robstiff: terminated", err
    assert all(line.startswith("robstiff: warning: ") for line in lines[:-1]), err
    time.sleep(0.5)
    left = subprocess.run(["pgrep", "-f", "sigterm_marker_scenario"], capture_output=True, text=True).stdout.split()
    assert left == [], f"worker processes left behind: {left}"
    assert not out.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == [scen.name]


def test_ctrl_c_during_a_simulation_leaves_nothing_behind(tmp_path):
    scen = tmp_path / "slow.yaml"
    scen.write_text((ROOT / "diagrams" / "block_milling.yaml").read_text().replace("  feed_mm_per_s: 20.0",
                                                                                 "  feed_mm_per_s: 1.0"))
    proc = subprocess.Popen([sys.executable, "-m", "robstiff_drake", "simulate", str(scen), "--out",
                             str(tmp_path / "run"), "--json", str(tmp_path / "s.json")],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=tmp_path)
    time.sleep(4.0)
    assert proc.poll() is None, "the simulation ended before it could be interrupted"
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    # the last line says so, before it only the job's warnings (none from the chatter check at 1 mm/s: its 2.8 um
    # chip is linearised at the law's 10 um edge ramp, tests/test_chatter_check.py), no traceback
    lines = err.strip().splitlines()
    assert lines[-1] == "robstiff: interrupted", err
    assert all(line.startswith("robstiff: warning: ") for line in lines[:-1]), err
    assert not any("chatter:" in line for line in lines), err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["slow.yaml"]


def _import_failing(monkeypatch, error):
    import builtins

    real = builtins.__import__

    def imp(name, *a, **k):
        if name == "robstiff_drake.commands.main":
            error()
        return real(name, *a, **k)

    monkeypatch.setattr(builtins, "__import__", imp)


def test_ctrl_c_while_the_command_is_still_importing_is_one_line(monkeypatch, capsys):
    """A Ctrl-C in the first tenth of a second lands in numpy's import, which turns it into an ImportError: it
    printed numpy's traceback and exited 1 (a SIGINT 50 ms after `robstiff simulate` started); now the one line
    and 130, as later on.  An ImportError of another cause is raised as it was."""
    from robstiff_drake import cli

    def interrupted_import():
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt:
            raise ImportError("PyCapsule_Import could not import module \"datetime\"")

    _import_failing(monkeypatch, interrupted_import)
    assert cli.main(["robots"]) == 130
    assert capsys.readouterr().err == "robstiff: interrupted\n"

    def broken_install():
        raise ImportError("no module named numpy")

    _import_failing(monkeypatch, broken_install)
    with pytest.raises(ImportError, match="numpy"):
        cli.main(["robots"])


def test_ctrl_c_in_a_commands_own_import_is_one_line(monkeypatch, capsys):
    """The same later on: a Ctrl-C while a command imports Drake (`simulate` imports it lazily, seconds in on a
    loaded machine) came out of pydrake's extension as "ImportError: initialization failed": a traceback and exit
    1 (tests/test_ctrl_c_during_a_simulation_leaves_nothing_behind at load 5); now the one line and 130.  An
    ImportError of another cause is raised as it was."""
    from robstiff_drake import cli
    from robstiff_drake.commands import robots

    def interrupted(**kwargs):
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt as e:
            raise ImportError("initialization failed") from e

    monkeypatch.setattr(robots, "run", interrupted)
    assert cli.main(["robots"]) == 130
    assert capsys.readouterr().err == "robstiff: interrupted\n"

    def broken(**kwargs):
        raise ImportError("no module named pydrake")

    monkeypatch.setattr(robots, "run", broken)
    with pytest.raises(ImportError, match="pydrake"):
        cli.main(["robots"])


# ------------------------------------------------- issue 19: small contract breaks


def test_a_full_disk_at_the_second_output_leaves_neither(capsys, tmp_path, campaign, monkeypatch):
    """identify --json --plot: the plot fails on a full disk after the JSON was
    written; the JSON must not be left behind (it was: id.json)."""
    import matplotlib.figure

    def full(self, *a, **k):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(matplotlib.figure.Figure, "savefig", full)
    code, _, err = cli(capsys, "identify", campaign, "--json", tmp_path / "id.json", "--plot", tmp_path / "fit.png")
    one_line_error(code, err)
    assert "No space left on device" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["v.csv"]
    (tmp_path / "id.json").write_text("earlier")  # an earlier result stays as it was
    code, _, err = cli(capsys, "identify", campaign, "--json", tmp_path / "id.json", "--plot", tmp_path / "fit.png")
    assert code == 2 and (tmp_path / "id.json").read_text() == "earlier"


@pytest.mark.parametrize("make, message", [
    (lambda d: str(d) + "/" + ("x" * 200 + "/") * 25 + "c.csv", "the path is 5"),
    (lambda d: d / ("y" * 300 + ".csv"), "a name in it is 304 bytes long"),
])
def test_an_output_path_the_system_cannot_take_is_one_line(capsys, tmp_path, make, message):
    code, _, err = cli(capsys, "synth", "stiffness", make(tmp_path))
    one_line_error(code, err)
    assert message in err and len(err) < 500
    assert list(tmp_path.iterdir()) == []


def test_kg_study_shows_its_progress(capsys):
    code, out, err = cli(capsys, "kg-study", "--grid", "2", "--progress")
    assert code == 0
    assert "kg-study: 100%" in err and "cases" in err


@pytest.mark.parametrize("nominal", [["a"] * 6, {"a": 1}, [[1, 2], [3], 4, 5, 6, 7]])
def test_a_model_with_a_malformed_nominal_stiffness_is_one_line(capsys, tmp_path, campaign, nominal):
    assert cli(capsys, "identify", campaign, "--json", tmp_path / "m.json")[0] == 0
    doc = json.loads((tmp_path / "m.json").read_text())
    doc["joint_stiffness_nominal_Nm_per_rad"] = nominal
    (tmp_path / "m.json").write_text(json.dumps(doc))
    c = synth.payload_campaign(ROBOT, n=15, seed=0)
    (tmp_path / "p.csv").write_text(synth.payload_csv(c, noise_N=1.0, noise_Nm=0.1, seed=0, how="test"))
    assert cli(capsys, "calibrate-payload", tmp_path / "p.csv", "--yaml", tmp_path / "pay.yaml")[0] == 0
    code, _, err = cli(capsys, "compensate", "--egm-port", "9", "--netft", "127.0.0.1:9", "--model",
                       tmp_path / "m.json", "--payload", tmp_path / "pay.yaml", "--wait-s", "0.1")
    one_line_error(code, err)
    assert "joint_stiffness_nominal_Nm_per_rad: expected six numbers" in err


# ------------------------------------------------- issue 19: intervals a design cannot support


def _campaign_file(tmp_path, name, n, loads_per_pose, tool_line=None):
    tool = ROBOT.payload.tool_point_m
    c = synth.stiffness_campaign(ROBOT, n=n, loads_per_pose=loads_per_pose, seed=4, tool_m=tool)
    text = synth.stiffness_csv(c, robot=ROBOT, noise_mm=0.01, seed=4, force_N=300.0, tool_m=tool, how="test")
    if tool_line is not None:
        assert "# tool_mm: 0, 0, 350" in text
        text = text.replace("# tool_mm: 0, 0, 350", tool_line)
    p = tmp_path / name
    p.write_text(text)
    return p


@pytest.mark.parametrize("n, loads, tool_line, reason", [
    (120, 4, "# tool_mm: 0, 0, 0.35", "the tool point (0, 0, 0.35) mm is 0.35 mm from the flange: a length in metres?"),
    (24, 24, None, "every row is at one pose"),
    (20, 4, None, "5 poses for 5 identified joints"),
])
def test_intervals_a_campaign_cannot_support_are_not_printed(capsys, tmp_path, n, loads, tool_line, reason):
    p = _campaign_file(tmp_path, "c.csv", n, loads, tool_line)
    code, out, err = cli(capsys, "identify", p, "--json", tmp_path / "id.json")
    assert code == 0, err
    res = json.loads((tmp_path / "id.json").read_text())
    assert res["intervals_available"] is False
    assert any(reason in r for r in res["intervals_not_available_because"]), res["intervals_not_available_because"]
    assert all(v is None for row in res["joint_stiffness_ci95_Nm_per_rad"] for v in row)
    assert all(v is None for v in res["joint_stiffness_std_Nm_per_rad"])
    assert any("95 % intervals not available" in w for w in res["warnings"])
    assert "not available" in out and "95 % intervals not available" in err
    assert not any(line.strip().startswith("1 ") and "[" in line for line in out.splitlines())


def test_a_campaign_loaded_along_one_line_has_no_intervals(tmp_path):
    from robstiff_drake.identification.stiffness.campaign import read_stiffness_campaign
    from robstiff_drake.identification.stiffness.interval_support import interval_support

    c = read_stiffness_campaign(_campaign_file(tmp_path, "c.csv", 60, 4), ROBOT)
    assert interval_support(c, ROBOT.payload.tool_point_m, 5) == []
    c.force_N[:] = np.outer(np.where(c.force_N[:, 0] < 0, -1.0, 1.0), [300.0, 0.0, 0.0])
    assert interval_support(c, ROBOT.payload.tool_point_m, 5) == [
        "every load is along one line: the rows cannot separate the joints beyond it; load in several directions"]


@pytest.mark.parametrize("command", [
    lambda c, d: ["table2", "--json", d / "t.json", "--plot", d / "t.png"],
    lambda c, d: ["diagnose", c, "--json", d / "d.json", "--report", d / "d.md", "--plots", d / "views"],
])
def test_every_command_with_several_outputs_writes_all_or_none(capsys, tmp_path, campaign, monkeypatch, command):
    """table2 and diagnose (like identify): a full disk at the figure leaves none of the other outputs behind
    (they were written one by one before: t.json, d.json and d.md stayed)."""
    import matplotlib.figure

    def full(self, *a, **k):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(matplotlib.figure.Figure, "savefig", full)
    out = tmp_path / "out"
    out.mkdir()
    code, _, err = cli(capsys, *command(campaign, out))
    one_line_error(code, err)
    assert "No space left on device" in err
    assert list(out.iterdir()) == []


@pytest.mark.parametrize("name, code_point", [("block\x1b[2J", "U+001B"), ("two\nlines", "U+000A"),
                                              ("bidi\u202eevil", "U+202E")])
def test_a_scenario_name_with_control_characters_is_refused(capsys, tmp_path, name, code_point):
    """The scenario's name is printed in titles, report lines and the replay: an escape sequence in it
    would act on the user's terminal (it was printed raw). One line naming file, line, key and character."""
    from robstiff_drake.paths import DIAGRAMS_DIR

    text = (DIAGRAMS_DIR / "short_block.yaml").read_text(encoding="utf-8")
    p = tmp_path / "named.yaml"
    p.write_text(text.replace("name: short_block", "name: " + json.dumps(name)), encoding="utf-8")
    code, _, err = cli(capsys, "simulate", p)
    one_line_error(code, err)
    assert "named.yaml:6" in err and "name" in err and code_point in err and "\x1b" not in err


def test_a_signal_during_the_outputs_commit_waits_for_its_end():
    """staged_outputs renames its files with SIGINT/SIGTERM held: a Ctrl-C
    arrives after the last rename, never between two."""
    import os
    import signal

    from robstiff_drake.io import _signals_held

    seen = []
    old = signal.signal(signal.SIGTERM, lambda *_: seen.append("TERM"))
    try:
        with _signals_held():
            os.kill(os.getpid(), signal.SIGTERM)
            seen.append("inside")
        assert seen == ["inside", "TERM"]
    finally:
        signal.signal(signal.SIGTERM, old)


_CTRL_C_IN_DRAKES_START = """
import os, signal, sys
from robstiff_drake import cli


class CtrlC:  # a Ctrl-C that lands while Drake's native library starts (it imports cpp_template then)
    def find_spec(self, name, path, target=None):
        if name == "pydrake.common.cpp_template":
            os.kill(os.getpid(), signal.SIGINT)
        return None


def run():
    sys.meta_path.insert(0, CtrlC())
    return cli.main(sys.argv[1:])


sys.exit(run())
"""


def test_ctrl_c_while_drake_starts_is_one_line(tmp_path):
    """A Ctrl-C inside pydrake.common's start (its native library, 60-200 ms whenever a command first imports Drake;
    seconds in on a loaded machine) made Drake print "CRITICAL:drake:Could not initialize pydrake: KeyboardInterrupt"
    and a stack of import frames before the one line (tests/test_ctrl_c_during_a_simulation_leaves_nothing_behind,
    at load 7): now the Ctrl-C is held back until that import is done, and the run ends with the one line and 130.
    The Ctrl-C is sent from inside the import (no timing)."""
    script = tmp_path / "ctrl_c.py"
    script.write_text(_CTRL_C_IN_DRAKES_START)
    cp = subprocess.run([sys.executable, str(script), "simulate", "block_milling", "--out", str(tmp_path / "run")],
                        capture_output=True, text=True, cwd=tmp_path, timeout=300)
    assert cp.returncode == 130, cp.stderr
    assert cp.stderr == "robstiff: interrupted\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ctrl_c.py"]
