"""The milling force's compiled update (model/force_step_kernels.py)
against the plain-Python arithmetic it replaces: the tool's progress along
a path of lines (MillingForceSource.motion with PlannedPath.project) and
the whole revolution-averaged update on the plant's law with its runout
and wear (MillingForceSource._step: pose, motion, smoothed feed, worn edge,
averaged wrench, travel), through a corner, a tool that goes back and the
history's first updates, to round-off.  The kernels' Python originals are
checked with or without numba; the compiled ones where numba is
installed.  A path with arcs keeps the references."""

import numpy as np
import pytest
from pydrake.multibody.tree import BodyIndex

from robstiff_drake.model import force_step_kernels as fk
from robstiff_drake.model import jit
from robstiff_drake.model.milling import Cutter, CuttingCoefficients, MillingForceModel, Workpiece
from robstiff_drake.model.path import PlannedPath
from robstiff_drake.model.plant_cutting import PlantCuttingLaw, PlantCuttingPhysics
from robstiff_drake.model.realtime import DeflectionPredictor
from robstiff_drake.systems.milling_force import MillingForceSource
from kernel_checks import assert_round_off, kernel

LINEAR = MillingForceModel(Cutter(0.075, 6, 3600.0), CuttingCoefficients(631, 99, 273, 13, 10, 2.8), 0.02)
T = 0.004


@pytest.fixture(scope="module")
def cell(robot):
    """(source on a three-line path with a corner, kinematics, link angles at its corner)."""
    tool = robot.payload.tool_point_m
    kin = DeflectionPredictor(robot.dh, robot.joint_stiffness_Nm_per_rad, tool)
    q0 = np.deg2rad([5.0, 15.0, 20.0, 10.0, 50.0, -20.0])
    _, p0 = kin.flange_rotation_and_tool_point(q0)
    path = PlannedPath([p0 - [0.1, 0, 0], p0, p0 + [0.0, 0.06, 0], p0 + [0.0, 0.06, -0.02]], 0.02, ramp_s=0.5)
    wp = Workpiece.from_boxes([[p0[0] - 0.05, p0[0] + 0.02, p0[1] - 0.03, p0[1] + 0.05, p0[2] + 0.003]])
    law = PlantCuttingLaw(LINEAR, PlantCuttingPhysics())  # (runout and wear on)
    src = MillingForceSource(force_model=law, workpiece=wp, path=path, kinematics=kin, tool_point_m=tool,
                             period_s=T, spindle_body_index=BodyIndex(7))
    return src, kin, q0


def states(src, q0):
    """(t, q, process, hist) along a run through the corner: the tool
    wobbling about the path, going back now and then, the history filling
    from its first update; each from the reference's step before it."""
    rng = np.random.default_rng(7)
    process = np.array([1.0, 0.0, 0.015, 0.2])
    hist = np.full(3 * src._n_hist, np.nan)
    with jit.disabled():
        for k in range(60):
            t = 5.0 + T * k
            q = q0 + np.r_[rng.normal(0.0, 2e-3, 3), rng.normal(0.0, 1e-3, 3)]
            yield t, q, process, hist
            _, _, _, process, hist = src._step(t, q, process, hist)


@pytest.mark.parametrize("compiled", [True, False], ids=["compiled", "python original"])
def test_the_motion_on_lines_is_the_reference(cell, compiled):
    line_motion = kernel(compiled, fk.line_motion)
    src, kin, q0 = cell
    checked = 0
    for t, q, _process, hist in states(src, q0):
        if np.isnan(hist[-3]):
            continue  # (the first update searches the whole path: the reference's)
        p = kin.flange_rotation_and_tool_point(q)[1]
        with jit.disabled():
            u, feed, h = src.motion(t, p, hist)
        out = np.empty(hist.shape[0])
        got = line_motion(t, float(p[0]), float(p[1]), float(p[2]), hist, src._window, *src._lines, out)
        assert_round_off(got, [u[0], u[1], feed])
        assert_round_off(out, h)
        checked += 1
    assert checked > 50


@pytest.mark.parametrize("compiled", [True, False], ids=["compiled", "python original"])
def test_the_averaged_update_is_the_reference(cell, compiled):
    step = kernel(compiled, fk.averaged_force_step)
    src, _kin, q0 = cell
    cut = 0
    for t, q, process, hist in states(src, q0):
        with jit.disabled():
            w, pose, _, proc, h = src._step(t, q, process, hist)
        if np.isnan(hist[-3]):
            continue
        out = np.empty(22 + hist.shape[0])
        step(q, t, hist, process, *src._fused, out)
        assert_round_off(out[:6], w)
        assert_round_off(out[6:10], proc)
        assert_round_off(out[10:22], pose)
        assert_round_off(out[22:], h)
        cut += np.linalg.norm(w[:3]) > 10.0
    assert cut > 20  # (in the material, the travel growing)
    if compiled:  # the source's own step takes the compiled update
        t, q, process, hist = list(states(src, q0))[-1]
        with jit.disabled():
            want = src._step(t, q, process, hist)
        got = src._step(t, q, process, hist)
        for a, b in zip(got, want):
            if b is not None:
                assert_round_off(a, b)


def test_a_path_with_arcs_keeps_the_references(cell):
    src, kin, q0 = cell
    _, p0 = kin.flange_rotation_and_tool_point(q0)
    path = PlannedPath([p0 - [0.1, 0, 0], p0, p0 + [0.0, 0.06, 0]], 0.02, zone_m=0.005)  # (a blended corner)
    assert fk.line_constants(path) is None
    arcs = MillingForceSource(force_model=src._model, workpiece=src._workpiece, path=path, kinematics=kin,
                              tool_point_m=src._tool,
                              period_s=T, spindle_body_index=BodyIndex(7))
    assert arcs._fused is None and arcs._lines is None
    assert fk.line_constants(src._path) is not None and src._fused is not None


def test_the_fused_kernels_disk_cache_goes_stale_with_the_kernels_it_calls(cell):
    """numba keys a kernel's disk cache on its own file; the averaged update
    calls the pose and force kernels of two other files, so its cache's
    stamp carries theirs too (model/jit.py): editing them compiles it again."""
    if not jit.available():
        pytest.skip("numba is not installed: nothing is compiled or cached")
    from robstiff_drake.model import cutting_kernels, tick_kernels
    impl = fk.averaged_force_step._impl or fk.averaged_force_step._compile()
    cache_file = getattr(getattr(impl, "_cache", None), "_cache_file", None)
    if cache_file is None:
        pytest.skip("this numba keeps its cache otherwise: the stamp is its own")
    files = {entry[0] for entry in cache_file._source_stamp[1:]}
    assert {tick_kernels.__file__, cutting_kernels.__file__} <= files
