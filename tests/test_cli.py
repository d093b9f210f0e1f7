"""The `robstiff` command line: outputs and error paths."""

import json
import subprocess
import sys

import numpy as np
import pytest
from independent_dh import fk_mm, jacobian_fd

from robstiff_drake.commands.main import main


def run_cli(capsys, *argv):
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def test_stiffness_json_matches_independent_dh(capsys, robot):
    q_deg = [12.5, 20.0, 15.0, -30.0, 60.0, 45.0]
    tool = (10.0, -5.0, 350.0)
    code, out, err = run_cli(capsys, "stiffness", *map(str, q_deg), "--tool", ",".join(map(str, tool)), "--json", "-")
    assert code == 0, err
    rep = json.loads(out)  # nothing but the JSON on stdout
    p_ref, _ = fk_mm(q_deg, tool)
    np.testing.assert_allclose(rep["position_mm"], p_ref, atol=1e-9)
    J_fd = np.array(jacobian_fd(q_deg, tool))
    np.testing.assert_allclose(rep["jacobian"], J_fd, atol=1e-7)
    assert rep["q_deg"] == q_deg
    assert rep["joint_stiffness_Nm_per_rad"] == robot.joint_stiffness_Nm_per_rad.tolist()
    # compliance from the independent Jacobian: C = Jv diag(1/k) Jv^T, in mm/N
    Jv = J_fd[:3]
    C_ref = Jv @ np.diag(1.0 / robot.joint_stiffness_Nm_per_rad) @ Jv.T * 1e3
    np.testing.assert_allclose(rep["compliance_mm_per_N"], C_ref, rtol=1e-6)
    assert np.array(rep["jacobian"]).shape == (6, 6)
    np.testing.assert_allclose(np.array(rep["stiffness_N_per_um"]) @ np.array(rep["compliance_mm_per_N"]) * 1e3,
                               np.eye(3), atol=1e-9)


def test_stiffness_table_and_json_file(capsys, tmp_path):
    out_json = tmp_path / "s.json"
    code, out, _ = run_cli(capsys, "stiffness", "0", "13.62", "21.95", "0", "54.43", "0",
                           "--tool", "0,0,350", "--json", str(out_json))
    assert code == 0
    assert "translational compliance C (um/N)" in out
    assert "principal directions" in out
    rep = json.loads(out_json.read_text())
    # the reference machining pose: tool point at (1600, 0, 700) mm
    np.testing.assert_allclose(rep["position_mm"], [1600.0, 0.0, 700.0], atol=0.2)
    assert [p.name for p in tmp_path.iterdir()] == ["s.json"]  # no temporary file left


def test_negative_angles_are_accepted(capsys):
    code, out, err = run_cli(capsys, "stiffness", "-30", "-10", "5", "-90", "45", "-120")
    assert code == 0, err


@pytest.mark.parametrize(
    "argv, message",
    [
        (["stiffness", "0", "0", "0", "0", "0"], "expected 6 joint angles Q1..Q6 in degrees, got 5"),
        (["stiffness", "0", "0", "0", "0", "0", "0", "0"], "expected 6 joint angles Q1..Q6 in degrees, got 7"),
        (["stiffness", "0", "abc", "0", "0", "0", "0"], "q2 = 'abc' is not a number"),
        (["stiffness", "0", "0", "nan", "0", "0", "0"], "q3 = nan is not a finite number"),
        (["stiffness", "0", "95", "0", "0", "45", "0"], "q2 = 95 deg is outside the joint limit [-70, 70] deg"),
        (["stiffness", "0", "0", "-40", "0", "45", "0"], "q3 = -40 deg is outside the joint limit [-28, 105] deg"),
        (["stiffness", "0", "0", "0", "0", "45", "0", "--tool", "1,2"], "--tool: expected 3 comma-separated numbers"),
        (["stiffness", "0", "0", "0", "0", "45", "0", "--tool", "1,x,2"], "--tool: component 2 'x' is not a number"),
        (["stiffness", "0", "0", "0", "0", "0", "0", "--kx"], "joints 4, 6"),
        (["stiffness-map", "--out", "x.svg"], "must name a .png file"),
        (["kg-study", "--grid", "0"], "argument --grid: 0 is outside the allowed range [1, 20]"),
        (["nonsense"], "invalid choice"),
        (["stiffness", "--robot", "/nonexistent.yaml", "0", "0", "0", "0", "45", "0"], "/nonexistent.yaml: no such robot file"),
    ],
)
def test_bad_input_is_one_line_exit_2(capsys, argv, message):
    code, out, err = run_cli(capsys, *argv)
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert message in lines[0]
    assert lines[0].startswith("robstiff")


def test_singular_pose_kx_error_still_prints_compliance(capsys):
    code, out, err = run_cli(capsys, "stiffness", "0", "0", "0", "0", "0", "0", "--kx")
    assert code == 2
    assert "wrist singularity: axes 4 and 6 are aligned" in err
    assert "translational compliance C (um/N)" in out  # the compliance form still answers


def test_console_script_has_no_traceback_and_exit_2():
    proc = subprocess.run([sys.executable, "-m", "robstiff_drake", "stiffness", "1", "2", "3"],
                          capture_output=True, text=True)
    assert proc.returncode == 2
    assert "Traceback" not in proc.stderr
    assert proc.stderr.strip() == "robstiff: error: stiffness: expected 6 joint angles Q1..Q6 in degrees, got 3"
    assert proc.stdout == ""


def test_stiffness_json_at_regular_pose_includes_kx(capsys, robot):
    code, out, _ = run_cli(capsys, "stiffness", "0", "13.62", "21.95", "0", "54.43", "0", "--kx", "--json", "-")
    assert code == 0
    rep = json.loads(out)
    Kx = np.array(rep["cartesian_stiffness_6x6"])
    J = np.array(rep["jacobian"])
    np.testing.assert_allclose(J.T @ Kx @ J, np.diag(robot.joint_stiffness_Nm_per_rad), rtol=1e-8, atol=1e-3)


def test_stiffness_map_writes_png(capsys, tmp_path):
    out = tmp_path / "map.png"
    code, text, err = run_cli(capsys, "stiffness-map", "--out", str(out), "--resolution", "7")
    assert code == 0, err
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "softest direction" in text


def test_kg_study_json(capsys):
    code, out, _ = run_cli(capsys, "kg-study", "--grid", "2", "--json", "-")
    assert code == 0
    res = json.loads(out)
    assert res["n_poses"] == 8
    force, payload = res["cases"]
    assert force["n_cases"] == 8 * 14 and payload["n_cases"] == 8
    # the paper's claim: K_g changes the deflection by well under 1 %
    assert 0 < force["max_relative_change"] < 0.01
    assert payload["max_relative_change"] > force["max_relative_change"]
    for case in (force, payload):  # each percentage and its micrometres describe one case
        assert case["change_at_max_relative_um"] == pytest.approx(
            case["max_relative_change"] * case["deflection_at_max_mm"] * 1e3, rel=1e-9)
        assert case["max_abs_change_um"] == pytest.approx(
            case["relative_change_at_max_abs"] * case["deflection_at_max_abs_mm"] * 1e3, rel=1e-9)
        assert case["max_abs_change_um"] >= case["change_at_max_relative_um"]


# `robstiff demo --out DIR`'s outputs and the paper's findings in demo.json: tests/test_wheel_install.py's _check_demo,
# on the demo docs/results.md and docs/cli.md show (run once per session from the wheel, their `share` block; this
# file ran the same demo again for them)
