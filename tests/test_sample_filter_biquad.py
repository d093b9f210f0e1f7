"""model/filters.SampleFilter.step's unrolled biquad (the default order 2)
gives bit for bit what the general direct-form loop gives (the same
operations in the same order), sample after sample, and after a reset."""

import numpy as np

from robstiff_drake.model.filters import SampleFilter, filter_coefficients


def test_the_biquad_path_equals_the_general_loop_bit_for_bit():
    b, a = filter_coefficients("lowpass", 2.0, 2, 1000.0, 3600.0)
    fast, ref = SampleFilter(b, a), SampleFilter(b, a)
    assert fast._n == 2  # (the path under test)
    rng = np.random.default_rng(7)
    w0 = (rng.normal(size=6) * 100.0).tolist()
    fast.reset(w0)
    ref.reset(w0)
    for k in range(2000):
        u = (rng.normal(size=6) * 300.0).tolist()
        if k == 1000:
            fast.reset(u)
            ref.reset(u)
        assert fast.step(u) == ref._step_general(u)
    assert fast._z == ref._z


def test_a_higher_order_filter_still_takes_the_general_loop():
    b, a = filter_coefficients("lowpass", 10.0, 4, 1000.0, 3600.0)
    f, ref = SampleFilter(b, a), SampleFilter(b, a)
    assert f._n == 4
    rng = np.random.default_rng(8)
    for _ in range(200):
        u = (rng.normal(size=6) * 50.0).tolist()
        assert f.step(u) == ref._step_general(u)
