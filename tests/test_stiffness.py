"""The conventional (Eq. 1) and CCT (Eqs. 6-7) stiffness models."""

import numpy as np
import pytest
from conftest import random_q

from robstiff_drake.errors import SingularPoseError
from robstiff_drake.model import kinematics as kin
from robstiff_drake.model import stiffness as st
from robstiff_drake.model.realtime import DeflectionPredictor


def test_compliance_is_symmetric_positive_semidefinite(robot, rng):
    for q in random_q(robot, rng, 20):
        C = st.cartesian_compliance(kin.jacobian(robot.dh, q), robot.joint_stiffness_Nm_per_rad)
        np.testing.assert_allclose(C, C.T, atol=1e-20)
        assert np.linalg.eigvalsh(C).min() > -1e-18


def test_stiffness_form_inverts_compliance_form(robot, rng):
    for q in random_q(robot, rng, 10):
        J = kin.jacobian(robot.dh, q, robot.payload.tool_point_m)
        if st.singular_joints(J):
            continue
        K = st.cartesian_stiffness(J, robot.joint_stiffness_Nm_per_rad)
        C = st.cartesian_compliance(J, robot.joint_stiffness_Nm_per_rad)
        np.testing.assert_allclose(K @ C, np.eye(6), atol=1e-8)


def test_deflection_obeys_virtual_work(robot, rng):
    # F^T dx = tau^T dq (the paper's Eq. 5) and dx = J dq (Eq. 4)
    q = random_q(robot, rng)
    F = rng.normal(size=6) * 200
    J = kin.jacobian(robot.dh, q)
    dq, dx = st.deflection_conventional(J, robot.joint_stiffness_Nm_per_rad, F)
    np.testing.assert_allclose(F @ dx, (J.T @ F) @ dq, rtol=1e-12)
    np.testing.assert_allclose(robot.joint_stiffness_Nm_per_rad * dq, J.T @ F, rtol=1e-12)


@pytest.mark.parametrize(
    "q_deg, joints, words",
    [
        ([10, 20, 30, 40, 0, -50], (4, 6), "wrist singularity"),
        ([0, 0, 0, 0, 0, 0], (4, 6), "axes 4 and 6"),
    ],
)
def test_singular_pose_names_the_aligned_joints(robot, q_deg, joints, words):
    J = kin.jacobian(robot.dh, np.deg2rad(q_deg))
    with pytest.raises(SingularPoseError, match=words) as err:
        st.cartesian_stiffness(J, robot.joint_stiffness_Nm_per_rad)
    assert err.value.joints == joints
    # the compliance form still answers, and is finite
    C = st.cartesian_compliance(J, robot.joint_stiffness_Nm_per_rad)
    assert np.all(np.isfinite(C)) and C[0, 0] > 0


def test_elbow_singularity_is_named():
    from robstiff_drake.model.robot import load_robot

    robot = load_robot()
    # stretched arm: theta3 + atan2(d4, a3) = 0, i.e. forearm in line with the lower arm
    q3 = -np.arctan2(robot.dh.d_m[3], robot.dh.a_m[2])
    J = kin.jacobian(robot.dh, np.array([0.0, 0.2, q3, 0.3, 0.5, 0.1]))
    with pytest.raises(SingularPoseError, match="elbow") as err:
        st.cartesian_stiffness(J, robot.joint_stiffness_Nm_per_rad)
    assert {2, 3} <= set(err.value.joints)


def test_cct_is_second_order_accurate_where_conventional_is_first(robot, rng):
    # Against the large-deflection equilibrium of the same springs, the joint
    # deflection error of the conventional model scales with the load squared
    # (relative error ~ |K_g| / K_q ~ load), the CCT model's with the load cubed.
    soft = robot.joint_stiffness_Nm_per_rad / 20.0  # a soft robot, so the effect is clear
    tool = robot.payload.tool_point_m
    q = np.deg2rad([5, 15, 20, 10, 50, -20])
    direction = np.array([0.6, -0.3, -0.74, 0, 0, 0])
    errs = {}
    for scale in (200.0, 400.0):
        F = scale * direction
        dq_exact, _ = st.deflection_exact(robot.dh, q, soft, F, tool)
        dq_conv, _ = st.deflection_conventional(kin.jacobian(robot.dh, q, tool), soft, F)
        dq_cct, _ = st.deflection_cct(robot.dh, q, soft, F, tool)
        errs[scale] = (np.linalg.norm(dq_conv - dq_exact), np.linalg.norm(dq_cct - dq_exact))
    conv_ratio = errs[400.0][0] / errs[200.0][0]
    cct_ratio = errs[400.0][1] / errs[200.0][1]
    assert 3.5 < conv_ratio < 4.5
    assert 7.0 < cct_ratio < 9.0
    assert errs[400.0][1] < 0.05 * errs[400.0][0]


def test_kg_effect_is_small_for_the_irb6400_and_grows_with_load(robot):
    tool = robot.payload.tool_point_m
    q = np.deg2rad([0.0, 13.62, 21.95, 0.0, 54.43, 0.0])
    small = st.kg_effect(robot.dh, q, robot.joint_stiffness_Nm_per_rad, [0, 0, -500.0, 0, 0, 0], tool)
    big = st.kg_effect(robot.dh, q, robot.joint_stiffness_Nm_per_rad, [0, 0, -1471.5, 0, 0, 0], tool)
    assert 1e-5 < small["relative_change"] < 0.005
    assert big["relative_change"] > 2.5 * small["relative_change"]
    np.testing.assert_allclose(big["dp_conventional"] / small["dp_conventional"], 1471.5 / 500.0, rtol=1e-12)


def test_realtime_predictor_matches_reference(robot, rng):
    tool = robot.payload.tool_point_m
    p = DeflectionPredictor(robot.dh, robot.joint_stiffness_Nm_per_rad, tool)
    for q in random_q(robot, rng, 20):
        F = rng.normal(size=6) * np.array([300, 300, 300, 20, 20, 20])
        J = kin.jacobian(robot.dh, q, tool)
        dq_ref, dx_ref = st.deflection_conventional(J, robot.joint_stiffness_Nm_per_rad, F)
        dq, dx = p(q, F)
        np.testing.assert_allclose(p.jacobian(q), J, atol=1e-14)
        np.testing.assert_allclose(dq, dq_ref, rtol=1e-12, atol=1e-18)
        np.testing.assert_allclose(dx, dx_ref, rtol=1e-12, atol=1e-18)
    with pytest.raises(ValueError, match="positive"):
        p.set_joint_stiffness([1, 1, 1, 1, 1, 0])


def test_shoulder_singularity_is_named(robot):
    # wrist centre on axis 1: solve the planar arm for a wrist centre at u = -a1
    from robstiff_drake.model import ik

    pc = np.array([0.0, 0.0, 2.2])  # on axis 1
    R = kin.rpy_to_rotation([0.4, 1.0, 0.3])  # any orientation away from the wrist singularity
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = pc + robot.dh.d_m[5] * R[:, 2]
    q = ik.solve_ik(robot.dh, T)
    J = kin.jacobian(robot.dh, q)
    with pytest.raises(SingularPoseError, match="shoulder") as err:
        st.cartesian_stiffness(J, robot.joint_stiffness_Nm_per_rad)
    assert 1 in err.value.joints
