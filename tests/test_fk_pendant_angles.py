"""`robstiff fk` prints the rotation's angles as a FANUC pendant's W, P, R
(a newcomer checking an M-20iD/25 file against the TCP display had only a
rotation matrix to compare with X, Y, Z, W, P, R); other makers get roll,
pitch, yaw, the JSON's rpy_deg."""

import numpy as np

from robstiff_drake.commands.main import main
from robstiff_drake.model import kinematics as kin
from robstiff_drake.model.robot import load_robot


def _angles_line(capsys, args):
    assert main(["fk", *args]) == 0
    return [ln for ln in capsys.readouterr().out.splitlines() if ln.startswith("angles")]


def test_a_fanuc_gets_its_pendants_w_p_r(capsys):
    line = _angles_line(capsys, ["10", "30", "-20", "40", "-60", "70", "--robot", "r2000ic_165f"])
    assert len(line) == 1 and line[0].startswith("angles (FANUC's W, P, R; deg): W ")
    robot = load_robot("r2000ic_165f")
    T = kin.tool_pose(robot.dh, robot.joint_rad([10, 30, -20, 40, -60, 70]), np.zeros(3))
    w, p, r = (float(line[0].split(f" {k} ")[1].split()[0]) for k in "WPR")
    # W, P, R: fixed x-y-z angles, R = Rz(R) Ry(P) Rx(W)
    Rz = lambda a: np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])  # noqa: E731
    Ry = lambda a: np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])  # noqa: E731
    Rx = lambda a: np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])  # noqa: E731
    assert np.allclose(Rz(np.radians(r)) @ Ry(np.radians(p)) @ Rx(np.radians(w)), T[:3, :3], atol=1e-4)


def test_the_faceplate_points_down_with_w_180_at_j5_minus_90(capsys):
    line = _angles_line(capsys, ["0", "30", "0", "0", "-90", "0", "--robot", "r2000ic_165f"])
    assert line == ["angles (FANUC's W, P, R; deg): W -180.000  P +0.000  R +0.000"]


def test_other_makers_get_roll_pitch_yaw(capsys):
    line = _angles_line(capsys, ["0", "-90", "90", "0", "45", "0", "--robot", "kr240_r2900"])
    assert line == ["angles (roll, pitch, yaw: R = Rz(yaw) Ry(pitch) Rx(roll); deg): -180.000  +45.000  -180.000"]
