"""A robot file's rated_payload_kg (the data sheet's wrist payload): a
payload over it is a warning naming the file's line, in the robot's
warnings and in calibrate-payload's.  Before, a newcomer's M-20iD/25 file
(25 kg rated) with the library's 40 kg spindle loaded without a word, and
the key itself was refused as unknown."""

from pathlib import Path
from types import SimpleNamespace

import numpy as np

from robstiff_drake.identification.stiffness.payload import check_payload_fit
from robstiff_drake.model.robot import load_robot

ROOT = Path(__file__).resolve().parents[1]
FANUC = (ROOT / "models" / "r2000ic_165f.yaml").read_text()  # its payload: 40 kg


def _robot(tmp_path, rated_kg):
    assert "\npayload:\n" in FANUC
    path = tmp_path / "my_fanuc.yaml"
    path.write_text(FANUC.replace("\npayload:\n", f"\nrated_payload_kg: {rated_kg}\npayload:\n", 1))
    return load_robot(str(path)), path


def test_a_payload_over_the_rated_one_is_a_warning_at_its_line(tmp_path):
    robot, path = _robot(tmp_path, 25.0)
    assert robot.rated_payload_kg == 25.0
    over = [w for w in robot.warnings if "rated payload" in w]
    assert len(over) == 1, robot.warnings
    line = FANUC.replace("\npayload:\n", "\nrated_payload_kg: 25.0\npayload:\n", 1).splitlines().index(
        "  mass_kg: 40.0") + 1
    assert f"{path}:{line}:" in over[0] and "40 kg" in over[0] and "25 kg" in over[0]


def test_a_payload_within_the_rating_says_nothing(tmp_path):
    robot, _ = _robot(tmp_path, 165.0)
    assert not [w for w in robot.warnings if "rated payload" in w]


def test_calibrate_payload_warns_when_the_calibrated_mass_is_over_the_rating(tmp_path):
    robot, _ = _robot(tmp_path, 38.0)
    fit = SimpleNamespace(mass_kg=39.5, com_m=np.array([0.0, 0.0, 0.18]))
    assert any("over the arm's rated payload (38 kg" in w for w in check_payload_fit(fit, robot, "p.csv"))
    fit.mass_kg = 37.0
    assert not any("rated payload" in w for w in check_payload_fit(fit, robot, "p.csv"))
