"""The arm the cutting-force tests drive: the library robot's tool-point
kinematics at one pose, and link angles that move its tool point by a
given displacement (tests/test_plant_cutting.py, test_regenerative_chip.py)."""

import numpy as np

from robstiff_drake.model.realtime import DeflectionPredictor


def arm_at_pose(robot):
    """(kinematics, tool point m, link angles rad) of the library robot at one pose."""
    tool = robot.payload.tool_point_m
    kin = DeflectionPredictor(robot.dh, robot.joint_stiffness_Nm_per_rad, tool)
    q0 = np.deg2rad([5.0, 15.0, 20.0, 10.0, 50.0, -20.0])
    return kin, tool, q0


def moved(kin, q0, dx):
    """Link angles that put the tool point dx (m, base frame) from q0's, by Newton steps."""
    _, p0 = kin.flange_rotation_and_tool_point(q0)
    q = q0.copy()
    for _ in range(5):
        _, p = kin.flange_rotation_and_tool_point(q)
        J = kin.jacobian(q)
        q = q + np.linalg.lstsq(J[:3], p0 + dx - p, rcond=None)[0]
    return q
