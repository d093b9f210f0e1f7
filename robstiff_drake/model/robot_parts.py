"""The robot's parts as plain values: its kinematic table (DH), the map
from the controller's joint angles to the model's (JointMap), a link's
inertial data (Link), the payload on the flange (Payload) and the tool
point's working box (Workspace).  model/robot.py's RobotModel holds them
and loads them from a robot file.  Plain numpy: nothing here knows about
Drake; lengths in metres, angles in radians."""

from dataclasses import dataclass

import numpy as np

from robstiff_drake.model.robot_file import N_JOINTS


@dataclass(frozen=True)
class DH:
    """The canonical chain: a fixed base transform (4x4, m; None: identity)
    then six standard-DH links, link i = Rz(theta_i) Tz(d_i) Tx(a_i)
    Rx(alpha_i) [Ry(beta_i)] with theta_i = q_i + home_i (q: the model's
    joint angles)."""

    d_m: np.ndarray
    a_m: np.ndarray
    alpha_rad: np.ndarray
    home_rad: np.ndarray
    base: np.ndarray | None = None
    # Hayati's tilt: link i = Rz Tz Tx Rx(alpha_i) Ry(beta_i), for nearly
    # parallel consecutive axes (a calibrated arm); None: all zero
    beta_rad: np.ndarray | None = None


@dataclass(frozen=True)
class JointMap:
    """Controller angles -> model joint angles: q = G q_ctrl + offset (rad).

    ``coupling``: tuples (joint, from_joint, factor), 0-based: the model's
    ``joint`` gets ``factor`` times the controller's ``from_joint`` angle."""

    sign: np.ndarray
    offset_rad: np.ndarray
    coupling: tuple = ()
    # (joint, period_rad, sin_rad, cos_rad), 0-based: the controller's angle of ``joint`` is off by
    # sin_rad sin(2 pi q / period) + cos_rad cos(2 pi q / period) (a reducer's or encoder's periodic error)
    periodic: tuple = ()

    def periodic_error_rad(self, q_ctrl_rad):
        """(..., 6) rad: the periodic errors of controller angles (rad)."""
        q = np.asarray(q_ctrl_rad, dtype=float)
        e = np.zeros_like(q)
        for j, period, s, c in self.periodic:
            w = 2 * np.pi / period
            e[..., j] += s * np.sin(w * q[..., j]) + c * np.cos(w * q[..., j])
        return e

    @property
    def G(self):
        G = np.diag(np.asarray(self.sign, dtype=float))
        for j, k, f in self.coupling:
            G[j, k] += f
        return G

    @property
    def is_identity(self):
        return (not self.coupling and np.all(self.sign == 1) and not np.any(self.offset_rad)
                and not self.periodic)

    def to_model(self, q_ctrl_rad):
        """Model joint angles (rad) of controller angles (rad), shape (..., 6)."""
        q = np.asarray(q_ctrl_rad, dtype=float)
        if self.is_identity:
            return q.copy()
        if self.periodic:
            q = q + self.periodic_error_rad(q)
        return q @ self.G.T + self.offset_rad

    def to_controller(self, q_rad):
        """Controller angles (rad) of model joint angles (rad), shape (..., 6)
        (with periodic errors: the fixed point q_c = x - e(q_c), x the map's
        inverse; each step shrinks the error by the slope of e, which the
        robot file's reader keeps below MAX_PERIODIC_SLOPE)."""
        q = np.asarray(q_rad, dtype=float)
        if self.is_identity:
            return q.copy()
        x = (q - self.offset_rad) @ np.linalg.inv(self.G).T
        if not self.periodic:
            return x
        qc = x.copy()
        for _ in range(30):
            qc = x - self.periodic_error_rad(qc)
        return qc

    def model_interval(self, lower_rad, upper_rad):
        """The box of model joint angles that the controller's limit box
        spans (for couplings, the bounding interval of each model joint)."""
        G = self.G
        lo = self.offset_rad + np.where(G > 0, G * lower_rad, G * upper_rad).sum(axis=1)
        hi = self.offset_rad + np.where(G > 0, G * upper_rad, G * lower_rad).sum(axis=1)
        return lo, hi


IDENTITY_MAP = JointMap(np.ones(N_JOINTS), np.zeros(N_JOINTS))


@dataclass(frozen=True)
class Link:
    """Inertial data of one link, in its URDF link frame (DH frame i-1 turned
    by joint i).  ``inertia_kgm2`` is the 3x3 tensor about the centre of mass."""

    name: str
    mass_kg: float
    com_m: np.ndarray
    inertia_kgm2: np.ndarray
    size_m: np.ndarray  # visual box size (3,) or (radius, length, 0) for cylinders
    shape: str  # "box" or "cylinder"
    cylinder_axis: str = "z"


@dataclass(frozen=True)
class Payload:
    """Spindle, sensor and tool on the flange (DH frame 6 = sensor frame).
    ``tool_point_m`` is None when the robot file gives none."""

    mass_kg: float
    com_m: np.ndarray
    tool_point_m: np.ndarray | None
    # the laser tracker's target on the flange (payload.measured_point_mm, written by diagnose --write-robot); None
    measured_point_m: np.ndarray | None = None

    # ASSUMPTION: the payload's shape is a solid cylinder along the spindle
    # axis, 120 mm in radius and twice its centre of mass's distance from
    # the flange in length (no drawing of the spindle is available).
    RADIUS_M = 0.12

    @property
    def length_m(self):
        return max(2.0 * abs(float(self.com_m[2])), 0.05)

    @property
    def inertia_about_com_kg_m2(self):
        """(3, 3) rotational inertia about the centre of mass, flange axes."""
        m, r, L = self.mass_kg, self.RADIUS_M, self.length_m
        return np.diag([m * (3 * r**2 + L**2) / 12.0] * 2 + [0.5 * m * r**2])


@dataclass(frozen=True)
class Workspace:
    """Box for the tool point in the base frame (m), spindle axis down."""

    x_m: tuple
    y_m: tuple
    z_m: tuple
    reference_tool_point_m: np.ndarray
