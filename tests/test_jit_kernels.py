"""The compiled per-tick arithmetic (model/jit.py, model/cutting_kernels.py)
against the numpy references it replaces: the plant's cutting law's
revolution average and its tooth-resolved wrench, to round-off.  The
kernels' Python originals are checked with or without numba; the compiled
ones where numba is installed (the test says why it skips otherwise)."""

import os
import subprocess
import sys

import numpy as np
import pytest

from robstiff_drake.model import cutting_kernels as ck
from robstiff_drake.model import jit
from robstiff_drake.model.milling import Cutter, CuttingCoefficients, MillingForceModel, Workpiece
from robstiff_drake.model.plant_cutting import _GAUSS_W, _GAUSS_X, PlantCuttingLaw, PlantCuttingPhysics
from kernel_checks import assert_round_off

CUTTER = Cutter(0.075, 6, 3600.0)
LINEAR = MillingForceModel(CUTTER, CuttingCoefficients(631, 99, 273, 13, 10, 2.8), 0.02)
ONE_BOX = Workpiece.from_boxes([[-0.05, 0.1, -0.02, 0.03, 0.003]])
TWO_BOXES = Workpiece.from_boxes([[-0.05, 0.1, -0.02, 0.03, 0.003], [0.02, 0.05, -0.05, 0.0, 0.005]])
LAWS = {"rich": PlantCuttingLaw(LINEAR),
        "linear": PlantCuttingLaw(LINEAR, PlantCuttingPhysics.linear()),
        "runout only": PlantCuttingLaw(LINEAR, PlantCuttingPhysics(chip_exponent=1.0, runout_m=20e-6,
                                                                   runout_angle_rad=0.7, edge_ramp_chip_m=0.0))}


def cases(seed, n=60):
    """(tool point m, feed direction, feed m/s, cut length m) over and
    around the boxes, the cutter in and out of the material."""
    rng = np.random.default_rng(seed)
    for _ in range(n):
        a = rng.uniform(0.0, 2 * np.pi)
        yield (np.array([rng.uniform(-0.1, 0.15), rng.uniform(-0.1, 0.08), rng.uniform(-0.002, 0.006)]),
               (np.cos(a), np.sin(a)), rng.uniform(0.0, 0.06), rng.uniform(0.0, 200.0))


def kernel_average(law, p, u, wp, feed, travel, fn):
    h_scale, e, ramp, Kc = law._constants()
    return fn(float(p[0]), float(p[1]), float(p[2]), float(u[0]), float(u[1]),
              np.array(wp.boxes, dtype=float).reshape(-1, 5), float(law.linear.chip_per_tooth_m(feed)), h_scale, e,
              ramp, Kc, law.edge_coefficients(travel), float(CUTTER.radius_m), law._k, law._dR, _GAUSS_X, _GAUSS_W)


def kernel_teeth(law, t, p, u, wp, phase, feed, travel, fn):
    h_scale, e, ramp, Kc = law._constants()
    n = CUTTER.n_teeth
    return fn(np.asarray(t, dtype=float), float(p[0]), float(p[1]), float(p[2]), float(u[0]), float(u[1]), phase,
              CUTTER.spindle_rad_per_s, 2 * np.pi * np.arange(n) / n, float(law.linear.chip_per_tooth_m(feed)),
              h_scale, e, ramp, Kc, law.edge_coefficients(travel), float(CUTTER.radius_m), law._k, law._dR,
              np.array(wp.boxes, dtype=float).reshape(-1, 5))


@pytest.mark.parametrize("name", sorted(LAWS))
@pytest.mark.parametrize("wp", [ONE_BOX, TWO_BOXES], ids=["one box", "two boxes"])
def test_the_kernels_python_originals_are_the_numpy_references(name, wp):
    law = LAWS[name]
    engaged = 0
    for i, (p, u, feed, travel) in enumerate(cases(1)):
        want = law.average_wrench_reference(p, u, wp, feed, travel)
        engaged += bool(np.any(want != 0.0))
        assert_round_off(kernel_average(law, p, u, wp, feed, travel, ck.average_wrench_at.py_func), want, rel=1e-12)
        t = np.linspace(0.0, 0.004, 7) + 0.001 * i
        assert_round_off(kernel_teeth(law, t, p, u, wp, 0.3, feed, travel, ck.tooth_wrenches_at.py_func),
                         law.tooth_wrenches_reference(t, p, u, wp, 0.3, feed, travel), rel=1e-12)
    assert engaged > 10  # (the cases cut, not only air)


def test_with_the_compiler_off_the_law_runs_its_numpy_reference():
    law = LAWS["rich"]
    p, u = np.array([0.02, 0.0, 0.0]), (1.0, 0.0)
    with jit.disabled():
        assert not jit.available()
        np.testing.assert_array_equal(law.average_wrench(p, u, ONE_BOX, 0.02, 5.0),
                                      law.average_wrench_reference(p, u, ONE_BOX, 0.02, 5.0))
        t = np.linspace(0.0, 0.01, 5)
        np.testing.assert_array_equal(law.tooth_wrenches(t, p, u, ONE_BOX, 0.1, 0.02, 5.0),
                                      law.tooth_wrenches_reference(t, p, u, ONE_BOX, 0.1, 0.02, 5.0))
    env = dict(os.environ, ROBSTIFF_NO_JIT="1")
    out = subprocess.run([sys.executable, "-c", "from robstiff_drake.model import jit; print(jit.available())"],
                         env=env, capture_output=True, text=True, check=True).stdout
    assert out.strip() == "False"


def test_the_compiled_kernels_are_the_numpy_references():
    if not jit.available():
        pytest.skip("numba is not installed (pip install 'robstiff-drake[fast]'): the compiled kernels are not "
                    "used here; their Python originals are tested above")
    for name, law in LAWS.items():
        for i, (p, u, feed, travel) in enumerate(cases(2, 40)):
            assert_round_off(law.average_wrench(p, u, TWO_BOXES, feed, travel),
                             law.average_wrench_reference(p, u, TWO_BOXES, feed, travel), rel=1e-12)
            t = np.linspace(0.0, 0.002, 22) + 0.0007 * i
            assert_round_off(law.tooth_wrenches(t, p, u, TWO_BOXES, 0.3, feed, travel),
                             law.tooth_wrenches_reference(t, p, u, TWO_BOXES, 0.3, feed, travel), rel=1e-12)
    assert ck.average_wrench_at._impl is not ck.average_wrench_at.py_func  # (it did run compiled)
