"""The tool point travels with the data: synth and plan-poses write a
`# tool_mm:` line, identify and diagnose read it, a --tool that disagrees
with it is an error naming both, and without either the robot file's tool
point is used (with a warning)."""

import json

import numpy as np
import pytest

from robstiff_drake.commands.main import main
from robstiff_drake.identification.stiffness.campaign import read_tool_header
from robstiff_drake.model.robot import load_robot


def cli(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def test_synth_writes_the_tool_point_and_identify_reads_it(capsys, tmp_path):
    """A campaign written with its tool point (synth --tool 0,0,350), identified without --tool."""
    robot = load_robot()
    data = tmp_path / "c.csv"
    assert cli(capsys, "synth", "stiffness", data, "--n", 120, "--seed", 5, "--tool", "0,0,350")[0] == 0
    assert "# tool_mm: 0, 0, 350\n" in data.read_text()
    np.testing.assert_allclose(read_tool_header(data), [0, 0, 350])
    code, out, err = cli(capsys, "identify", data, "--json", "-")
    assert code == 0 and "warning" not in err
    res = json.loads(out)
    assert res["tool_mm"] == [0.0, 0.0, 350.0] and res["warnings"] == []
    k = np.array(res["joint_stiffness_Nm_per_rad"])
    np.testing.assert_allclose(k[:5], robot.joint_stiffness_Nm_per_rad[:5], rtol=0.05)


def test_synth_default_tool_is_the_robot_files(capsys, tmp_path):
    data = tmp_path / "c.csv"
    assert cli(capsys, "synth", "stiffness", data, "--n", 24, "--robot", "kr240_r2900")[0] == 0
    np.testing.assert_allclose(read_tool_header(data), load_robot("kr240_r2900").payload.tool_point_m * 1e3)


@pytest.mark.parametrize("command", ["identify", "diagnose"])
def test_a_disagreeing_tool_is_an_error_naming_both(capsys, tmp_path, command):
    data = tmp_path / "c.csv"
    cli(capsys, "synth", "stiffness", data, "--n", 24, "--tool", "0,0,350")
    out = tmp_path / "out.json"
    code, _, err = cli(capsys, command, data, "--tool", "0,0,300", "--json", out)
    assert code == 2 and len(err.strip().splitlines()) == 1
    assert "--tool 0, 0, 300 mm disagrees with the tool point (0, 0, 350) mm" in err and str(data) in err
    assert not out.exists()
    # an equal --tool is fine
    assert cli(capsys, "identify", data, "--tool", "0,0,350.0", "--json", out)[0] == 0


def test_a_file_without_the_line_uses_the_robot_files_tool_point_and_says_so(capsys, tmp_path):
    data = tmp_path / "c.csv"
    cli(capsys, "synth", "stiffness", data, "--n", 48, "--seed", 2)
    data.write_text("".join(ln for ln in data.read_text().splitlines(keepends=True) if not ln.startswith("# tool_mm")))
    code, out, err = cli(capsys, "identify", data, "--json", tmp_path / "r.json")
    assert code == 0
    assert "robstiff: warning:" in err and "no '# tool_mm:' line" in err and "(0, 0, 350) mm" in err
    res = json.loads((tmp_path / "r.json").read_text())
    assert res["tool_mm"] == [0.0, 0.0, 350.0] and len(res["warnings"]) == 1


@pytest.mark.parametrize("line, message", [("# tool_mm: 0, 350", "expects three numbers"),
                                           ("# tool_mm: 0, x, 350", "expects three numbers")])
def test_a_malformed_line_names_file_and_line(capsys, tmp_path, line, message):
    data = tmp_path / "c.csv"
    cli(capsys, "synth", "stiffness", data, "--n", 24)
    lines = data.read_text().splitlines(keepends=True)
    i = next(k for k, ln in enumerate(lines) if ln.startswith("# tool_mm"))
    lines[i] = line + "\n"
    data.write_text("".join(lines))
    code, _, err = cli(capsys, "identify", data)
    assert code == 2 and f"{data}:{i + 1}: '# tool_mm:' {message}" in err


def test_a_second_line_is_an_error(tmp_path):
    from robstiff_drake.errors import InputError

    path = tmp_path / "c.csv"
    path.write_text("# tool_mm: 0, 0, 350\n# tool_mm: 0, 0, 300\nq1\n")
    with pytest.raises(InputError, match=r"c.csv:2: a second '# tool_mm:' line \(the first is line 1\)"):
        read_tool_header(path)


def test_plan_poses_writes_the_tool_point_in_the_controller_convention(capsys, tmp_path):
    plan = tmp_path / "plan.csv"
    assert cli(capsys, "plan-poses", 12, "--candidates", 20, "--robot", "r2000ic_165f", "--out", plan)[0] == 0
    np.testing.assert_allclose(read_tool_header(plan), [0, 0, 350])
    robot = load_robot("r2000ic_165f")
    rows = [ln.split(",") for ln in plan.read_text().splitlines() if ln and not ln.startswith("#")][1:]
    q = np.array([[float(v) for v in r[2:8]] for r in rows])
    lo, hi = np.rad2deg(robot.q_lower_rad), np.rad2deg(robot.q_upper_rad)
    assert np.all(q >= lo - 1e-6) and np.all(q <= hi + 1e-6)
    # the plan's angles are FANUC's: their tool points are in the machining box
    from robstiff_drake.model import kinematics as kin

    p = kin.tool_position(robot.dh, robot.joint_rad(q), robot.payload.tool_point_m)
    ws = robot.workspace
    assert np.all((p[:, 0] > ws.x_m[0] - 1e-6) & (p[:, 0] < ws.x_m[1] + 1e-6))
