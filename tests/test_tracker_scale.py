"""A large tracker campaign's work and memory, counted (not timed: the
machine is shared; the speed figures are benchmarks/bench_tracker_large.py's):
the diagnosis evaluates the arm a number of times that does not grow with
the rows and is not repeated per candidate effect, and the big arrays are
not held twice (the kinematics' frames, the search's columns, the residual
map's design over a held-out fold)."""

import sys
import tracemalloc
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial import cKDTree

from robstiff_drake.identification.tracker import residual_map as rmap
from robstiff_drake.identification.tracker import diagnosis as td
from robstiff_drake.identification.tracker import fit as tracker_fit
from robstiff_drake.identification.tracker.campaign import read_tracker_campaign
from robstiff_drake.model import kinematics as kin
from robstiff_drake.model.robot import load_robot

sys.path.insert(0, str(Path(__file__).resolve().parent))
import tracker_world as tw  # noqa: E402


def _peak(fn):
    tracemalloc.start()
    try:
        out = fn()
        return tracemalloc.get_traced_memory()[1], out
    finally:
        tracemalloc.stop()


def test_the_diagnosis_evaluates_the_arm_a_fixed_number_of_times(tmp_path, monkeypatch):
    """Problem.evaluate (the arm's kinematics and sag over the rows) runs
    as often at 1,200 rows as at 300, and at most 85 times (before: 98, the
    declared fit evaluated again for every candidate effect's columns)."""
    robot = load_robot("irb6400")
    counts = {}
    evaluate = tracker_fit.Problem.evaluate

    def counted(self, *a, **k):
        counts["n"] += 1
        return evaluate(self, *a, **k)

    monkeypatch.setattr(tracker_fit.Problem, "evaluate", counted)
    seen = []
    for n in (300, 1200):
        path = tmp_path / f"c{n}.csv"
        path.write_text(tw.make_tracker_campaign(robot, 7, n=n, noise_mm=0.03).csv_text)
        counts["n"] = 0
        td.diagnose_tracker(robot, read_tracker_campaign(path, robot), noise_mm=0.03, residual_map=False)
        seen.append(counts["n"])
    print("evaluations at 300 and 1,200 rows:", seen)
    assert abs(seen[0] - seen[1]) <= 8 and max(seen) <= 85, seen


def test_frames_hold_no_stack_of_link_transforms():
    """kinematics.frames over 50,000 poses: the peak of its allocations is
    about its result (before: the (N, 6, 4, 4) link transforms and
    contiguous copies of them besides, 2.3 x)."""
    q = np.random.default_rng(0).uniform(-2, 2, (50000, 6))
    dh = load_robot("irb6400").dh
    peak, T = _peak(lambda: kin.frames(dh, q))
    assert peak < 1.6 * T.nbytes, peak / T.nbytes


def test_the_search_columns_are_scaled_in_place():
    X = np.random.default_rng(1).normal(size=(30000, 40))
    tests = [np.arange(k, 30000, 5) for k in range(5)]
    groups = np.arange(30000) // 3
    nbytes = X.nbytes
    peak, cv = _peak(lambda: tracker_fit.LinearCV(X, X[:, 0] * 2.0, tests, groups, copy=False))
    assert cv.Xs is X and peak < 1.5 * nbytes, peak / nbytes  # (a copy: 2 x and more)


def test_the_residual_map_predicts_a_large_fold_in_blocks():
    """A fold of 20,000 rows: the map's prediction holds a block of the
    design at a time (before: the whole design, 3 x 20,000 x 576 floats,
    276 MB), and gives the whole design's numbers."""
    rng = np.random.default_rng(2)
    n, H = 20000, max(rmap.HARMONICS)
    J, Jv = rng.uniform(-2, 2, (n, 6)), rng.normal(size=(n, 3, 6)) * 1e-3
    m = rmap.ResidualMap(H, 1e-5)
    m.coef = rng.normal(size=6 * 16 * H) * 1e-3
    m.tree, m.d0 = cKDTree(J), 1.0  # every pose predicted is a training pose: inside the domain, weight 1
    peak, got = _peak(lambda: m.predict(J, Jv))
    assert peak < 40e6, peak / 1e6
    whole = (rmap.design(J[:500], Jv[:500], H) @ m.coef).reshape(-1, 3)
    assert np.allclose(got[:500], whole, rtol=1e-12, atol=1e-18)


@pytest.mark.parametrize("n", [7, 2048, 2049])
def test_blocks_at_their_edges(n):
    rng = np.random.default_rng(n)
    J, Jv = rng.uniform(-2, 2, (n, 6)), rng.normal(size=(n, 3, 6))
    m = rmap.ResidualMap(2, 1e-5)
    m.coef = rng.normal(size=6 * 16 * 2)
    m.tree, m.d0 = cKDTree(J), 1.0
    assert np.allclose(m.predict(J, Jv, block=1000), (rmap.design(J, Jv, 2) @ m.coef).reshape(-1, 3))
