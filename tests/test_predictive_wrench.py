"""Predictive compensation's model wrench (systems/predictive_wrench.py):
the linear model's revolution average compiled
(model/cutting_kernels.linear_average_wrench, through lead_arcs) against
MillingForceModel.average_wrench, its plain-Python reference, over tool
points across one box's edges and corners and two overlapping boxes of
different tops, feeds in every direction and depths on and off the
material, to round-off; and the wrenches PredictiveWrench keeps (three a
tick, one of them the tick before's) against the reference computed
afresh.  The kernels' Python originals are checked with or without numba;
the compiled ones where numba is installed."""

import math

import numpy as np
import pytest

from robstiff_drake.model import cutting_kernels as ck
from robstiff_drake.model.milling import Cutter, CuttingCoefficients, MillingForceModel, Workpiece
from robstiff_drake.model.path import PlannedPath
from robstiff_drake.model.realtime import DeflectionPredictor
from robstiff_drake.systems.predictive_wrench import PredictiveWrench
from kernel_checks import assert_round_off, kernel

MODEL = MillingForceModel(Cutter(0.075, 6, 3600.0), CuttingCoefficients(631, 99, 273, 13, 10, 2.8), 0.02)
# one wide box and a taller one overlapping it (m): edges, corners, a step in depth
WORKPIECE = Workpiece.from_boxes([[0.0, 0.3, -0.1, 0.05, 0.003], [0.1, 0.2, -0.02, 0.02, 0.005]])


def points(n=600, seed=3):
    """(tool point m, feed direction) pairs: in, across and off the boxes."""
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        p = np.array([rng.uniform(-0.05, 0.35), rng.uniform(-0.15, 0.1), rng.choice([-0.001, 0.0, 0.004, 0.006])])
        a = rng.uniform(-math.pi, math.pi)
        out.append((p, (math.cos(a), math.sin(a))))
    # exactly on an edge, feeding along the axes
    out += [(np.array([0.0375, 0.0, 0.0]), (1.0, 0.0)), (np.array([0.1, 0.05, 0.0]), (0.0, -1.0)),
            (np.array([0.3, 0.05 + 0.0375, 0.0]), (-1.0, 0.0))]
    return out


@pytest.mark.parametrize("compiled", [False, True])
def test_linear_average_wrench_is_the_models(compiled):
    f = kernel(compiled, ck.linear_average_wrench)
    boxes = np.array(WORKPIECE.boxes, dtype=float).reshape(-1, 5)
    basis = np.array(MODEL._basis, dtype=float)
    engaged = 0
    for p, u in points():
        want = MODEL.average_wrench(p, u, WORKPIECE)
        got = f(float(p[0]), float(p[1]), float(p[2]), u[0], u[1], boxes, MODEL.cutter.radius_m, basis)
        assert_round_off(got, want)
        engaged += bool(np.any(want != 0.0))
    assert engaged > 100  # (the cases cut, not only air)


@pytest.mark.parametrize("compiled", [False, True])
def test_lead_arcs_are_the_models_intervals(compiled):
    f = kernel(compiled, ck.lead_arcs)
    boxes = np.array(WORKPIECE.boxes, dtype=float).reshape(-1, 5)
    for p, u in points(200, seed=5):
        arcs, n = f(float(p[0]), float(p[1]), float(p[2]), u[0], u[1], boxes, MODEL.cutter.radius_m)
        want = MODEL.lead_intervals(p, u, WORKPIECE)
        assert n == len(want)
        if n:
            assert_round_off(arcs[:n], want)


def test_kept_model_wrenches_are_computed_afresh(robot):
    """PredictiveWrench's model wrench at the times of a run (each asked for
    as its ticks ask: the replica's sample, the output's, the lead's), from
    its kept ones, equals the reference computed for each time afresh."""
    kin = DeflectionPredictor(robot.dh, robot.joint_stiffness_Nm_per_rad, robot.payload.tool_point_m)
    path = PlannedPath([[0.02, 0.0, 0.0], [0.25, 0.0, 0.0], [0.25, 0.04, 0.0]], 0.02, ramp_s=0.2)
    sys_ = PredictiveWrench(force_model=MODEL, workpiece=WORKPIECE, path=path, kinematics=kin,
                            tool_m=(0.0, 0.0, 0.2), lead_s=0.015, filter_ba=([0.2], [1.0, -0.8]), rate_hz=250.0,
                            period_s=0.004)
    h = 0.004
    asked = []
    for k in range(3000):
        t = k * h
        asked += [t - h - 2 * h, t - 2 * h, t + 0.015]  # (_advance's, then _calc's)
    got = [sys_.model_wrench_base(t).copy() for t in asked]
    for t, w in zip(asked[::7], got[::7]):
        assert_round_off(w, sys_.model_wrench_reference(t))
    assert sum(bool(np.any(w != 0.0)) for w in got) > 1000  # (along the cut, not only before it)
