"""compensate warns when the payload calibration's mass is far from the
robot file's payload mass: a KR 210 user who ran real_cell.md's
`calibrate-payload payload_poses.csv --yaml payload.yaml` (no --robot: the
irb6400's kinematics) or calibrated another tool got no word, and the
simulated cell cut 0.105 mm shallow with a 40 kg calibration on a 45 kg
payload (simulate's compensated mean: +0.001 mm)."""

from pathlib import Path

from robstiff_drake.commands.compensate_inputs import payload_mass_note
from robstiff_drake.model.robot import load_robot

ROOT = Path(__file__).resolve().parents[1]

CALIBRATION = """payload_calibration:
  mass_kg: {mass}
  com_mm: [0.0, 0.0, 180.0]
  force_bias_N: [0.0, 0.0, 0.0]
  torque_bias_Nm: [0.0, 0.0, 0.0]
  sensor_mount_rpy_deg: [0.0, 0.0, 0.0]
"""


def test_the_note_names_both_masses_and_the_force_they_leave(tmp_path):
    from robstiff_drake.diagrams.scenario_models import read_payload_calibration

    robot = load_robot("irb6400")  # payload 40 kg
    assert robot.payload.mass_kg == 40.0
    for mass in (42.0, 45.0):
        (tmp_path / f"{mass:g}.yaml").write_text(CALIBRATION.format(mass=mass))
    assert payload_mass_note(robot, read_payload_calibration(tmp_path / "42.yaml"), "42.yaml") is None  # 5 %
    line = payload_mass_note(robot, read_payload_calibration(tmp_path / "45.yaml"), "45.yaml")
    assert line is not None and "\n" not in line
    assert "45.yaml" in line and "45.0 kg" in line and "40 kg" in line and "49 N" in line and "--robot" in line


def test_compensate_prints_it_before_any_socket(tmp_path, capsys):
    """The warning comes with the start's checks: here before the refusal of
    --netft and --controller naming one endpoint (exit 2, no socket)."""
    from robstiff_drake.commands.main import main

    assert main(["identify", str(ROOT / "examples" / "campaign.csv"), "--json", str(tmp_path / "model.json"),
                 "--quiet"]) == 0
    payload = tmp_path / "payload.yaml"
    payload.write_text(CALIBRATION.format(mass=30.0))
    capsys.readouterr()
    code = main(["compensate", "--listen-port", "6511", "--controller", "127.0.0.1:6510", "--netft", "127.0.0.1:6510",
                 "--model", str(tmp_path / "model.json"), "--payload", str(payload), "--quiet"])
    err = capsys.readouterr().err
    assert code == 2 and "same address and port" in err
    warnings = [ln for ln in err.splitlines() if ln.startswith("robstiff: warning: compensate: --payload")]
    assert len(warnings) == 1 and "30.0 kg" in warnings[0] and "40 kg" in warnings[0]


def test_real_cell_commands_name_the_robot_for_the_model_and_the_payload():
    """real_cell.md's lines that make compensate's --model and --payload name
    the robot: without --robot both take the irb6400, and a user of another
    arm who copies them gets a payload calibrated with the wrong kinematics."""
    import re

    text = (ROOT / "docs" / "real_cell.md").read_text()
    lines = [ln for ln in text.splitlines() if re.match(r"\s*robstiff (identify|calibrate-payload) ", ln)]
    assert lines
    assert all("--robot " in ln for ln in lines), lines
