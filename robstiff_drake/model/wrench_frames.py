"""A wrench between the frames the compensation chain uses: at the tool
point in the base frame (force N, moment N*m about the tool point), and as
the wrist sensor sees it (force, moment about the sensor origin, which is
the flange origin, in the sensor frame).  Plain Python floats (the
per-cycle path) with numpy wrappers."""

import numpy as np

from robstiff_drake.model.realtime import rotate, rotate_transposed


def to_sensor_frame(R, tool_m, w):
    """A wrench at the tool point, base frame, as the wrist sensor sees it,
    for a sensor frame equal to the flange frame.  R: flange rotation,
    row-major 9 floats (base <- DH 6); tool_m: the tool point in the flange
    frame (3 floats).  Returns a list of 6."""
    f0, f1, f2 = rotate_transposed(R, w[:3])
    m0, m1, m2 = rotate_transposed(R, w[3:])
    tx, ty, tz = tool_m
    # moment about the sensor origin: m + tool x f
    return [f0, f1, f2, m0 + ty * f2 - tz * f1, m1 + tz * f0 - tx * f2, m2 + tx * f1 - ty * f0]


def wrench_to_tool_base(R_sensor, r_s, w_sensor):
    """The inverse of to_sensor_frame for a sensor frame R_sensor (base <-
    sensor, row-major 9 floats) and the tool point r_s in the sensor frame;
    w_sensor 6 floats.  Returns a list of 6."""
    fx, fy, fz, mx, my, mz = w_sensor
    rx, ry, rz = r_s
    f = rotate(R_sensor, (fx, fy, fz))
    m = rotate(R_sensor, (mx - (ry * fz - rz * fy), my - (rz * fx - rx * fz), mz - (rx * fy - ry * fx)))
    return list(f + m)


def sensor_to_tool_base(w_sensor, R_flange, tool_m, R_mount=None):
    """A wrench measured in the sensor frame (about its origin) as a wrench
    at the tool point in the base frame.  ``R_flange`` (3x3, base <- DH 6),
    ``R_mount`` (DH 6 <- sensor), ``tool_m`` the tool point in the flange
    frame (m)."""
    R_mount = np.eye(3) if R_mount is None else np.asarray(R_mount, dtype=float)
    Rs = np.asarray(R_flange, dtype=float) @ R_mount
    r_s = R_mount.T @ np.asarray(tool_m, dtype=float)  # tool point in the sensor frame
    return np.array(wrench_to_tool_base(Rs.ravel().tolist(), r_s.tolist(), np.asarray(w_sensor, dtype=float).tolist()))
