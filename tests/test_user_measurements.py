"""The preview knows only what a user measures (diagrams/user_measurements.py):
the modal test's fit recovers modes it did not make, and the preview is
built from measured values, never from the plant's own."""

import copy
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from robstiff_drake.diagrams import milling_cell
from robstiff_drake.diagrams.scenario import load_scenario
from robstiff_drake.diagrams.scenario_models import cutting_setup, plant_damping_ratios
from robstiff_drake.diagrams.user_measurements import user_measured_damping
from robstiff_drake.diagrams.user_model import _exact_servo
from robstiff_drake.model.milling import Workpiece
from robstiff_drake.identification.stiffness.modes import era_modes, impulse_response, merge_close

ROOT = Path(__file__).resolve().parents[1]


def two_modes(f_hz, zeta):
    """A continuous system of uncoupled unit-mass modes (state: x, x'), one input and output per mode."""
    n = len(f_hz)
    A = np.zeros((2 * n, 2 * n))
    for i, (f, z) in enumerate(zip(f_hz, zeta)):
        w = 2 * np.pi * f
        A[i, n + i] = 1.0
        A[n + i, i] = -w * w
        A[n + i, n + i] = -2 * z * w
    B = np.zeros((2 * n, n))
    B[n:, :] = np.eye(n) + 0.3  # each blow excites every mode
    C = np.zeros((n, 2 * n))
    C[:, :n] = np.eye(n) + 0.2
    return A, B, C


def test_the_modal_fit_recovers_modes_it_did_not_make():
    """Modes of a system written here (not the station's) with 1 % noise:
    the ERA fit finds each within 1 % in frequency and 15 % in damping."""
    f, z = [5.0, 9.0, 40.0], [0.03, 0.05, 0.08]
    A, B, C = two_modes(f, z)
    Y = impulse_response(A, B, C, 0.001, 1.0, noise_rel=0.01, seed=3)
    ff, zz = merge_close(*era_modes(Y, 0.001))
    assert len(ff) == 3, (ff, zz)
    np.testing.assert_allclose(ff, f, rtol=0.01)
    np.testing.assert_allclose(zz, z, rtol=0.15)


@pytest.fixture(scope="module")
def captured(robot):
    """The preview factory of the face-and-contour job with an identified
    model, its table and correction replaced by recorders of what they are
    given."""
    sc = load_scenario(ROOT / "diagrams" / "face_and_contour.yaml")
    sc.controller.mode = "preview"
    sc._user_model = SimpleNamespace(coefficient_factors=None, servo=_exact_servo(sc),
                                     joint_stiffness_Nm_per_rad=robot.joint_stiffness_Nm_per_rad * 1.05)
    tool = robot.tool_point(where="test")
    path, t_ref, q_ref = milling_cell.planned_path(sc, robot, tool)
    station = milling_cell.build_station(sc, robot, q_modes_rad=q_ref[0], path=path)
    _, _, workpiece = cutting_setup(sc)
    seen = {}
    mp = pytest.MonkeyPatch()
    mp.setattr(milling_cell, "preview_table", lambda model, **kw: seen.update(model=model, **kw) or "table")
    mp.setattr(milling_cell, "PreviewCorrection", lambda **kw: kw)
    mp.setattr(milling_cell, "_PREVIEWS", {})
    try:
        make = milling_cell.preview_factory(
            sc, robot, path=path, workpiece=workpiece, t_ref=t_ref, q_ref=q_ref, tool_m=station.tool_m,
            filter_ba=([1.0], [1.0]), modal_damping=lambda s: user_measured_damping(s, robot, station, q_ref[0]))
        from robstiff_drake.model.realtime import DeflectionPredictor

        make(DeflectionPredictor(robot.dh, robot.joint_stiffness_Nm_per_rad, station.tool_m), None)
    finally:
        mp.undo()
    return sc, robot, station, workpiece, seen


def test_the_preview_reads_no_plant_only_parameter(captured):
    sc, robot, station, workpiece, seen = captured
    model = seen["model"]
    # the tool point: a TCP calibration's, about 0.5 mm off, not the plant's
    d_tool = np.linalg.norm(np.asarray(seen["tool_m"]) - station.tool_m) * 1e3
    assert 0.05 < d_tool < 3.0, d_tool
    np.testing.assert_array_equal(model._tool, seen["tool_m"])
    assert np.allclose(model.kin._tool, seen["tool_m"])
    # the workpiece's top: a probe's, off by a few hundredths of a mm
    dz = (model.wp.top_m - workpiece.top_m) * 1e3
    assert np.all((np.abs(dz) > 1e-4) & (np.abs(dz) < 0.25)), dz
    # the inertias: the robot file's as a user's file has them (each link off), not the plant's
    plant_masses = np.array([link.mass_kg for link in robot.links])
    user_masses = np.array([m for _, m, *_ in model.inertia._bodies[:6]])
    rel = user_masses / plant_masses[1:7] - 1.0
    assert np.all(np.abs(rel) <= 0.15 + 1e-12) and np.mean(np.abs(rel)) > 0.02, rel
    # the damping: the modal test's drives-closed ratios, not the plant's stated motors-held ones
    ratios = np.asarray(seen["damping_ratios"])
    assert not np.allclose(ratios, plant_damping_ratios(sc))
    f_cl, z_cl = station.joints.closed_loop_modes()
    np.testing.assert_allclose(ratios[0], z_cl[0], rtol=0.1)  # the first mode as the test measures it, drives on


def test_the_bound_reads_the_exact_values(robot, captured):
    """model.source: nominal: the preview is the perfect-model bound (the plant's own values)."""
    sc0, _, station, workpiece, _ = captured
    sc = copy.deepcopy(sc0)
    sc.model.source = "nominal"
    tool = station.tool_m
    path, t_ref, q_ref = milling_cell.planned_path(sc, robot, tool)
    seen = {}
    mp = pytest.MonkeyPatch()
    mp.setattr(milling_cell, "preview_table", lambda model, **kw: seen.update(model=model, **kw) or "table")
    mp.setattr(milling_cell, "PreviewCorrection", lambda **kw: kw)
    mp.setattr(milling_cell, "_PREVIEWS", {})
    try:
        from robstiff_drake.model.realtime import DeflectionPredictor

        milling_cell.preview_factory(sc, robot, path=path, workpiece=workpiece, t_ref=t_ref, q_ref=q_ref, tool_m=tool,
                                     filter_ba=([1.0], [1.0]), modal_damping=lambda s: np.full(6, 0.9))(
            DeflectionPredictor(robot.dh, robot.joint_stiffness_Nm_per_rad, tool), None)
    finally:
        mp.undo()
    np.testing.assert_array_equal(seen["tool_m"], tool)
    np.testing.assert_array_equal(seen["model"].wp.top_m, workpiece.top_m)
    np.testing.assert_allclose(seen["damping_ratios"], plant_damping_ratios(sc))


@pytest.mark.parametrize("name, value", [("chip_exponent", 0.6), ("runout_mm", 0.03), ("flank_wear_mm", 0.1),
                                         ("flank_wear_mm_per_m", 0.01)])
def test_the_model_twin_reads_no_plant_only_cutting_parameter(robot, name, value):
    """The twin the feed planner and the preview's predictions run (the
    compensator's model of the cell) cuts with the compensator's linear,
    revolution-averaged law: the plant's chip exponent, runout and flank
    wear, which no user measures, change nothing of it."""
    from robstiff_drake.diagrams.feed_plan import twin_scenario
    from robstiff_drake.diagrams.scenario_models import plant_cutting_setup

    sc = load_scenario(ROOT / "diagrams" / "face_and_contour.yaml")
    sc.model.source = "nominal"  # (the exact model: the cutting law is the only difference left)
    other = copy.deepcopy(sc)
    setattr(other.cutting, name, value)
    p = np.array([1.65, 0.0, 0.698])
    laws = [plant_cutting_setup(twin_scenario(s, robot, 1.0))[1] for s in (sc, other)]
    a, b = (law.average_wrench(p, (1.0, 0.0), Workpiece.from_boxes([[1.6, 1.72, -0.04, 0.04, 0.7]]), 0.02)
            for law in laws)
    np.testing.assert_array_equal(a, b)
    linear = cutting_setup(sc)[1].average_wrench(p, (1.0, 0.0), Workpiece.from_boxes([[1.6, 1.72, -0.04, 0.04, 0.7]]),
                                                 0.02)
    np.testing.assert_allclose(a, linear, rtol=1e-9, atol=1e-9)
    assert np.linalg.norm(a[:3]) > 100.0  # (in the material)
