"""One rule for every file a command reads (issue 19, item 1), whether named
on the command line or inside a scenario, robot, run folder or compensator
file: no output may be it, contain it or replace it, and an output folder
that holds an input is refused before anything is written.  And run
folders read as what they claim (symlinks out of the folder, another
robot's compensator.yaml, a wrench log in kN): one line each."""

import hashlib
import json
import shutil
import time
from pathlib import Path

import pytest

from robstiff_drake.commands.main import main
from robstiff_drake.paths import DEFAULT_ROBOT_YAML

ROOT = Path(__file__).parents[1]
SHORT = (ROOT / "tests" / "data" / "short_block.yaml").read_text()
PROGRAM = ROOT / "diagrams" / "contour_with_arcs.nc"
STIFFNESS = {"joint_stiffness_Nm_per_rad": [1.5e6, 1.1e6, 8e5, 3e5, 3e5, 2e5]}
PAYLOAD = ("payload_calibration:\n  mass_kg: 40.0\n  com_mm: [0, 0, 180]\n  force_bias_N: [3, -2, 5]\n"
           "  torque_bias_Nm: [0.2, -0.1, 0.05]\n  sensor_mount_rpy_deg: [0, 0, 0]\n")


def cli(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def digests(folder):
    return {p: hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(Path(folder).rglob("*")) if p.is_file()}


def refused_unchanged(capsys, folder, argv, *fragments):
    """The command ends in one line, exit 2, naming ``fragments``, within a
    few seconds (before any simulation), and no file under ``folder`` changes."""
    before = digests(folder)
    t0 = time.perf_counter()
    code, out, err = cli(capsys, *argv)
    assert code == 2, (out, err)
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err, err
    for f in fragments:
        assert f in lines[0], (f, lines[0])
    assert time.perf_counter() - t0 < 20.0
    assert digests(folder) == before
    return lines[0]


def scenario(folder, model="", robot=None, program=None):
    """A scenario in ``folder`` naming files beside it."""
    text = SHORT
    if model:  # (the fixture has a model section already: the keys join it)
        text = text.replace("\nmodel:\n", "\nmodel:\n" + model, 1) if "\nmodel:\n" in text else \
            text.replace("controller:", "model:\n" + model + "controller:")
    if robot:
        text = text.replace("name: short_block", f"name: short_block\nrobot: {robot}")
    if program:
        text = text.replace("path:\n", "toolpath:\n  program: " + program + "\n  work_offset_mm: [1520.0, -30.0, 700.0]\n"
                                      "path:\n").replace("  waypoints_mm:\n    - [1497.5, 0.0, 700.0]\n"
                                                          "    - [1702.5, 0.0, 700.0]\n", "")
    p = folder / "s.yaml"
    p.write_text(text)
    return p


@pytest.fixture
def named(tmp_path):
    """A scenario that names a robot file, an identification JSON and a payload YAML."""
    d = tmp_path / "cell"
    d.mkdir()
    shutil.copy(DEFAULT_ROBOT_YAML, d / "r.yaml")
    (d / "m.json").write_text(json.dumps(STIFFNESS))
    (d / "pay.yaml").write_text(PAYLOAD)
    s = scenario(d, "  identified_json: m.json\n  payload_yaml: pay.yaml\n", robot="r.yaml")
    return d, s


@pytest.mark.parametrize("target, key", [("r.yaml", "robot of"), ("m.json", "model.identified_json of"),
                                         ("pay.yaml", "model.payload_yaml of")])
@pytest.mark.parametrize("option", ["--json", "--replay"])
def test_simulate_never_writes_over_a_file_its_scenario_names(capsys, named, target, key, option):
    d, s = named
    refused_unchanged(capsys, d, ["simulate", s, option, d / target, "--out", d.parent / "o"],
                      f"{option} {d / target}: is an input of the command", key)
    assert not (d.parent / "o").exists()


def test_simulate_never_writes_over_its_program(capsys, tmp_path):
    shutil.copy(PROGRAM, tmp_path / "p.nc")
    s = scenario(tmp_path, program="p.nc")
    refused_unchanged(capsys, tmp_path, ["simulate", s, "--json", tmp_path / "p.nc", "--out", tmp_path / "o"],
                      "toolpath.program of")
    refused_unchanged(capsys, tmp_path, ["simulate", s, "--json", tmp_path / "p2.json", "--toolpath", tmp_path / "p.nc",
                                         "--out", tmp_path / "p.nc"], "--out", "holds an input of the command")


def test_an_output_folder_that_holds_a_named_input_is_refused(capsys, tmp_path):
    # the case: `simulate SC --out runcopy` deleted runcopy/m.json, the scenario's identified_json
    run = tmp_path / "runcopy"
    run.mkdir()
    (run / "RUN_ID").write_text("abc\n")
    (run / "m.json").write_text(json.dumps(STIFFNESS))
    s = scenario(tmp_path, "  identified_json: runcopy/m.json\n")
    refused_unchanged(capsys, tmp_path, ["simulate", s, "--out", run],
                      f"--out {run}: holds an input of the command ({run / 'm.json'}, model.identified_json of")


def test_a_robot_file_is_never_replaced_by_an_output(capsys, tmp_path):
    shutil.copy(DEFAULT_ROBOT_YAML, tmp_path / "R.yaml")
    r = tmp_path / "R.yaml"
    for argv in (["fk", 0, 0, 0, 0, 30, 0, "--robot", r, "--json", r],
                 ["stiffness", 0, 10, 20, 0, 30, 0, "--robot", r, "--json", r],
                 ["synth", "stiffness", r, "--robot", r],
                 ["kg-study", "--grid", 1, "--robot", r, "--json", r]):
        refused_unchanged(capsys, tmp_path, argv, f"{r}: ", "input of the command")


def test_sim_cell_never_writes_its_reference_over_the_robot_file(capsys, tmp_path):
    shutil.copy(DEFAULT_ROBOT_YAML, tmp_path / "myrobot.yaml")
    s = scenario(tmp_path, robot="myrobot.yaml")
    refused_unchanged(capsys, tmp_path, ["sim-cell", s, "--egm-to", "127.0.0.1:9", "--netft-port", "9",
                                         "--wait-s", "0.1", "--reference-out", tmp_path / "myrobot.yaml"],
                      "--reference-out", "robot of")


def test_a_compensator_files_robot_is_an_input_too(capsys, run_copy, tmp_path):
    """diagnose-run reads the robot its compensator.yaml names (relative to it)."""
    shutil.copy(DEFAULT_ROBOT_YAML, tmp_path / "mine.yaml")
    c = run_copy / "compensator.yaml"
    c.write_text(c.read_text().replace("robot: irb6400", "robot: ../mine.yaml"))
    refused_unchanged(capsys, tmp_path, ["diagnose-run", run_copy, "--json", tmp_path / "mine.yaml"],
                      f"--json {tmp_path / 'mine.yaml'}: is an input of the command")


# ------------------------------------------------------------ run folders


@pytest.fixture
def run_copy(short_run_folder, tmp_path):
    d = tmp_path / "run"
    shutil.copytree(short_run_folder, d)
    return d


@pytest.mark.parametrize("name", ["compensator.yaml", "scan.csv", "wrench_log.csv", "RUN_ID"])
def test_diagnose_run_never_writes_over_a_file_of_the_run(capsys, run_copy, name):
    refused_unchanged(capsys, run_copy, ["diagnose-run", run_copy, "--json", run_copy / name],
                      f"--json {run_copy / name}: is an input of the command")


@pytest.mark.parametrize("name", ["scan.csv", "compensator.yaml", "RUN_ID"])
def test_a_symlink_out_of_the_run_folder_is_refused_and_its_target_never_shown(capsys, run_copy, tmp_path, name):
    secret = tmp_path / "secret.txt"
    secret.write_text("TOP-SECRET first line\n")
    (run_copy / name).unlink()
    (run_copy / name).symlink_to(secret)
    line = refused_unchanged(capsys, tmp_path, ["diagnose-run", run_copy, "--out", tmp_path / "d"],
                             f"{run_copy / name}: a symbolic link to a file outside the run folder")
    assert "TOP-SECRET" not in line


def test_a_run_of_another_robot_is_refused(capsys, run_copy, tmp_path):
    c = run_copy / "compensator.yaml"
    # the case (IndexError: reduceat): the KUKA's working ranges exclude the run's angles
    c.write_text(c.read_text().replace("robot: irb6400", "robot: kr240_r2900"))
    refused_unchanged(capsys, tmp_path, ["diagnose-run", run_copy, "--out", tmp_path / "d"],
                      "joint_log.csv: row 1: q2 = ", "outside kr240_r2900's working range", "the run is not of this "
                      "robot")
    # the IRB 6640's ranges hold them, but its tool path runs 74 mm above the scanned face
    c.write_text(c.read_text().replace("robot: kr240_r2900", "robot: irb6640"))
    refused_unchanged(capsys, tmp_path, ["diagnose-run", run_copy, "--out", tmp_path / "d"],
                      "the tool path of irb6640 for these joint angles runs +7", "from the scanned face's nominal")


@pytest.mark.parametrize("scale, unit", [(1e-3, "kN"), (1e3, "mN")])
def test_a_wrench_log_in_other_units_is_refused_not_diagnosed(capsys, run_copy, tmp_path, scale, unit):
    p = run_copy / "wrench_log.csv"
    lines = []
    for ln in p.read_text().splitlines():
        if ln.startswith("#") or ln.startswith("t_s"):
            lines.append(ln)
            continue
        cells = ln.split(",")
        lines.append(",".join([cells[0]] + ["" if c == "" else repr(float(c) * scale) for c in cells[1:]]))
    p.write_text("\n".join(lines) + "\n")
    refused_unchanged(capsys, tmp_path, ["diagnose-run", run_copy, "--out", tmp_path / "d"],
                      "wrench_log.csv: the force readings are", f"the log looks like {unit}")


def test_the_run_folder_checks_pass_the_runs_own_robot(capsys, run_copy, tmp_path):
    code, out, err = cli(capsys, "diagnose-run", run_copy, "--json", "-", "--out", tmp_path / "d")
    assert code == 0, err
    assert json.loads(out)["run_id"] == (run_copy / "RUN_ID").read_text().strip()
