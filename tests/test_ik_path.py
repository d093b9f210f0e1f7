"""model/ik_path (IK along a whole path, vectorised) against model/ik.solve_for
called sample by sample, each warm-started from the previous answer (the
solver it replaces along paths), and diagrams/reference_cache's disk cache."""

import numpy as np
import pytest

from robstiff_drake.diagrams import reference_cache
from robstiff_drake.diagrams.milling_cell import scenario_path
from robstiff_drake.diagrams.scenario import load_scenario, scenario_robot
from robstiff_drake.model import ik, ik_path
from robstiff_drake.model import kinematics as kin
from robstiff_drake.model.path import PathError, PlannedPath
from robstiff_drake.model.robot import load_robot
from robstiff_drake.paths import DIAGRAMS_DIR


def one_by_one(robot, poses, tool, q_start=None):
    out, ref = [], q_start
    for T in poses:
        ref = ik.solve_for(robot, T, tool, q_ref_rad=ref)
        out.append(ref)
    return np.array(out)


@pytest.fixture(scope="module")
def job():
    sc = load_scenario(DIAGRAMS_DIR / "face_and_contour.yaml")
    robot = scenario_robot(sc, None)
    return scenario_path(sc), robot, robot.payload.tool_point_m


def test_the_path_ik_is_the_sample_by_sample_solver_to_round_off(job):
    path, robot, tool = job
    ts = np.arange(0.0, path.duration_s, 0.02)  # every fifth reference sample: the same warm-started chain
    poses = np.array([ik.tool_down_pose(path.position(t), path.yaw) for t in ts])
    fast = ik_path.solve_path(robot, poses, tool)
    ref = one_by_one(robot, poses, tool)
    assert fast.shape == ref.shape == (len(ts), 6)
    assert np.max(np.abs(fast - ref)) < 1e-12
    T = kin.tool_pose(robot.dh, fast, tool)
    assert np.max(np.abs(T[:, :3, 3] - poses[:, :3, 3])) < 1e-9  # m
    assert np.max(np.abs(T[:, :3, :3] - poses[:, :3, :3])) < 1e-9


@pytest.mark.parametrize("robot_name", ["irb6400", "kr240_r2900", "irb6640", "r2000ic_165f"])
def test_each_arm_and_a_start_reference(robot_name):
    """Other arms' chains (bases, offsets, joint maps), from a reference far
    from the path: the first sample's branch is chosen by that reference."""
    robot = load_robot(robot_name)
    tool = robot.tool_point(where="the test")
    p0 = np.asarray(robot.workspace.reference_tool_point_m, dtype=float)
    s = np.linspace(0.0, 1.0, 60)[:, None]
    pts = p0 + s * np.array([0.15, -0.2, 0.1])
    poses = np.array([ik.tool_down_pose(p, 0.3) for p in pts])
    for q_start in (None, np.array([0.1, 0.2, -0.1, 3.0, 0.5, -2.0])):
        fast = ik_path.solve_path(robot, poses, tool, q_start)
        assert np.max(np.abs(fast - one_by_one(robot, poses, tool, q_start))) < 1e-12


def test_a_wrist_singularity_and_limits_take_the_solvers_own_answer():
    """A pose with axes 4 and 6 aligned (the closed form keeps axis 4 at its
    reference) and a path whose nearer wrist branch leaves axis 6's range
    (the other branch is taken): the sample-by-sample answers."""
    robot = load_robot(None)
    tool = np.zeros(3)
    q = np.array([[0.1, 0.3, -0.2, 0.4, 0.0, 0.2], [0.1, 0.3, -0.2, 0.4, 0.3, 0.2],
                  [0.12, 0.31, -0.2, 0.4, 0.0, 0.25]])
    poses = kin.tool_pose(robot.dh, q, tool)
    assert np.max(np.abs(ik_path.solve_path(robot, poses, tool) - one_by_one(robot, poses, tool))) < 1e-12
    hi = robot.q_upper_rad[5]
    q6 = np.linspace(hi - 0.3, hi - 0.01, 20)
    qs = np.column_stack([np.full(20, 0.1), np.full(20, 0.3), np.full(20, -0.2), np.full(20, 0.4),
                          np.full(20, 0.5), q6])
    poses = kin.tool_pose(robot.dh, qs, tool)
    start = qs[0].copy()
    start[5] += 0.4  # the reference beyond the range: the nearer answer is outside it at the first samples
    fast = ik_path.solve_path(robot, poses, tool, start)
    assert np.max(np.abs(fast - one_by_one(robot, poses, tool, start))) < 1e-12


def test_paths_leaving_the_ranges_or_singular_fail_where_the_path_does():
    robot = load_robot(None)
    tool = robot.tool_point(where="the test")
    reach = PlannedPath([[1.6, 0.0, 0.7], [2.6, 0.0, 0.7]], feed_m_per_s=0.5)
    with pytest.raises(PathError) as fast:
        ik_path.joint_references(reach, robot, tool, 0.004)
    with pytest.raises(PathError) as slow:
        reach.joint_references(robot, tool, 0.004)
    assert str(fast.value) == str(slow.value) and "outside its joint limit" in str(fast.value)
    wrist = PlannedPath([[0.413, -0.03, 0.0], [0.413, 0.03, 0.0]], feed_m_per_s=0.05)
    with pytest.raises(PathError) as fast:
        ik_path.joint_references(wrist, robot, tool, 0.004)
    with pytest.raises(PathError) as slow:
        wrist.joint_references(robot, tool, 0.004)
    assert str(fast.value) == str(slow.value) and "singularity" in str(fast.value)


def test_the_references_are_kept_on_disk_by_content(job, tmp_path, monkeypatch):
    path, robot, tool = job
    monkeypatch.setenv("ROBSTIFF_CACHE_DIR", str(tmp_path))
    ts, qs = reference_cache.joint_references(path, robot, tool, 0.004)
    t_old, q_old = path.joint_references(robot, tool, 0.004)
    assert np.array_equal(ts, t_old) and np.max(np.abs(qs - q_old)) < 1e-12
    assert len(list(tmp_path.glob("joint-references-*.npz"))) == 1

    def no_ik(*a, **k):
        raise AssertionError("the IK ran again")

    monkeypatch.setattr(ik_path, "joint_references", no_ik)
    t2, q2 = reference_cache.joint_references(path, robot, tool, 0.004)
    assert np.array_equal(t2, ts) and np.array_equal(q2, qs)
    # another tool offset or reference period is another file (the IK runs)
    with pytest.raises(AssertionError, match="ran again"):
        reference_cache.joint_references(path, robot, tool + [0.0, 0.0, 0.001], 0.004)
    with pytest.raises(AssertionError, match="ran again"):
        reference_cache.joint_references(path, robot, tool, 0.008)
    # a damaged file is computed again, not read
    f = next(tmp_path.glob("joint-references-*.npz"))
    f.write_bytes(b"not an npz")
    with pytest.raises(AssertionError, match="ran again"):
        reference_cache.joint_references(path, robot, tool, 0.004)


def test_the_key_follows_the_robot_files_content(tmp_path):
    from robstiff_drake.paths import MODELS_DIR

    src = MODELS_DIR / "kr240_r2900.yaml"
    copy = tmp_path / "arm.yaml"
    copy.write_text(src.read_text())
    robot = load_robot(str(copy))
    tool = robot.tool_point(where="the test")
    path = PlannedPath([robot.workspace.reference_tool_point_m,
                        np.asarray(robot.workspace.reference_tool_point_m) + [0.05, 0.0, 0.0]], feed_m_per_s=0.05)
    k1 = reference_cache.key(path, robot, tool, 0.004)
    copy.write_text(src.read_text() + "\n# edited\n")
    assert reference_cache.key(path, load_robot(str(copy)), tool, 0.004) != k1


def test_a_controllers_own_kinematics_gives_the_sample_by_sample_references(job):
    """diagrams/milling_cell.references_with_kinematic_error (a controller
    whose joint zeros are off, the part touched off at the first point)
    against the loop it replaced: solve_for sample by sample."""
    import dataclasses

    from robstiff_drake.diagrams.milling_cell import references_with_kinematic_error

    path, robot, tool = job
    d = np.deg2rad([0.02, -0.015, 0.01, 0.03, -0.02, 0.025])
    ctrl = dataclasses.replace(robot, dh=dataclasses.replace(robot.dh, home_rad=robot.dh.home_rad + d))
    t = np.arange(0.0, path.duration_s, 0.05)
    fast = references_with_kinematic_error(path, t, robot, ctrl, tool)
    q_prev, shift, slow = None, np.zeros(3), []
    for k, tk in enumerate(t):
        q = ik.solve_for(ctrl, ik.tool_down_pose(path.position(tk) - shift, path.yaw), tool, q_ref_rad=q_prev)
        if k == 0:
            q0 = q
            shift = kin.tool_pose(robot.dh, q, tool)[:3, 3] - path.position(tk)
            q = ik.solve_for(ctrl, ik.tool_down_pose(path.position(tk) - shift, path.yaw), tool, q_ref_rad=q0)
        slow.append(q)
        q_prev = q
    assert np.max(np.abs(fast - np.array(slow))) < 1e-12
    assert np.max(np.abs(fast - ik_path.solve_path(robot, [ik.tool_down_pose(path.position(tk), path.yaw)
                                                           for tk in t], tool))) > 1e-5  # the error is there
