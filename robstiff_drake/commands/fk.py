"""``robstiff fk Q1..Q6``: forward kinematics of the robot at six controller
angles (deg): the flange's (or the --tool point's) position (mm) and
rotation in the robot's base frame."""

import numpy as np

from robstiff_drake.commands.options import parse_tool
from robstiff_drake.commands.stiffness import parse_q_deg
from robstiff_drake.io import Warnings, check_outputs, emit_json
from robstiff_drake.model import kinematics as kin
from robstiff_drake.model.robot import load_robot
from robstiff_drake.progress import wrote


def fk_report(robot, q_deg, tool_m):
    """position_mm, rotation (3x3, columns: the tool frame's axes in the base
    frame) and the angles, for checked controller angles ``q_deg``."""
    q = robot.joint_rad(q_deg)
    T = kin.tool_pose(robot.dh, q, tool_m)
    return {
        "robot": robot.name,
        "q_deg": [float(v) for v in q_deg],
        "q_model_deg": np.rad2deg(q),
        "tool_mm": np.asarray(tool_m) * 1e3,
        "position_mm": T[:3, 3] * 1e3,
        "rotation": T[:3, :3],
        "rpy_deg": np.rad2deg(kin.rotation_to_rpy(T[:3, :3])),
    }


def angles_line(robot, rpy_deg):
    """The rotation's fixed-axis x-y-z angles (deg), R = Rz(yaw) Ry(pitch)
    Rx(roll) (``rpy_deg``, URDF's), as one line; for a FANUC, named as its
    pendant's W, P, R (the same convention: W = roll, P = pitch, R = yaw),
    which it shows for this frame when frame 6 is its faceplate frame
    (the library's file: ROS-Industrial's tool0) and the tool frame is
    UTOOL 0.  (KUKA's A, B, C are the same angles of its $FLANGE frame, x
    out of the flange, not tool0's: not named here.)"""
    roll, pitch, yaw = (round(float(v), 3) + 0.0 for v in rpy_deg)
    if str(robot.manufacturer).upper() == "FANUC":
        return f"angles (FANUC's W, P, R; deg): W {roll:+.3f}  P {pitch:+.3f}  R {yaw:+.3f}"
    return f"angles (roll, pitch, yaw: R = Rz(yaw) Ry(pitch) Rx(roll); deg): {roll:+.3f}  {pitch:+.3f}  {yaw:+.3f}"


def run(*, q, tool=None, json_out=None, robot_yaml=None):
    check_outputs(files={"--json": json_out})
    robot = load_robot(robot_yaml)
    q_deg = parse_q_deg(q, what="fk")
    robot.check_q_deg(q_deg, where="fk")
    tool_m = np.zeros(3) if tool is None else parse_tool(tool)
    rep = fk_report(robot, q_deg, tool_m)
    rep["warnings"] = list(Warnings())  # (an input's: a --tool in metres)
    if json_out is not None:
        emit_json(rep, json_out)
    if json_out != "-":
        p, R = rep["position_mm"], rep["rotation"]
        what = "flange" if not np.any(tool_m) else f"tool point ({', '.join(f'{v:g}' for v in tool_m * 1e3)}) mm"
        print(f"{robot.name}: q = [" + ", ".join(f"{v:.3f}" for v in q_deg) + "] deg (controller convention)")
        print(f"{what} in the base frame: x {p[0]:10.3f}  y {p[1]:10.3f}  z {p[2]:10.3f}  mm")
        print("rotation (columns: the frame's x, y, z axes):")
        for row in R:
            print("  " + "  ".join(f"{v:+.6f}" for v in row))
        print(angles_line(robot, rep["rpy_deg"]))
    wrote(json_out, to_stderr=json_out == "-")
    return 0
