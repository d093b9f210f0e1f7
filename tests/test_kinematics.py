"""Forward kinematics, Jacobian, its derivative and IK, against an
independent DH implementation and finite differences."""

import numpy as np
import pytest
from conftest import random_q
from independent_dh import fk_mm, jacobian_fd

from robstiff_drake.model import ik
from robstiff_drake.model import kinematics as kin


def test_home_pose_matches_table1_geometry(robot):
    # At q = 0 the lower arm is vertical and the forearm horizontal: the flange
    # is at x = a1 + d4 + d6, z = d1 + a2 + a3, pointing along +x.
    T = kin.frames(robot.dh, np.zeros(6))[6]
    np.testing.assert_allclose(T[:3, 3], [1.688, 0.0, 2.075], atol=1e-12)
    np.testing.assert_allclose(T[:3, 2], [1.0, 0.0, 0.0], atol=1e-12)


def test_fk_matches_independent_dh(robot, rng):
    tool_mm = np.array([30.0, -20.0, 350.0])
    for q in random_q(robot, rng, 50):
        p_ref, R_ref = fk_mm(np.rad2deg(q), tool_mm)
        T = kin.tool_pose(robot.dh, q, tool_mm / 1000.0)
        np.testing.assert_allclose(T[:3, 3] * 1000.0, p_ref, atol=1e-9)
        np.testing.assert_allclose(T[:3, :3], R_ref, atol=1e-12)


def test_fk_is_batched(robot, rng):
    qs = random_q(robot, rng, 7)
    batch = kin.tool_position(robot.dh, qs, robot.payload.tool_point_m)
    one_by_one = np.array([kin.tool_position(robot.dh, q, robot.payload.tool_point_m) for q in qs])
    np.testing.assert_allclose(batch, one_by_one, atol=1e-15)


def test_jacobian_matches_finite_differences(robot, rng):
    tool_mm = (0.0, 40.0, 350.0)
    for q in random_q(robot, rng, 10):
        J = kin.jacobian(robot.dh, q, np.array(tool_mm) / 1000.0)
        J_fd = np.array(jacobian_fd(np.rad2deg(q), tool_mm))
        np.testing.assert_allclose(J, J_fd, atol=1e-7)


def test_geometric_stiffness_matches_finite_differences(robot, rng):
    tool = robot.payload.tool_point_m
    h = 1e-6
    for q in random_q(robot, rng, 10):
        F = rng.normal(size=6) * np.array([300, 300, 300, 30, 30, 30])
        K_g = kin.geometric_stiffness(robot.dh, q, F, tool)
        fd = np.zeros((6, 6))
        for j in range(6):
            e = np.zeros(6)
            e[j] = h
            fd[:, j] = (kin.jacobian(robot.dh, q + e, tool).T @ F - kin.jacobian(robot.dh, q - e, tool).T @ F) / (2 * h)
        np.testing.assert_allclose(K_g, fd, atol=1e-6 * np.abs(fd).max())


def test_rpy_round_trip(rng):
    for _ in range(20):
        rpy = rng.uniform(-np.pi, np.pi, 3) * np.array([1, 0.5, 1])
        R = kin.rpy_to_rotation(rpy)
        np.testing.assert_allclose(kin.rpy_to_rotation(kin.rotation_to_rpy(R)), R, atol=1e-12)
    R = kin.rpy_to_rotation([0.3, np.pi / 2, -0.2])  # gimbal lock
    np.testing.assert_allclose(kin.rpy_to_rotation(kin.rotation_to_rpy(R)), R, atol=1e-12)


def test_ik_round_trip_over_the_workspace(robot):
    tool = robot.payload.tool_point_m
    points, qs = ik.workspace_poses(robot, 4, tool)
    assert len(qs) == 64  # the whole machining box is reachable
    for p, q in zip(points, qs):
        T = kin.tool_pose(robot.dh, q, tool)
        np.testing.assert_allclose(T, ik.tool_down_pose(p), atol=1e-10)
        assert np.all(q >= robot.q_lower_rad) and np.all(q <= robot.q_upper_rad)


def test_ik_recovers_front_elbow_up_configurations(robot, rng):
    tool = np.array([0.0, 0.0, 0.3])
    for _ in range(30):
        q = rng.uniform([-1.5, -0.6, -0.3, -2.0, 0.2, -2.0], [1.5, 0.8, 1.2, 2.0, 1.8, 2.0])
        q_ik = ik.solve_ik(robot.dh, kin.tool_pose(robot.dh, q, tool), tool, q_ref_rad=q)
        np.testing.assert_allclose(q_ik, q, atol=1e-9)


def test_ik_refuses_unreachable_and_out_of_limit_poses(robot):
    with pytest.raises(ik.IKError, match="out of reach"):
        ik.solve_ik(robot.dh, ik.tool_down_pose([4.0, 0.0, 0.5]))
    with pytest.raises(ik.IKError, match=r"q2 = -118\.\d+ deg, outside its joint limit \[-70, 70\]"):
        # close to the base: the lower arm would have to lean far back
        ik.solve_ik(robot.dh, ik.tool_down_pose([0.4, 0.0, 0.7]), robot.payload.tool_point_m,
                    q_lower_rad=robot.q_lower_rad, q_upper_rad=robot.q_upper_rad)
