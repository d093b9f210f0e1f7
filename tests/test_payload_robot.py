"""The payload calibration names the robot it was computed with: a KR 210
user ran `calibrate-payload` without --robot (the IRB 6400's kinematics
turned the joint angles into gravity directions) and `compensate` took the
file without a word (the simulated cell cut 0.1 mm shallow).  Now
calibrate-payload writes payload_calibration.robot (the robot file's name:
--robot's, or the default's) and the JSON's ``robot``; compensate warns, in
the text and in summary.json's warnings, when it is another robot than the
one in use, and a simulated scenario's model.payload_yaml likewise; a file
written before the key still loads, with a note that it names no robot.
Before: no key was written, and `robot: irb6400` in a payload file was
refused as an unknown key."""

import json
import os
import sys
from pathlib import Path

import pytest

from robstiff_drake.commands.main import main
from robstiff_drake.diagrams.scenario_models import read_payload_calibration
from robstiff_drake.model.robot import load_robot

ROOT = Path(__file__).resolve().parents[1]
PAYLOAD_CSV = ROOT / "examples" / "payload.csv"
OLD_FILE = """payload_calibration:
  mass_kg: 40.0
  com_mm: [0.0, 0.0, 180.0]
  force_bias_N: [0.0, 0.0, 0.0]
  torque_bias_Nm: [0.0, 0.0, 0.0]
  sensor_mount_rpy_deg: [0.0, 0.0, 0.0]
"""


def cli(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


@pytest.mark.parametrize("robot_arg", [None, "irb6640"])
def test_calibrate_payload_writes_the_robot_and_reads_it_back(capsys, tmp_path, robot_arg):
    before = PAYLOAD_CSV.read_bytes()
    extra = [] if robot_arg is None else ["--robot", robot_arg]
    code, out, err = cli(capsys, "calibrate-payload", PAYLOAD_CSV, "--yaml", tmp_path / "p.yaml",
                         "--json", tmp_path / "p.json", *extra)
    assert code == 0, err
    name = robot_arg or "irb6400"
    text = (tmp_path / "p.yaml").read_text()
    assert f"\n  robot: {name}  #" in text, text
    assert read_payload_calibration(tmp_path / "p.yaml").robot == name
    assert json.loads((tmp_path / "p.json").read_text())["robot"] == name
    assert PAYLOAD_CSV.read_bytes() == before  # the input untouched


def test_a_name_yaml_would_read_otherwise_reads_back_as_written(tmp_path):
    from robstiff_drake.identification.stiffness.payload import yaml_name

    for name in ("irb6400", "yes", "null", "6400", "my robot", 'a "quoted" name', "kr210-r2700.v2"):
        (tmp_path / "p.yaml").write_text(OLD_FILE + f"  robot: {yaml_name(name)}\n")
        assert read_payload_calibration(tmp_path / "p.yaml").robot == name


def test_the_note_and_the_warning(tmp_path):
    from robstiff_drake.commands.compensate_inputs import payload_robot_note

    robot = load_robot("kr240_r2900")
    (tmp_path / "old.yaml").write_text(OLD_FILE)
    (tmp_path / "other.yaml").write_text(OLD_FILE + "  robot: irb6400\n")
    (tmp_path / "same.yaml").write_text(OLD_FILE + "  robot: kr240_r2900\n")
    warning, note = payload_robot_note(robot, read_payload_calibration(tmp_path / "old.yaml"), "old.yaml")
    assert warning is None and "old.yaml names no robot" in note and "kr240_r2900" in note, note
    warning, note = payload_robot_note(robot, read_payload_calibration(tmp_path / "other.yaml"), "other.yaml",
                                       "my_kr240.yaml")
    assert note is None and "\n" not in warning
    assert "other.yaml: calibrated with the robot 'irb6400', not 'kr240_r2900'" in warning, warning
    assert "--robot my_kr240.yaml" in warning, warning
    assert payload_robot_note(robot, read_payload_calibration(tmp_path / "same.yaml"), "same.yaml") == (None, None)


def test_compensate_warns_before_any_socket(capsys, tmp_path):
    """With another robot's calibration: the warning with the start's checks (here before the refusal of --netft
    and --controller naming one endpoint, exit 2, no socket); an old file: the note."""
    assert cli(capsys, "identify", ROOT / "examples" / "campaign.csv", "--json", tmp_path / "model.json",
               "--quiet")[0] == 0
    (tmp_path / "other.yaml").write_text(OLD_FILE + "  robot: kr240_r2900\n")
    (tmp_path / "old.yaml").write_text(OLD_FILE)
    argv = ["compensate", "--listen-port", "6511", "--controller", "127.0.0.1:6510", "--netft", "127.0.0.1:6510",
            "--model", tmp_path / "model.json", "--payload"]
    code, _, err = cli(capsys, *argv, tmp_path / "other.yaml")
    assert code == 2 and "same address and port" in err
    said = [ln for ln in err.splitlines() if "calibrated with the robot" in ln]
    assert len(said) == 1 and said[0].startswith("robstiff: warning: compensate: --payload "), err
    assert "'kr240_r2900', not 'irb6400'" in said[0], said
    code, _, err = cli(capsys, *argv, tmp_path / "old.yaml")
    assert code == 2 and "calibrated with the robot" not in err
    assert "robstiff: note: compensate: --payload " in err and "names no robot" in err, err


def test_a_scenario_with_another_robots_payload_is_warned(tmp_path):
    from robstiff_drake.diagrams.scenario import load_scenario
    from robstiff_drake.diagrams.scenario_models import scenario_warnings
    from robstiff_drake.paths import DIAGRAMS_DIR

    robot = load_robot()
    for name, robot_key in (("other", "  robot: kr240_r2900\n"), ("same", "  robot: irb6400\n"), ("old", "")):
        (tmp_path / f"{name}.yaml").write_text(OLD_FILE + robot_key)
        text = (DIAGRAMS_DIR / "short_block.yaml").read_text()
        assert text.count("\nmodel:\n") == 1
        path = tmp_path / f"scenario_{name}.yaml"
        path.write_text(text.replace("\nmodel:\n", f"\nmodel:\n  payload_yaml: {name}.yaml\n"))
        said = [w for w in scenario_warnings(load_scenario(path), robot) if "calibrated with the robot" in w]
        assert len(said) == (name == "other"), said
        if said:
            assert "model.payload_yaml: calibrated with the robot 'kr240_r2900', not the scenario's 'irb6400'" \
                in said[0]


@pytest.mark.skipif(not all(__import__("importlib").util.find_spec(m) for m in ("pynetft", "abb_robot_client")),
                    reason="the cell tests need pynetft and abb-robot-client (pip install '.[test]')")
def test_summary_json_holds_the_warning(tmp_path):
    """A short run against a scripted controller with another robot's calibration: the warning in the text,
    events.csv and summary.json's warnings; the run itself as before."""
    sys.path.insert(0, os.path.dirname(__file__))
    import cell_helpers as h

    robot = load_robot()
    model, payload, _, ref_fn = h.write_inputs(str(tmp_path), robot, duration_s=0.5)
    text = Path(payload).read_text()
    assert "  robot: irb6400\n" in text
    Path(payload).write_text(text.replace("  robot: irb6400\n", "  robot: kr240_r2900\n"))
    q0 = [float(v) for v in __import__("numpy").degrees(ref_fn(0.0))]
    sensor = h.FakeSensor(h.hold_wrench(robot, ref_fn(0.0)))
    log = str(tmp_path / "log")
    _, code, err = h.held_run(model, payload, sensor, h.free_udp_port(), q0, 20, log=log)
    assert code == 0, err
    said = [x for x in err.splitlines() if "calibrated with the robot" in x]
    assert len(said) == 1 and said[0].startswith("robstiff: warning: compensate: "), err
    summary = json.loads(Path(log, "summary.json").read_text())
    warned = [w for w in summary["warnings"] if "calibrated with the robot 'kr240_r2900'" in w]
    assert len(warned) == 1 and warned[0] in said[0], summary["warnings"]
    assert "calibrated with the robot" in Path(log, "events.csv").read_text()
