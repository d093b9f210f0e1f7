"""studies/deck_pass_trace.py's reading of a pass (issue 29): the moment
that set each point's depth (the face mill keeps the deepest cut) and the
stretches of the stripe.  Geometry only: no simulation."""

import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "studies"))

import deck_pass_trace as trace  # noqa: E402
from robstiff_drake.model.surface import envelope_heights  # noqa: E402


def test_the_deepest_sample_is_the_one_that_cut_each_point():
    """A level pass along x with one sample 0.2 mm low: every point its
    75 mm cutter covered is cut by that sample, at its depth; the heights
    are the envelope's; a point no cutter reached has none."""
    n = 401
    p = np.column_stack([np.linspace(1.40, 1.80, n), np.zeros(n), np.full(n, 0.700)])
    p[200, 2] -= 0.2e-3  # the tool at x = 1.600 m dips 0.2 mm
    up = np.tile([0.0, 0.0, 1.0], (n, 1))
    x = np.array([1.57, 1.60, 1.63, 1.70, 2.00])
    h, arg = trace.deepest_samples(x, 0.0025, p, up)
    assert list(arg[:3]) == [200, 200, 200]
    assert h[:3] == pytest.approx(0.700 - 0.2e-3)
    assert arg[3] != 200 and h[3] == pytest.approx(0.700)
    assert arg[4] == -1 and np.isinf(h[4])
    assert h[:4] == pytest.approx(envelope_heights(x[:4], 0.0025, p, up, 0.0375, np.inf))


def test_the_stripe_splits_at_the_chambers():
    x = np.r_[np.linspace(1.395, 1.418, 47), np.linspace(1.503, 1.511, 17)]  # 0.5 mm apart
    parts = trace.stretches(x)
    assert len(parts) == 2
    assert x[parts[0][1] - 1] == pytest.approx(1.418) and x[parts[1][0]] == pytest.approx(1.503)
