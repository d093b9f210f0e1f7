"""A run folder keeps the inputs it was made with (inputs/: the robot file,
the identified model, the payload calibration, the G-code program), so
`diagnose-run` and a rerun of its sim_scenario.yaml need nothing else.

First the failure issue 23 reported: a run made with a user's own robot
file (a KUKA KR 210 R2700 added by hand) recorded ``robot:
kr210_r2700.yaml`` without keeping the file; moved away from that file,
`diagnose-run` could not read it, and `--robot` was refused as disagreeing
with the run."""

import json
import shutil

import pytest
import yaml

from robstiff_drake.commands.diagnose_run import run_robot
from robstiff_drake.commands.main import main
from robstiff_drake.identification.runs import settings as rs
from robstiff_drake.paths import MODELS_DIR, scenario_file

# the KR 210's joint springs (N*m/rad): not the KR 240's, so a run that read the library's file would show it
KR210_STIFFNESS = [1.9e6, 1.4e6, 1.0e6, 3.1e5, 3.1e5, 2.1e5]


def _users_cell(folder):
    """A robot file written by hand (the KR 240 R2900's kinematics, its own name and springs) and a
    scenario naming it relative to itself, as docs/your_robot.md step 6 shows."""
    folder.mkdir()
    doc = yaml.safe_load((MODELS_DIR / "kr240_r2900.yaml").read_text())
    doc["name"], doc["joint_stiffness_Nm_per_rad"] = "kr210_r2700", KR210_STIFFNESS
    (folder / "kr210_r2700.yaml").write_text(yaml.safe_dump(doc, sort_keys=False))
    text = scenario_file("block_milling_kr240_r2900").read_text()
    assert "\nrobot: kr240_r2900\n" in text
    (folder / "my_block.yaml").write_text(text.replace("\nrobot: kr240_r2900\n", "\nrobot: kr210_r2700.yaml\n"))
    return folder / "my_block.yaml"


@pytest.fixture(scope="module")
def moved_run(tmp_path_factory):
    """A compensated cut of the user's scenario, its run folder then moved away from the user's files
    (which are deleted)."""
    tmp = tmp_path_factory.mktemp("users_robot")
    scenario = _users_cell(tmp / "cell")
    assert main(["simulate", str(scenario), "--compensation", "on", "--out", str(tmp / "run"), "--quiet"]) == 0
    elsewhere = tmp / "elsewhere"
    elsewhere.mkdir()
    shutil.move(tmp / "run", elsewhere / "run")
    shutil.rmtree(tmp / "cell")
    return elsewhere / "run"


def test_the_run_folder_keeps_the_users_robot_file_and_names_the_copy(moved_run):
    kept = moved_run / "inputs" / "kr210_r2700.yaml"
    assert yaml.safe_load(kept.read_text())["joint_stiffness_Nm_per_rad"] == KR210_STIFFNESS
    assert rs.read_settings(moved_run / "compensator.yaml")[1].robot == "inputs/kr210_r2700.yaml"
    assert yaml.safe_load((moved_run / "sim_scenario.yaml").read_text())["robot"] == "inputs/kr210_r2700.yaml"
    assert run_robot(moved_run).joint_stiffness_Nm_per_rad.tolist() == KR210_STIFFNESS


def test_diagnose_run_needs_nothing_but_the_folder(moved_run, capsys, tmp_path):
    capsys.readouterr()
    assert main(["diagnose-run", str(moved_run), "--out", str(tmp_path / "d1"), "--json", "-"]) == 0
    rep = json.loads(capsys.readouterr().out)
    assert rep["run_id"] == (moved_run / "RUN_ID").read_text().strip()
    # a candidate fix names the same robot file, relative to where the candidate is written
    for cand in (tmp_path / "d1" / "candidates").glob("*/compensator.yaml"):
        robot = rs.read_settings(cand)[1].robot
        assert (cand.parent / robot).resolve() == (moved_run / "inputs" / "kr210_r2700.yaml").resolve()
    # --robot: the same file elsewhere agrees; another robot is refused, naming both
    mine = tmp_path / "my_copy.yaml"
    shutil.copy(moved_run / "inputs" / "kr210_r2700.yaml", mine)
    assert main(["diagnose-run", str(moved_run), "--robot", str(mine), "--out", str(tmp_path / "d2"), "--quiet"]) == 0
    capsys.readouterr()
    assert main(["diagnose-run", str(moved_run), "--robot", "kr240_r2900", "--out", str(tmp_path / "d3")]) == 2
    assert "--robot kr240_r2900 disagrees with the robot of" in capsys.readouterr().err


def test_a_folder_that_lacks_its_robot_file_takes_it_from_robot(moved_run, capsys, tmp_path):
    """A folder made before runs kept their inputs (or a cell's log naming a file it does not hold):
    one line saying what to give; given, --robot stands in for the missing file, with a warning."""
    old = tmp_path / "old_run"
    shutil.copytree(moved_run, old)
    shutil.rmtree(old / "diagnosis", ignore_errors=True)
    settings = old / "compensator.yaml"
    settings.write_text(settings.read_text().replace("robot: inputs/kr210_r2700.yaml", "robot: kr210_r2700.yaml"))
    mine = tmp_path / "kr210_r2700.yaml"
    shutil.move(old / "inputs" / "kr210_r2700.yaml", mine)
    capsys.readouterr()
    assert main(["diagnose-run", str(old)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "the run folder has no such file" in err[0] and "--robot" in err[0]
    assert main(["diagnose-run", str(old), "--robot", str(mine), "--quiet"]) == 0
    assert "which the run folder lacks: taking --robot" in capsys.readouterr().err


def test_every_input_a_scenario_names_is_kept_and_named_relative_to_the_run(tmp_path, capsys):
    """The identified model, the payload calibration and the G-code program go to inputs/ too, and
    the scenario as run names the copies: read from the run folder alone, it finds them."""
    from robstiff_drake.diagrams.run_inputs import kept_inputs, write_kept
    from robstiff_drake.commands.simulate import scenario_text
    from robstiff_drake.diagrams.scenario import load_scenario, resolve
    from robstiff_drake.io import RunFolder
    from robstiff_drake.model.robot import load_robot

    cell = tmp_path / "cell"
    cell.mkdir()
    assert main(["synth", "stiffness", str(cell / "campaign.csv"), "--n", "24", "--quiet"]) == 0
    assert main(["identify", str(cell / "campaign.csv"), "--json", str(cell / "k.json"), "--quiet"]) == 0
    assert main(["synth", "payload", str(cell / "payload.csv"), "--quiet"]) == 0
    assert main(["calibrate-payload", str(cell / "payload.csv"), "--yaml", str(cell / "payload.yaml"), "--quiet"]) == 0
    capsys.readouterr()
    shutil.copy(scenario_file("contour_with_arcs").with_suffix(".nc"), cell / "part.nc")
    text = scenario_file("contour_with_arcs").read_text()
    assert "contour_with_arcs.nc" in text and "\nmodel:" not in text
    text = text.replace("contour_with_arcs.nc", "part.nc") + "model:\n  identified_json: k.json\n  payload_yaml: payload.yaml\n"
    (cell / "job.yaml").write_text(text)
    sc = load_scenario(cell / "job.yaml")
    robot = load_robot(None)
    kept = kept_inputs(sc, robot)
    assert kept.robot == "irb6400"  # a library robot keeps its name (and its copy, below)
    assert kept.names == {"robot": "inputs/irb6400.yaml", "identified_json": "inputs/k.json",
                          "payload_yaml": "inputs/payload.yaml", "program": "inputs/part.nc"}
    with RunFolder(tmp_path / "run") as run:
        write_kept(run, kept)
        run.write("sim_scenario.yaml", scenario_text(sc, run.run_id, kept))
    shutil.rmtree(cell)  # the user's files are gone
    again = load_scenario(tmp_path / "run" / "sim_scenario.yaml")
    assert again.robot == "irb6400"
    for key, ref in (("identified_json", again.model.identified_json), ("payload_yaml", again.model.payload_yaml),
                     ("program", again.toolpath.program)):
        assert resolve(again, ref).resolve() == (tmp_path / "run" / kept.names[key]).resolve(), key
        assert resolve(again, ref).is_file()
