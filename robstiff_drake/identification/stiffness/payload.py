"""Gravity calibration of the wrist sensor's payload (the paper's Section 4: mass
and centre of mass from readings at 15 configurations; here also the
sensor's force and torque bias).  Plain numpy + scipy; no Drake.

With g_s the gravity vector in the sensor frame at configuration i, the
payload's weight reads
    f_i = m g_s + b_f                      (linear in m, b_f)
    t_i = c x (m g_s) + b_t = p x g_s + b_t,  p = m c   (linear in p, b_t)
so two linear least-squares problems give m, b_f and p, b_t; c = p / m.
The torque problem needs at least three different gravity directions in the
sensor frame (two leave p's component along their difference unobserved);
turning the wrist about the vertical alone gives no new direction.
"""

import json
import re
from dataclasses import dataclass

import numpy as np
from scipy import stats

from robstiff_drake.errors import InputError
from robstiff_drake.model import kinematics as kin
from robstiff_drake.model.robot import GRAVITY_BASE_M_PER_S2

MIN_DIRECTIONS = 3
DISTINCT_DEG = 5.0  # gravity directions closer than this count as one


@dataclass
class PayloadFit:
    mass_kg: float
    mass_std_kg: float
    com_m: np.ndarray
    com_std_m: np.ndarray
    force_bias_N: np.ndarray
    torque_bias_Nm: np.ndarray
    rms_force_N: float
    rms_torque_Nm: float
    residual_force_N: np.ndarray
    residual_torque_Nm: np.ndarray
    n_configurations: int
    n_directions: int
    mount_rpy_deg: np.ndarray


def skew(v):
    x, y, z = v
    return np.array([[0, -z, y], [z, 0, -x], [-y, x, 0]])


def gravity_in_sensor(dh, q_rad, R_mount=None):
    """Gravity (m/s^2) in the sensor frame, (N, 3)."""
    R6 = kin.frames(dh, q_rad)[:, 6, :3, :3]
    Rs = R6 if R_mount is None else R6 @ R_mount
    return np.einsum("nji,j->ni", Rs, GRAVITY_BASE_M_PER_S2)


def count_directions(g_s):
    """How many distinct gravity directions (more than 5 deg apart)."""
    u = g_s / np.linalg.norm(g_s, axis=1, keepdims=True)
    reps = []
    for v in u:
        if all(np.degrees(np.arccos(np.clip(v @ r, -1, 1))) > DISTINCT_DEG for r in reps):
            reps.append(v)
    return len(reps)


def calibrate(robot, campaign, *, mount_rpy_deg=(0.0, 0.0, 0.0)):
    """Mass, centre of mass (sensor frame), force and torque bias."""
    R_mount = kin.rpy_to_rotation(np.deg2rad(mount_rpy_deg))
    g_s = gravity_in_sensor(robot.dh, robot.joint_rad(campaign.q_deg), R_mount)
    n = len(campaign)
    n_dir = count_directions(g_s)
    if n_dir < MIN_DIRECTIONS:
        raise InputError(
            f"{campaign.path}: the {n} configurations give only {n_dir} distinct gravity direction(s) in the "
            f"sensor frame; the centre of mass needs at least {MIN_DIRECTIONS} (turn the wrist, axes 4-6, "
            "not just axis 1)"
        )
    # force: f = [g_s, I] [m; b_f]
    Af = np.zeros((3 * n, 4))
    Af[:, 0] = g_s.reshape(-1)
    Af[:, 1:] = np.tile(np.eye(3), (n, 1))
    bf = campaign.force_N.reshape(-1)
    xf, *_ = np.linalg.lstsq(Af, bf, rcond=None)
    rf = bf - Af @ xf
    # torque: t = -[g_s]x p + b_t
    At = np.zeros((3 * n, 6))
    for i in range(n):
        At[3 * i:3 * i + 3, :3] = -skew(g_s[i])
        At[3 * i:3 * i + 3, 3:] = np.eye(3)
    bt = campaign.torque_Nm.reshape(-1)
    xt, *_ = np.linalg.lstsq(At, bt, rcond=None)
    rt = bt - At @ xt
    m = float(xf[0])
    if m <= 0:
        raise InputError(f"{campaign.path}: the identified mass is {m:.3g} kg (not positive): check the sign "
                         "convention of fx,fy,fz (the wrench the payload exerts on the sensor)")
    dof_f, dof_t = 3 * n - 4, 3 * n - 6
    s2f = rf @ rf / dof_f
    s2t = rt @ rt / dof_t
    cov_f = s2f * np.linalg.inv(Af.T @ Af)
    cov_t = s2t * np.linalg.inv(At.T @ At)
    p = xt[:3]
    return PayloadFit(
        mass_kg=m,
        mass_std_kg=float(np.sqrt(cov_f[0, 0])),
        com_m=p / m,
        com_std_m=np.sqrt(np.diag(cov_t)[:3]) / m,
        force_bias_N=xf[1:],
        torque_bias_Nm=xt[3:],
        rms_force_N=float(np.sqrt(np.mean(rf**2))),
        rms_torque_Nm=float(np.sqrt(np.mean(rt**2))),
        residual_force_N=rf.reshape(n, 3),
        residual_torque_Nm=rt.reshape(n, 3),
        n_configurations=n,
        n_directions=n_dir,
        mount_rpy_deg=np.asarray(mount_rpy_deg, dtype=float),
    )


def t95(dof):
    return float(stats.t.ppf(0.975, dof))


# A calibrated mass this far from the robot file's payload (a factor) means
# the forces are in other units (kN, daN, lbf, mN) rather than another tool;
# within it but beyond PAYLOAD_WARN_REL, a warning.  A centre of mass beyond
# MAX_COM_M from the sensor is not a spindle's.
UNITS_FACTOR = 20.0
PAYLOAD_WARN_REL = 0.25
MAX_COM_M = 1.0


def check_payload_fit(fit, robot, path):
    """InputError when the fit says the forces are in other units; otherwise
    warnings (one line each) for a result far from the robot file's payload."""
    m, m0 = fit.mass_kg, robot.payload.mass_kg
    if not m > 0:
        raise InputError(f"{path}: the calibrated mass is {m:.4g} kg: the forces do not show a payload's weight "
                         "(sign-flipped, or not the sensor's reading of its payload)")
    if m < m0 / UNITS_FACTOR or m > m0 * UNITS_FACTOR:
        unit = "kN" if m < m0 / UNITS_FACTOR else "mN or another small unit"
        raise InputError(f"{path}: the calibrated mass {m:.4g} kg is {m / m0:.3g} times the robot file's payload "
                         f"({m0:g} kg): the forces look like {unit}, not N (fx,fy,fz in N, mx,my,mz in N*m)")
    out = []
    if abs(m - m0) > PAYLOAD_WARN_REL * m0:
        out.append(f"calibrated mass {m:.3g} kg is far from the robot file's payload ({m0:g} kg): another tool?")
    rated = getattr(robot, "rated_payload_kg", None)
    if rated is not None and m > rated:
        out.append(f"calibrated mass {m:.3g} kg is over the arm's rated payload ({rated:g} kg, the robot file's "
                   "rated_payload_kg): the maker's load and wrist-moment limits are exceeded")
    c = np.linalg.norm(fit.com_m)
    if c > MAX_COM_M:
        out.append(f"the centre of mass is {c * 1e3:.0f} mm from the sensor, more than a spindle's "
                   f"({MAX_COM_M * 1e3:.0f} mm): check the moments' units (N*m)")
    return out


# A robot's name written as a plain YAML scalar; any other (a space, a
# quote, 'yes', 'null', a number) is written as a quoted string, read back
# as the same text.
_PLAIN_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_.-]*")
_YAML_WORDS = {"y", "n", "yes", "no", "on", "off", "true", "false", "null"}


def yaml_name(name):
    """``name`` as a YAML scalar that reads back as the same string."""
    name = str(name)
    plain = _PLAIN_NAME.fullmatch(name) and name.lower() not in _YAML_WORDS
    return name if plain else json.dumps(name)


def yaml_block(fit, source, robot_name):
    """The parameters of the closed loop's gravity-removal system, as YAML;
    ``robot_name``: the robot file the fit used (its kinematics turned the
    joint angles into gravity directions), read back by whoever loads the
    block (diagrams/scenario_models.read_payload_calibration), which warns
    when the robot in use is another."""
    def v(a, nd):
        return "[" + ", ".join(f"{x:.{nd}f}" for x in a) + "]"

    return (
        f"# Wrist-sensor payload, from `robstiff calibrate-payload {source}`\n"
        f"# ({fit.n_configurations} configurations, {fit.n_directions} gravity directions; "
        f"rms residual {fit.rms_force_N:.3f} N, {fit.rms_torque_Nm:.4f} N*m).\n"
        "payload_calibration:\n"
        f"  robot: {yaml_name(robot_name)}  # the robot file it was computed with (its kinematics)\n"
        f"  mass_kg: {fit.mass_kg:.4f}\n"
        f"  com_mm: {v(fit.com_m * 1e3, 3)}\n"
        f"  force_bias_N: {v(fit.force_bias_N, 4)}\n"
        f"  torque_bias_Nm: {v(fit.torque_bias_Nm, 5)}\n"
        f"  sensor_mount_rpy_deg: {v(fit.mount_rpy_deg, 4)}\n"
    )
