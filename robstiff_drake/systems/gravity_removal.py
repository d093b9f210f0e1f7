"""Gravity removal: subtracts the payload's weight (and the sensor's bias)
from the filtered wrench, for any robot configuration, with the parameters
that `robstiff calibrate-payload` identifies."""

from dataclasses import dataclass

import numpy as np
from pydrake.systems.framework import LeafSystem

from robstiff_drake.model.kinematics import rpy_to_rotation
from robstiff_drake.model.realtime import rotate_transposed
from robstiff_drake.model.robot import GRAVITY_BASE_M_PER_S2

_GRAVITY = tuple(GRAVITY_BASE_M_PER_S2.tolist())


@dataclass
class PayloadCalibration:
    """What `robstiff calibrate-payload` writes (payload_calibration block)."""

    mass_kg: float = 0.0
    com_mm: list = None
    force_bias_N: list = None
    torque_bias_Nm: list = None
    sensor_mount_rpy_deg: list = None

    def arrays(self):
        z = [0.0, 0.0, 0.0]
        return (float(self.mass_kg), np.asarray(self.com_mm or z, dtype=float) / 1000.0,
                np.asarray(self.force_bias_N or z, dtype=float), np.asarray(self.torque_bias_Nm or z, dtype=float),
                rpy_to_rotation(np.deg2rad(self.sensor_mount_rpy_deg or z)))


def payload_weight(R_flange, R_mount, mass_kg, com_m):
    """The payload's weight as the sensor feels it: (force N, moment N*m
    about the sensor origin), sensor frame, a tuple.  R_flange (base <- DH
    frame 6) and R_mount (DH 6 <- sensor) row-major, 9 floats each; com_m
    (3 floats) in the sensor frame.  Scalar arithmetic: the per-cycle path."""
    gx, gy, gz = rotate_transposed(R_mount, rotate_transposed(R_flange, _GRAVITY))  # gravity, sensor frame
    fx, fy, fz = mass_kg * gx, mass_kg * gy, mass_kg * gz
    cx, cy, cz = com_m
    return (fx, fy, fz, cy * fz - cz * fy, cz * fx - cx * fz, cx * fy - cy * fx)


def payload_wrench(R_flange, calibration, arrays=None):
    """The wrench the calibrated payload (weight + bias) puts on the sensor,
    sensor frame, for the flange rotation R_flange (3x3, base <- DH frame 6).
    ``arrays``: calibration.arrays(), when the caller keeps them."""
    m, c, bf, bt, R_mount = arrays or calibration.arrays()
    weight = payload_weight(np.ravel(R_flange).tolist(), R_mount.ravel().tolist(), m, c.tolist())
    return np.array(weight) + np.concatenate([bf, bt])


class GravityRemoval(LeafSystem):
    """Inputs ``wrench`` (6, sensor frame) and ``q`` (6, rad); output
    ``process_wrench`` (6): the wrench minus the payload's weight and bias
    (``payload_wrench``, here in scalar arithmetic for the per-cycle path).
    Direct feedthrough, recomputed only when an input changes."""

    def __init__(self, *, calibration, kinematics):
        super().__init__()
        m, c, bf, bt, R_mount = calibration.arrays()
        self._m = m
        self._c = tuple(c.tolist())
        self._bias = np.concatenate([bf, bt])
        self._R_mount = tuple(R_mount.ravel().tolist())
        self._kin = kinematics
        self._w = self.DeclareVectorInputPort("wrench", 6)
        self._q = self.DeclareVectorInputPort("q", 6)
        self.DeclareVectorOutputPort(
            "process_wrench", 6, self._calc,
            prerequisites_of_calc={self._w.ticket(), self._q.ticket()})

    def _calc(self, context, output):
        R = self._kin.pose(self._q.Eval(context))  # rotation in the first nine
        weight = payload_weight(R, self._R_mount, self._m, self._c)
        output.SetFromVector(self._w.Eval(context) - self._bias - weight)
