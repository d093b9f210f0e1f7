"""The robot's parameters (DH table, limits, joint stiffness, inertias,
payload), loaded from the YAML parameter file in ``models/``.

Plain numpy: nothing here knows about Drake.  Inside the model, lengths are
metres and angles radians; the YAML and every user-facing interface use mm
and degrees (controller convention of the seed's Table 1).
"""

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml

from robstiff_drake.errors import InputError
from robstiff_drake.paths import DEFAULT_ROBOT_YAML

N_JOINTS = 6
GRAVITY_BASE_M_PER_S2 = np.array([0.0, 0.0, -9.81])  # in the robot base frame


@dataclass(frozen=True)
class DH:
    """Standard DH table: link i is Rz(theta_i) Tz(d_i) Tx(a_i) Rx(alpha_i),
    with theta_i = q_i + home_i (q in the controller convention)."""

    d_m: np.ndarray
    a_m: np.ndarray
    alpha_rad: np.ndarray
    home_rad: np.ndarray


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
    """Spindle, sensor and tool on the flange (DH frame 6 = sensor frame)."""

    mass_kg: float
    com_m: np.ndarray
    tool_point_m: np.ndarray

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


@dataclass(frozen=True)
class RobotModel:
    name: str
    dh: DH
    q_lower_rad: np.ndarray
    q_upper_rad: np.ndarray
    joint_stiffness_Nm_per_rad: np.ndarray
    links: tuple
    payload: Payload
    workspace: Workspace
    source: str = field(default="")

    @property
    def joint_compliance_rad_per_Nm(self):
        return 1.0 / self.joint_stiffness_Nm_per_rad

    @property
    def total_mass_kg(self):
        return float(sum(link.mass_kg for link in self.links))

    def with_joint_stiffness(self, k_Nm_per_rad):
        """A copy of the model with other joint stiffnesses (N*m/rad)."""
        from dataclasses import replace

        k = np.asarray(k_Nm_per_rad, dtype=float).reshape(N_JOINTS)
        return replace(self, joint_stiffness_Nm_per_rad=k)

    def check_q_deg(self, q_deg, where="joint angles"):
        """Return q in radians after checking count, finiteness and limits.

        Raises InputError naming the joint, the value and the limit."""
        q = np.asarray(q_deg, dtype=float)
        if q.shape != (N_JOINTS,):
            raise InputError(f"{where}: expected {N_JOINTS} joint angles, got {q.size}")
        lo = np.rad2deg(self.q_lower_rad)
        hi = np.rad2deg(self.q_upper_rad)
        for i in range(N_JOINTS):
            if not np.isfinite(q[i]):
                raise InputError(f"{where}: q{i + 1} = {q[i]} is not a finite number")
            if q[i] < lo[i] - 1e-9 or q[i] > hi[i] + 1e-9:
                raise InputError(
                    f"{where}: q{i + 1} = {q[i]:g} deg is outside the joint limit "
                    f"[{lo[i]:g}, {hi[i]:g}] deg of {self.name} ({self.source})"
                )
        return np.deg2rad(q)


def _inertia_box(m, size):
    a, b, c = size
    return np.diag([m * (b * b + c * c), m * (a * a + c * c), m * (a * a + b * b)]) / 12.0


def _inertia_cylinder(m, radius, length, axis):
    i_ax = 0.5 * m * radius**2
    i_perp = m * (3 * radius**2 + length**2) / 12.0
    k = "xyz".index(axis)
    diag = [i_perp] * 3
    diag[k] = i_ax
    return np.diag(diag)


class _Reader:
    """Walks the parsed YAML with error messages that name file and key."""

    def __init__(self, path):
        self.path = str(path)

    def fail(self, key, what):
        raise InputError(f"{self.path}: key '{key}': {what}")

    def get(self, mapping, key, prefix=""):
        full = f"{prefix}{key}"
        if not isinstance(mapping, dict) or key not in mapping:
            self.fail(full, "missing")
        return mapping[key]

    def vector(self, mapping, key, n, prefix=""):
        value = self.get(mapping, key, prefix)
        try:
            arr = np.asarray(value, dtype=float)
        except (TypeError, ValueError):
            self.fail(f"{prefix}{key}", f"expected {n} numbers, got {value!r}")
        if arr.shape != (n,):
            self.fail(f"{prefix}{key}", f"expected {n} numbers, got {arr.size}")
        if not np.all(np.isfinite(arr)):
            self.fail(f"{prefix}{key}", "contains a non-finite number")
        return arr

    def number(self, mapping, key, prefix="", positive=False):
        value = self.get(mapping, key, prefix)
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            self.fail(f"{prefix}{key}", f"expected a number, got {value!r}")
        if positive and not value > 0:
            self.fail(f"{prefix}{key}", f"must be > 0, got {value!r}")
        return float(value)

    def only_keys(self, mapping, allowed, prefix=""):
        for key in mapping:
            if key not in allowed:
                self.fail(f"{prefix}{key}", f"unknown key (allowed: {', '.join(sorted(allowed))})")


def load_robot(path=None):
    """Load a RobotModel from a YAML parameter file (default: the IRB6400)."""
    path = Path(path) if path is not None else DEFAULT_ROBOT_YAML
    try:
        text = path.read_text()
    except OSError as e:
        raise InputError(f"{path}: cannot read robot parameter file ({e.strerror})") from None
    try:
        doc = yaml.safe_load(text)
    except yaml.YAMLError as e:
        mark = getattr(e, "problem_mark", None)
        where = f"line {mark.line + 1}, column {mark.column + 1}: " if mark else ""
        raise InputError(f"{path}: {where}invalid YAML ({getattr(e, 'problem', e)})") from None
    r = _Reader(path)
    if not isinstance(doc, dict):
        raise InputError(f"{path}: expected a mapping at the top level")
    r.only_keys(doc, {"name", "dh", "joint_limits", "joint_stiffness_Nm_per_rad", "links",
                      "payload", "machining_workspace"})

    dh_doc = r.get(doc, "dh")
    r.only_keys(dh_doc, {"d_mm", "a_mm", "alpha_deg", "home_deg"}, "dh.")
    dh = DH(
        d_m=r.vector(dh_doc, "d_mm", N_JOINTS, "dh.") / 1000.0,
        a_m=r.vector(dh_doc, "a_mm", N_JOINTS, "dh.") / 1000.0,
        alpha_rad=np.deg2rad(r.vector(dh_doc, "alpha_deg", N_JOINTS, "dh.")),
        home_rad=np.deg2rad(r.vector(dh_doc, "home_deg", N_JOINTS, "dh.")),
    )

    lim = r.get(doc, "joint_limits")
    r.only_keys(lim, {"lower_deg", "upper_deg"}, "joint_limits.")
    lower = r.vector(lim, "lower_deg", N_JOINTS, "joint_limits.")
    upper = r.vector(lim, "upper_deg", N_JOINTS, "joint_limits.")
    for i in range(N_JOINTS):
        if not lower[i] < upper[i]:
            r.fail("joint_limits", f"joint {i + 1}: lower {lower[i]} >= upper {upper[i]}")

    k = r.vector(doc, "joint_stiffness_Nm_per_rad", N_JOINTS)
    if np.any(k <= 0):
        j = int(np.argmax(k <= 0)) + 1
        r.fail("joint_stiffness_Nm_per_rad", f"joint {j} stiffness must be > 0")

    links_doc = r.get(doc, "links")
    if not isinstance(links_doc, list) or len(links_doc) != N_JOINTS + 1:
        r.fail("links", f"expected a list of {N_JOINTS + 1} links (base and six moving links)")
    links = []
    for i, ld in enumerate(links_doc):
        p = f"links[{i}]."
        r.only_keys(ld, {"name", "mass_kg", "com_mm", "box_mm", "cylinder_mm"}, p)
        m = r.number(ld, "mass_kg", p, positive=True)
        com = r.vector(ld, "com_mm", 3, p) / 1000.0
        if "box_mm" in ld:
            size = r.vector(ld, "box_mm", 3, p) / 1000.0
            inertia, shape, axis = _inertia_box(m, size), "box", "z"
        elif "cylinder_mm" in ld:
            cyl = ld["cylinder_mm"]
            r.only_keys(cyl, {"radius", "axis", "length"}, p + "cylinder_mm.")
            rad = r.number(cyl, "radius", p + "cylinder_mm.", positive=True) / 1000.0
            length = r.number(cyl, "length", p + "cylinder_mm.", positive=True) / 1000.0
            axis = r.get(cyl, "axis", p + "cylinder_mm.")
            if axis not in ("x", "y", "z"):
                r.fail(p + "cylinder_mm.axis", f"expected x, y or z, got {axis!r}")
            inertia, shape = _inertia_cylinder(m, rad, length, axis), "cylinder"
            size = np.array([rad, length, 0.0])
        else:
            r.fail(p + "box_mm", "each link needs box_mm or cylinder_mm")
        links.append(Link(str(r.get(ld, "name", p)), m, com, inertia, size, shape, axis))

    pl = r.get(doc, "payload")
    r.only_keys(pl, {"mass_kg", "com_mm", "tool_point_mm"}, "payload.")
    payload = Payload(
        mass_kg=r.number(pl, "mass_kg", "payload.", positive=True),
        com_m=r.vector(pl, "com_mm", 3, "payload.") / 1000.0,
        tool_point_m=r.vector(pl, "tool_point_mm", 3, "payload.") / 1000.0,
    )

    ws = r.get(doc, "machining_workspace")
    p = "machining_workspace."
    r.only_keys(ws, {"x_mm", "y_mm", "z_mm", "reference_tool_point_mm"}, p)
    box = {}
    for key in ("x_mm", "y_mm", "z_mm"):
        lo_hi = r.vector(ws, key, 2, p) / 1000.0
        if not lo_hi[0] < lo_hi[1]:
            r.fail(p + key, "expected [min, max] with min < max")
        box[key] = (float(lo_hi[0]), float(lo_hi[1]))
    workspace = Workspace(box["x_mm"], box["y_mm"], box["z_mm"],
                          r.vector(ws, "reference_tool_point_mm", 3, p) / 1000.0)

    return RobotModel(
        name=str(r.get(doc, "name")),
        dh=dh,
        q_lower_rad=np.deg2rad(lower),
        q_upper_rad=np.deg2rad(upper),
        joint_stiffness_Nm_per_rad=k,
        links=tuple(links),
        payload=payload,
        workspace=workspace,
        source=str(path),
    )
