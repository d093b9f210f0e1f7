"""The summary's cutting force at mid-pass is a force where the cutter cuts:
a job whose log's middle falls between passes (the face-and-contour job at
its corner) reports the middle of its cutting, never a rounded zero."""

import numpy as np

from robstiff_drake.commands.simulate import format_table, mid_pass_wrench


def test_between_passes_at_its_middle_the_middle_of_the_cutting_is_reported():
    cw = np.zeros((11, 6))
    cw[1:4, :3] = [-100.0, 200.0, 50.0]  # the first pass
    cw[6:10, :3] = [80.0, -8.0, 15.0]  # the second: the log's middle (5) is between them
    cw[5, :3] = [0.2, -0.3, 0.0]
    np.testing.assert_array_equal(mid_pass_wrench(cw), cw[6])  # (the 4th of the 7 cutting samples)
    single = np.tile([-165.0, 112.0, 39.0, 0, 0, 0], (9, 1))
    np.testing.assert_array_equal(mid_pass_wrench(single), single[4])  # a single pass: its middle, as before


def test_a_rounded_zero_has_no_sign():
    summ = {"name": "x", "surface_error_mm": {}, "cutting_wrench_at_mid_pass": {"force_N": [0.2, -0.3, -0.0]},
            "spindle_power_W": 1000.0, "spindle_rating_W": 3730.0, "natural_frequencies_hz": [5.0],
            "drives_closed_modes": [], "runs": []}
    text = format_table(summ)
    assert "(0, 0, 0)" in text and "-0" not in text.split("cutting force")[1].split(";")[0]
