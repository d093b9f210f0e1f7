"""The library's nominal-stiffness rule (the IRB 6400's stiffnesses scaled
by the rated payload moment on joints 1-3 and the rated payload on the
wrist) applied to a small arm gave it about 54 um/N at the tool (the
largest direction; the library's arms 3.6-5.8) without a word; a robot file that follows the rule beyond the arms it was drawn from
(165-240 kg) now gets a warning naming them (in the robot's warnings: every
command prints them and puts them in its JSON).  The library's four files
follow the rule within its range and load without a warning."""

import json
from pathlib import Path

import numpy as np
import pytest

from robstiff_drake.commands.main import main
from robstiff_drake.model.robot import load_robot
from robstiff_drake.model.robot_checks import largest_compliance_um_per_N, reference_pose
from robstiff_drake.model.stiffness_rule import ANCHOR_NM_PER_RAD, LIBRARY_COMPLIANCE_UM_PER_N, rule_factors

ROOT = Path(__file__).resolve().parents[1]
LIBRARY = ("irb6400", "irb6640", "kr240_r2900", "r2000ic_165f")


def _small_arm(tmp_path, payload_kg=25.0, reach_m=1.8):
    """The FANUC file with the rule's stiffnesses for a small arm (a newcomer's M-20iD/25-like sizes)."""
    text = (ROOT / "models" / "r2000ic_165f.yaml").read_text()
    arm, wrist = payload_kg * reach_m / (200.0 * 2.4), payload_kg / 200.0
    k = ANCHOR_NM_PER_RAD * np.r_[[arm] * 3, [wrist] * 3]
    old = "joint_stiffness_Nm_per_rad: [1.37e6, 1.0e6, 7.3e5, 2.48e5, 2.48e5, 1.65e5]"
    assert text.count(old) == 1
    path = tmp_path / "small.yaml"
    path.write_text(text.replace(old, "joint_stiffness_Nm_per_rad: [" + ", ".join(f"{v:.4g}" for v in k) + "]")
                    .replace("rated_payload_kg: 165.0", f"rated_payload_kg: {payload_kg:g}")
                    .replace("  mass_kg: 40.0", "  mass_kg: 20.0"))
    return path


def test_the_rule_extrapolated_to_a_small_arm_is_warned(tmp_path, capsys):
    robot = load_robot(str(_small_arm(tmp_path)))
    said = [w for w in robot.warnings if "nominal-stiffness rule" in w]
    assert len(said) == 1, robot.warnings
    assert "about 25 kg" in said[0] and "IRB 6640-235/2.55" in said[0] and "KR 240 R2900-2" in said[0]
    assert "R-2000iC/165F" in said[0] and "165-240 kg" in said[0] and "robstiff identify" in said[0]
    # through a command: printed and in its JSON
    assert main(["stiffness", "0", "-60", "100", "0", "45", "0", "--robot", str(tmp_path / "small.yaml"),
                 "--json", str(tmp_path / "s.json")]) == 0
    err = capsys.readouterr().err
    assert "nominal-stiffness rule" in err
    assert any("nominal-stiffness rule" in w for w in json.loads((tmp_path / "s.json").read_text())["warnings"])


@pytest.mark.parametrize("name", LIBRARY)
def test_the_library_follows_the_rule_within_its_range(name):
    robot = load_robot(name)
    assert rule_factors(robot.joint_stiffness_Nm_per_rad) is not None
    assert not robot.warnings


def test_the_stated_library_compliance_range_is_the_library_s():
    c = [largest_compliance_um_per_N(r, reference_pose(r)[0]) for r in map(load_robot, LIBRARY)]
    lo, hi = LIBRARY_COMPLIANCE_UM_PER_N
    assert abs(min(c) - lo) < 0.1 and abs(max(c) - hi) < 0.1, c


@pytest.mark.parametrize("name", ["irb6400", "r2000ic_165f"])
def test_the_compliance_is_the_arms_deflection_under_a_force(name):
    """largest_compliance_um_per_N against the arm itself, from its forward kinematics alone: each joint's torque
    under a 1 N force by virtual work (finite differences of the tool point's position), the joints turned by
    torque / stiffness, the tool point's move (before: the Jacobian's columns taken for its rows, 11.5 um/N for
    the IRB 6400 where the arm moves 5.1 um at most under 1 N)."""
    from robstiff_drake.model import kinematics as kin

    robot = load_robot(name)
    q = reference_pose(robot)[0]
    tool = robot.payload.tool_point_m if robot.payload.tool_point_m is not None else np.zeros(3)

    def p(qq):
        return kin.tool_position(robot.dh, qq, tool)

    h = 1e-7
    dp_dq = np.column_stack([(p(q + h * e) - p(q - h * e)) / (2 * h) for e in np.eye(6)])  # (3, 6)
    C = np.zeros((3, 3))
    for i, f in enumerate(np.eye(3)):  # 1 N along x, y, z
        tau = dp_dq.T @ f  # virtual work: N*m per joint
        C[:, i] = (p(q + tau / robot.joint_stiffness_Nm_per_rad) - p(q)) * 1e6  # um
    C = 0.5 * (C + C.T)
    assert largest_compliance_um_per_N(robot, q) == pytest.approx(np.linalg.eigvalsh(C)[-1], rel=1e-3)


def test_stiffnesses_not_of_the_rule_are_not_its_business(tmp_path):
    """An identified (not proportional) set of a small arm's stiffnesses: no rule warning."""
    path = _small_arm(tmp_path)
    text = path.read_text()
    start = text.index("joint_stiffness_Nm_per_rad: [")
    end = text.index("]", start)
    path.write_text(text[:start] + "joint_stiffness_Nm_per_rad: [2.1e5, 1.6e5, 9.0e4, 2.2e4, 1.9e4, 1.2e4"
                    + text[end:])
    robot = load_robot(str(path))
    assert rule_factors(robot.joint_stiffness_Nm_per_rad) is None
    assert not [w for w in robot.warnings if "nominal-stiffness rule" in w]
