"""What the compiled kernels' tests share: a kernel compiled or its
plain-Python original (``py_func``), and their agreement to round-off."""

import numpy as np
import pytest

from robstiff_drake.model import jit


def kernel(compiled, k):
    """``k`` compiled, or its plain-Python original; skips the compiled case without numba."""
    if compiled and not jit.available():
        pytest.skip("numba is not installed: the callers run the plain-Python references (tested here too)")
    return k if compiled else k.py_func


def assert_round_off(got, want, rel=1e-13):
    """``got`` equals ``want`` within ``rel`` of its largest magnitude (at least 1), NaN where it is NaN."""
    got, want = np.asarray(got, dtype=float), np.asarray(want, dtype=float)
    np.testing.assert_allclose(got, want, rtol=0.0, atol=rel * max(1.0, float(np.nanmax(np.abs(want)))))
    np.testing.assert_array_equal(np.isnan(got), np.isnan(want))
