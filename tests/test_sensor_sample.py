"""The wrist sensor's compiled sample (model/sensor_sample.py) against its
plain-Python sample (systems/wrist_sensor.WristForceSensor, inside
jit.disabled()) in one simulation each: the same samples, bit for bit, with
and without noise, NaN in the reaction on the way; and the sensors that
must keep the plain path (dropouts, spikes, the tooth ripple, a subclass
with its own reading) keep it."""

import contextlib

import numpy as np
import pytest
from pydrake.common import RandomGenerator
from pydrake.common.value import AbstractValue
from pydrake.multibody.math import SpatialForce
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder, LeafSystem
from pydrake.systems.primitives import LogVectorOutput

from robstiff_drake.model import jit, sensor_sample
from robstiff_drake.systems.wrist_sensor import LagFreeCuttingSensor, WristForceSensor, add_random_inputs

RATE_HZ = 250.0
JOINT = 2  # (the weld's index in the list: not the first or the last)


class Reactions(LeafSystem):
    """A list of three joints' reaction forces (abstract), the middle one
    varying with time (and NaN on one stretch, zero on another)."""

    def __init__(self):
        super().__init__()
        self.DeclareAbstractOutputPort("reaction_forces", lambda: AbstractValue.Make([SpatialForce()]),
                                       self._calc)

    def _calc(self, context, out):
        t = context.get_time()
        c = np.array([5.0, -3.0, 20.0, 300.0, -250.0, 60.0]) * np.sin(11.0 * t + np.arange(6))
        if 0.05 <= t < 0.06:
            c[:] = np.nan
        if 0.08 <= t < 0.09:
            c[:] = 0.0
        other = SpatialForce(np.arange(6.0))
        out.set_value([other, other, SpatialForce(c[:3], c[3:]), other])


def _samples(noise):
    b = DiagramBuilder()
    src = b.AddSystem(Reactions())
    sensor = b.AddSystem(WristForceSensor(weld_joint_index=JOINT, rate_hz=RATE_HZ, force_bias_N=(2.0, -1.0, 3.0),
                                          torque_bias_Nm=(0.1, 0.0, -0.2), noise_N=0.5 * noise,
                                          noise_Nm=0.05 * noise))
    b.Connect(src.get_output_port(), sensor.GetInputPort("reaction_forces"))
    add_random_inputs(b, sensor)
    log = LogVectorOutput(sensor.get_output_port(), b, 1.0 / RATE_HZ)
    diagram = b.Build()
    sim = Simulator(diagram)
    diagram.SetRandomContext(sim.get_mutable_context(), RandomGenerator(7))
    sim.AdvanceTo(0.2)
    return sensor, log.FindLog(sim.get_context()).data()


@pytest.mark.parametrize("noise", [1.0, 0.0], ids=["noise", "no noise"])
def test_the_compiled_sample_is_the_plain_sample_exactly(noise):
    if not jit.available():
        pytest.skip("numba is not installed: the sensor runs its plain sample (tested elsewhere)")
    sensor, compiled = _samples(noise)
    assert sensor._lean
    with jit.disabled():
        _, plain = _samples(noise)
    assert compiled.shape == plain.shape == (6, 51)
    np.testing.assert_array_equal(compiled, plain)  # (bit for bit; NaN where NaN)
    assert np.isnan(compiled).any() and np.isfinite(compiled).sum() > 200
    finite = np.isfinite(plain)  # (the zeros' signs too; a NaN's sign bit means nothing)
    assert np.array_equal(np.signbit(compiled[finite]), np.signbit(plain[finite]))
    assert (plain == 0.0).any() or noise


def test_the_kernel_is_the_plain_arithmetic():
    """The kernel's own operations, compiled or as Python, on awkward values."""
    rng = np.random.default_rng(3)
    for _ in range(50):
        c, g, bias, noise = (rng.normal(size=6) * s for s in (300.0, 1.0, 2.0, 0.5))
        c[rng.integers(6)] = rng.choice([0.0, -0.0, np.inf, 1e300])
        t0, t1, t2, f0, f1, f2 = c.tolist()
        plain = [a + b + n * s for a, b, n, s in zip([-f0, -f1, -f2, -t0, -t1, -t2], bias.tolist(), noise.tolist(),
                                                      g.tolist())]
        for fn in (sensor_sample.wrist_sample, sensor_sample.wrist_sample.py_func):
            out = np.full(6, 7.0)
            fn(c, g, bias, noise, out)
            np.testing.assert_array_equal(out, plain)
            out = np.full(6, 7.0)
            fn(c, sensor_sample.NO_NOISE, bias, noise, out)
            np.testing.assert_array_equal(out, [a + b for a, b in zip([-f0, -f1, -f2, -t0, -t1, -t2], bias.tolist())])


@pytest.mark.parametrize("kw", [dict(dropout_probability=0.01), dict(spike_probability=0.01, spike_N=50.0),
                                dict(tooth_ripple=True)], ids=["dropouts", "spikes", "tooth ripple"])
def test_what_the_kernel_does_not_do_stays_plain(kw):
    assert not WristForceSensor(weld_joint_index=0, rate_hz=RATE_HZ, noise_N=0.5, **kw)._lean


def test_a_subclass_with_its_own_reading_stays_plain():
    from robstiff_drake.model.payload import PayloadCalibration

    s = LagFreeCuttingSensor(tool_m=(0.0, 0.0, 0.3), payload=PayloadCalibration(mass_kg=40.0),
                             weld_joint_index=0, rate_hz=RATE_HZ)
    assert not s._lean
