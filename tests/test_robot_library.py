"""The robot library: every robot's kinematics against Drake's plant (from
the URDF generated out of its robot file) and against implementations
that share no code with the package (the published URDF descriptions, the
paper's Table 1, Craig's modified DH), in each robot's controller
convention; inverse kinematics over each machining workspace."""

import numpy as np
import pytest
from independent_chains import FANUC_MDH, fanuc_theta_deg, fk_modified_dh, fk_urdf, jacobian_fd
from independent_dh import fk_mm as fk_table1

from robstiff_drake.model import ik
from robstiff_drake.model import kinematics as kin
from robstiff_drake.model.robot import load_robot
from robstiff_drake.paths import library_robots
from robstiff_drake.plant import make_robot_plant, tool_position_and_jacobian

LIBRARY = ["irb6400", "irb6640", "kr240_r2900", "r2000ic_165f"]
TOOLS_MM = [(0.0, 0.0, 0.0), (0.0, 0.0, 350.0), (40.0, -25.0, 310.0)]


def independent_fk(name):
    """The independent forward kinematics of a library robot: (q_ctrl_deg, tool_mm) -> (p_mm, R)."""
    if name == "irb6400":
        return fk_table1
    return lambda q, tool=(0.0, 0.0, 0.0): fk_urdf(name, q, tool)


def controller_samples(robot, rng, n):
    """Random controller angles (deg) inside the working ranges."""
    return np.rad2deg(rng.uniform(robot.q_lower_rad, robot.q_upper_rad, size=(n, 6)))


def test_the_library_is_complete_and_covers_every_convention():
    assert library_robots() == LIBRARY
    robots = {n: load_robot(n) for n in LIBRARY}
    assert {r.convention for r in robots.values()} == {"standard_dh", "modified_dh"}
    assert robots["irb6400"].joint_map.is_identity and robots["irb6640"].joint_map.is_identity
    kuka, fanuc = robots["kr240_r2900"].joint_map, robots["r2000ic_165f"].joint_map
    assert np.any(kuka.sign < 0) and np.any(kuka.offset_rad) and not kuka.coupling
    assert fanuc.coupling == ((2, 1, -1.0),)
    for r in robots.values():
        assert r.citation not in ("", "-") and r.manufacturer in ("ABB", "KUKA", "FANUC")
        assert 900 < r.total_mass_kg < 2100


@pytest.mark.parametrize("name", LIBRARY)
def test_fk_and_jacobian_match_drake(name, rng):
    robot = load_robot(name)
    plant, _ = make_robot_plant(robot)
    ctx = plant.CreateDefaultContext()
    flange = plant.GetFrameByName("flange")
    for q_deg in controller_samples(robot, rng, 40):
        q = robot.joint_rad(q_deg)
        for tool_mm in TOOLS_MM:
            tool = np.array(tool_mm) / 1e3
            p, J = tool_position_and_jacobian(plant, ctx, q, tool)
            np.testing.assert_allclose(kin.tool_position(robot.dh, q, tool), p, rtol=0, atol=1e-9)
            np.testing.assert_allclose(kin.jacobian(robot.dh, q, tool), J, rtol=0, atol=1e-9)
        X = plant.CalcRelativeTransform(ctx, plant.world_frame(), flange)
        np.testing.assert_allclose(kin.frames(robot.dh, q)[6, :3, :3], X.rotation().matrix(), rtol=0, atol=1e-12)


@pytest.mark.parametrize("name", LIBRARY)
def test_fk_matches_the_independent_implementation_in_controller_angles(name, rng):
    robot = load_robot(name)
    fk = independent_fk(name)
    for q_deg in controller_samples(robot, rng, 40):
        for tool_mm in TOOLS_MM:
            p_ref, R_ref = fk(list(q_deg), tool_mm)
            T = kin.tool_pose(robot.dh, robot.joint_rad(q_deg), np.array(tool_mm) / 1e3)
            np.testing.assert_allclose(T[:3, 3] * 1e3, p_ref, rtol=0, atol=1e-6)  # 1e-9 m
            np.testing.assert_allclose(T[:3, :3], R_ref, rtol=0, atol=1e-12)


def test_fanuc_against_an_independent_modified_dh_with_the_j2_j3_interaction(rng):
    robot = load_robot("r2000ic_165f")
    for q_deg in controller_samples(robot, rng, 40):
        p_ref, R_ref = fk_modified_dh(FANUC_MDH, fanuc_theta_deg(list(q_deg)), (0.0, 0.0, 350.0))
        T = kin.tool_pose(robot.dh, robot.joint_rad(q_deg), np.array([0.0, 0.0, 0.35]))
        np.testing.assert_allclose(T[:3, 3] * 1e3, p_ref, rtol=0, atol=1e-6)
        np.testing.assert_allclose(T[:3, :3], R_ref, rtol=0, atol=1e-12)
    # the interaction itself: turning J2 with J3 held keeps the forearm's
    # direction from the horizontal (J3 is measured from it)
    q = np.array([0.0, 0.0, 10.0, 0.0, 0.0, 0.0])
    axis4 = lambda qd: kin.frames(robot.dh, robot.joint_rad(qd))[3, :3, 2]  # noqa: E731
    np.testing.assert_allclose(axis4(q + [0, 30, 0, 0, 0, 0]), axis4(q), atol=1e-12)
    assert np.degrees(np.arcsin(abs(axis4(q)[2]))) == pytest.approx(10.0)


@pytest.mark.parametrize("name", LIBRARY)
def test_jacobian_in_controller_angles_matches_finite_differences(name, rng):
    """J (model joints) times G (d model / d controller) is the Jacobian of the
    independent FK with respect to the controller's angles."""
    robot = load_robot(name)
    fk = independent_fk(name)
    G = robot.joint_map.G
    tool_mm = (30.0, -20.0, 350.0)
    for q_deg in controller_samples(robot, rng, 8):
        J = kin.jacobian(robot.dh, robot.joint_rad(q_deg), np.array(tool_mm) / 1e3) @ G
        np.testing.assert_allclose(J, np.array(jacobian_fd(fk, list(q_deg), tool_mm)), atol=1e-7)


@pytest.mark.parametrize("name", LIBRARY)
def test_controller_map_round_trip_and_limits(name, rng):
    robot = load_robot(name)
    qc = rng.uniform(robot.q_lower_rad, robot.q_upper_rad, size=(20, 6))
    np.testing.assert_allclose(robot.joint_map.to_controller(robot.joint_map.to_model(qc)), qc, atol=1e-12)
    lo, hi = robot.model_limits_rad
    qm = robot.joint_map.to_model(qc)
    assert np.all(qm >= lo - 1e-12) and np.all(qm <= hi + 1e-12)
    for q in qm:
        assert robot.within_limits(q)
    bad = np.rad2deg(qc[0])
    bad[1] = np.rad2deg(robot.q_upper_rad[1]) + 1.0
    j, value, _, hi_deg = robot.limit_violation(robot.joint_rad(bad))
    assert j == 1 and value == pytest.approx(bad[1]) and hi_deg == pytest.approx(np.rad2deg(robot.q_upper_rad[1]))


@pytest.mark.parametrize("name", LIBRARY)
def test_ik_over_the_machining_workspace(name):
    robot = load_robot(name)
    tool = robot.payload.tool_point_m
    points, qs = ik.workspace_poses(robot, 4, tool)
    assert len(qs) == 64  # the whole box is reachable, within the working ranges
    for p, q in zip(points, qs):
        np.testing.assert_allclose(kin.tool_pose(robot.dh, q, tool), ik.tool_down_pose(p), atol=1e-10)
        assert robot.within_limits(q)


@pytest.mark.parametrize("name", LIBRARY)
def test_ik_recovers_random_configurations(name, rng):
    """From poses of random configurations of the machining branch (the
    arm's front, elbow up): IK gives the configuration back."""
    robot = load_robot(name)
    tool = np.array([0.0, 0.0, 0.3])
    found = 0
    for q_deg in controller_samples(robot, rng, 200):
        q = robot.joint_rad(q_deg)
        T = kin.tool_pose(robot.dh, q, tool)
        q_ik = ik.solve_ik(robot.dh, T, tool, q_ref_rad=q)
        np.testing.assert_allclose(kin.tool_pose(robot.dh, q_ik, tool), T, atol=1e-10)  # always the pose
        if np.allclose(q_ik, q, atol=1e-8):
            found += 1
    assert found >= 20  # the machining branch's share of random configurations


def _non_spherical(tmp_path, a4_mm=60.0):
    text = open(load_robot("irb6400").source).read().replace(
        "a_mm:      [188.0, 950.0, 225.0,    0.0,  0.0,   0.0]", f"a_mm:      [188.0, 950.0, 225.0, {a4_mm},  0.0,   0.0]")
    path = tmp_path / "offset_wrist.yaml"
    path.write_text(text)
    return load_robot(path)


def test_numerical_ik_for_a_wrist_that_is_not_spherical(tmp_path, rng):
    robot = _non_spherical(tmp_path)
    assert "not spherical" in ik.closed_form_reason(robot.dh)
    tool = robot.payload.tool_point_m
    for _ in range(10):
        q = rng.uniform([-1.0, -0.4, -0.2, -1.5, 0.4, -1.5], [1.0, 0.6, 1.0, 1.5, 1.5, 1.5])
        T = kin.tool_pose(robot.dh, q, tool)
        q_ik = ik.solve_ik(robot.dh, T, tool, q_ref_rad=q + 0.05)
        np.testing.assert_allclose(kin.tool_pose(robot.dh, q_ik, tool), T, atol=1e-9)
    with pytest.raises(ik.IKError, match="numerical IK found no solution.*not spherical"):
        ik.solve_ik(robot.dh, ik.tool_down_pose([4.5, 0.0, 0.5]), tool)
    # a path over the machining box works with the numerical solver too
    points, qs = ik.workspace_poses(robot, 2, tool)
    assert len(qs) == 8
