"""The wrist sensor's sample as a compiled kernel (model/jit.py): the
weld's reaction turned into the wrench the payload exerts on the sensor,
plus the sensor's bias and Gaussian noise (systems/wrist_sensor.py,
``WristForceSensor``).

The same scalar operations in the same order as the sensor's plain-Python
sample, ``(-reaction + bias) + noise * gaussian`` per axis, so the
compiled sample equals it bit for bit (tests/test_sensor_sample.py).
Without numba (or with ROBSTIFF_NO_JIT set) the sensor keeps its plain
Python, which this kernel's Python original would only make slower.
"""

import numpy as np

from robstiff_drake.model import jit
from robstiff_drake.model.jit import kernel

NO_NOISE = np.zeros(0)  # (``gaussian`` of a sensor without noise: no noise term is added)


@kernel
def wrist_sample(reaction, gaussian, bias, noise, out):
    """Write into ``out`` (6: force N, torque N*m, sensor frame) the sample
    of the weld's reaction ``reaction`` (6: torque N*m, then force N, the
    order of Drake's SpatialForce coefficients: the flange's pull on the
    spindle) negated, plus ``bias`` (6: N, N*m) and, where ``gaussian`` has
    6 values (standard normal), plus ``noise`` (6: standard deviations N,
    N*m) times them."""
    for i in range(3):
        out[i] = -reaction[3 + i] + bias[i]
        out[3 + i] = -reaction[i] + bias[3 + i]
    if gaussian.shape[0] == 6:
        for i in range(6):
            out[i] = out[i] + noise[i] * gaussian[i]


def warm_up():
    """Load (or compile) the kernel now, for the arrays a simulation passes
    it (writeable float64), not in the first sample of a timed run."""
    if jit.available():
        out = np.zeros(6)
        wrist_sample(np.zeros(6), np.zeros(6), np.zeros(6), np.zeros(6), out)
        wrist_sample(np.zeros(6), NO_NOISE, np.zeros(6), np.zeros(6), out)
