"""The wrist sensor's payload (spindle, adapter, tool) as the sensor feels
it: its calibration (what `robstiff calibrate-payload` identifies) and its
weight in the sensor frame for any flange orientation.  Plain numpy."""

from dataclasses import dataclass

import numpy as np

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
    # the robot file calibrate-payload computed it with (its kinematics gave the gravity directions; the
    # file's payload_calibration.robot); None: a file written before the key, or a calibration made here
    robot: str = None

    def arrays(self):
        """(mass kg, centre of mass m (3,), force bias N, torque bias N*m,
        R_mount (3x3, DH 6 <- sensor))."""
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
