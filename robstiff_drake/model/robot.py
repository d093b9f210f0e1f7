"""The robot's parameters (kinematic table, controller convention, limits,
joint stiffness, inertias, payload), loaded from a YAML robot file: one of
the library in ``models/`` (``load_robot("irb6640")``) or any file of the
same form (``load_robot("my_robot.yaml")``).

Plain numpy: nothing here knows about Drake.  Inside the model, lengths are
metres and angles radians; the YAML and every user-facing interface use mm
and degrees.

Two sets of joint angles:

* the controller's angles ``q_ctrl`` (what the pendant shows, what a
  measurement file holds, what the joint limits of a datasheet refer to);
* the model's joint angles ``q`` (radians), one per physical joint of the
  serial chain: the kinematic table's joint variable is theta = q + home,
  the Drake plant's positions are q, and the joint springs act on q.

They are related by the robot file's ``controller`` block,
``q = G q_ctrl + offset`` with G = diag(sign) plus coupling terms (FANUC's
J2/J3 interaction: the controller's J3 is measured from the horizontal, so
the model's elbow angle is J3 + J2).  Without the block q = q_ctrl (the
paper's IRB6400).  Every kinematic table, standard or modified
Denavit-Hartenberg, is turned into one canonical chain (standard DH links
after an optional fixed base transform), which all the kinematics uses.
"""

import re
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import yaml

from robstiff_drake.errors import InputError
from robstiff_drake.paths import DEFAULT_ROBOT_NAME, library_robots, robot_file

N_JOINTS = 6
GRAVITY_BASE_M_PER_S2 = np.array([0.0, 0.0, -9.81])  # in the robot base frame
CONVENTIONS = ("standard_dh", "modified_dh")
NAME_RE = re.compile(r"[A-Za-z][A-Za-z0-9_]*")  # robot and link names (file names, URDF names)
TOP_KEYS = {"name", "manufacturer", "model", "source", "convention", "dh", "controller", "joint_limits",
            "joint_stiffness_Nm_per_rad", "links", "payload", "machining_workspace"}


@dataclass(frozen=True)
class DH:
    """The canonical chain: a fixed base transform (4x4, m; None: identity)
    then six standard-DH links, link i = Rz(theta_i) Tz(d_i) Tx(a_i)
    Rx(alpha_i) with theta_i = q_i + home_i (q: the model's joint angles)."""

    d_m: np.ndarray
    a_m: np.ndarray
    alpha_rad: np.ndarray
    home_rad: np.ndarray
    base: np.ndarray | None = None


@dataclass(frozen=True)
class JointMap:
    """Controller angles -> model joint angles: q = G q_ctrl + offset (rad).

    ``coupling``: tuples (joint, from_joint, factor), 0-based: the model's
    ``joint`` gets ``factor`` times the controller's ``from_joint`` angle."""

    sign: np.ndarray
    offset_rad: np.ndarray
    coupling: tuple = ()

    @property
    def G(self):
        G = np.diag(np.asarray(self.sign, dtype=float))
        for j, k, f in self.coupling:
            G[j, k] += f
        return G

    @property
    def is_identity(self):
        return (not self.coupling and np.all(self.sign == 1) and not np.any(self.offset_rad))

    def to_model(self, q_ctrl_rad):
        """Model joint angles (rad) of controller angles (rad), shape (..., 6)."""
        q = np.asarray(q_ctrl_rad, dtype=float)
        if self.is_identity:
            return q.copy()
        return q @ self.G.T + self.offset_rad

    def to_controller(self, q_rad):
        """Controller angles (rad) of model joint angles (rad), shape (..., 6)."""
        q = np.asarray(q_rad, dtype=float)
        if self.is_identity:
            return q.copy()
        return (q - self.offset_rad) @ np.linalg.inv(self.G).T

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
    q_lower_rad: np.ndarray  # controller convention (the datasheet's working range)
    q_upper_rad: np.ndarray
    joint_stiffness_Nm_per_rad: np.ndarray  # on the model's joints
    links: tuple
    payload: Payload
    workspace: Workspace
    source: str = field(default="")  # the robot file
    manufacturer: str = ""
    model: str = ""
    citation: str = ""  # where the kinematics come from (the file's `source:`)
    convention: str = "standard_dh"
    joint_map: JointMap = IDENTITY_MAP
    # the controller's axis speed and acceleration limits (deg/s, deg/s^2,
    # controller convention; joint_limits.speed_deg_per_s and
    # .acceleration_deg_per_s2); None: the robot file does not give them
    speed_limit_deg_per_s: np.ndarray | None = None
    acceleration_limit_deg_per_s2: np.ndarray | None = None

    @property
    def joint_compliance_rad_per_Nm(self):
        return 1.0 / self.joint_stiffness_Nm_per_rad

    @property
    def total_mass_kg(self):
        return float(sum(link.mass_kg for link in self.links))

    def with_joint_stiffness(self, k_Nm_per_rad):
        """A copy of the model with other joint stiffnesses (N*m/rad)."""
        k = np.asarray(k_Nm_per_rad, dtype=float).reshape(N_JOINTS)
        return replace(self, joint_stiffness_Nm_per_rad=k)

    # ------------------------------------------------ controller <-> model

    def joint_rad(self, q_ctrl_deg):
        """Model joint angles (rad) of controller angles in degrees, (..., 6)."""
        return self.joint_map.to_model(np.deg2rad(np.asarray(q_ctrl_deg, dtype=float)))

    def controller_deg(self, q_rad):
        """Controller angles (deg) of model joint angles in radians, (..., 6)."""
        return np.rad2deg(self.joint_map.to_controller(q_rad))

    def controller_delta_deg(self, dq_rad):
        """A change of the model's joint angles (rad) as the controller's (deg), (..., 6)."""
        return np.rad2deg(np.asarray(dq_rad, dtype=float) @ np.linalg.inv(self.joint_map.G).T)

    def model_delta_rad(self, dq_ctrl_deg):
        """A change of the controller's angles (deg) as the model's (rad), (..., 6)."""
        return np.deg2rad(np.asarray(dq_ctrl_deg, dtype=float)) @ self.joint_map.G.T

    @property
    def model_limits_rad(self):
        """(lower, upper) box of the model's joint angles that the
        controller's working ranges span (the URDF's joint limits)."""
        return self.joint_map.model_interval(self.q_lower_rad, self.q_upper_rad)

    def limit_violation(self, q_rad, tol_deg=1e-7):
        """None when model angles ``q_rad`` are inside the working ranges,
        else (joint index, controller angle deg, lower deg, upper deg)."""
        q = self.controller_deg(q_rad)
        lo, hi = np.rad2deg(self.q_lower_rad), np.rad2deg(self.q_upper_rad)
        for i in range(N_JOINTS):
            if not lo[i] - tol_deg <= q[i] <= hi[i] + tol_deg:
                return i, float(q[i]), float(lo[i]), float(hi[i])
        return None

    def within_limits(self, q_rad):
        return self.limit_violation(q_rad) is None

    def check_q_deg(self, q_deg, where="joint angles"):
        """Model joint angles (rad) of controller angles (deg), after checking
        count, finiteness and the working ranges.

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
        return self.joint_rad(q)

    def tool_point(self, tool_m=None, where="this command"):
        """``tool_m`` (m) when given, else the robot file's tool point; an
        InputError naming the file and key when neither is there."""
        if tool_m is not None:
            return np.asarray(tool_m, dtype=float)
        if self.payload.tool_point_m is None:
            raise InputError(f"{self.source}: key 'payload.tool_point_mm': missing, and {where} needs a tool "
                             "point (add it to the robot file or pass --tool X,Y,Z)")
        return self.payload.tool_point_m


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


def _inertia_tensor(r, v, key):
    """[ixx, iyy, izz, ixy, ixz, iyz] (kg m^2) -> 3x3, refused unless physical
    (positive principal moments, each no larger than the sum of the others)."""
    ixx, iyy, izz, ixy, ixz, iyz = v
    I = np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])
    w = np.linalg.eigvalsh(I)
    if w[0] <= 0 or w[0] + w[1] < w[2] * (1 - 1e-9):
        r.fail(key, f"not a physical inertia tensor (principal moments {np.round(w, 6).tolist()} kg m^2: each must "
                    "be > 0 and at most the sum of the other two)")
    return I


def _rot_x(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[1.0, 0, 0], [0, c, -s], [0, s, c]])


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

    def mapping(self, mapping, key, prefix=""):
        value = self.get(mapping, key, prefix)
        if not isinstance(value, dict):
            self.fail(f"{prefix}{key}", f"expected a mapping of keys, got {value!r}")
        return value

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
        if not np.isfinite(value):
            self.fail(f"{prefix}{key}", f"expected a finite number, got {value!r}")
        if positive and not value > 0:
            self.fail(f"{prefix}{key}", f"must be > 0, got {value!r}")
        return float(value)

    def text(self, mapping, key, default=None):
        if key not in mapping and default is not None:
            return default
        value = self.get(mapping, key)
        if not isinstance(value, (str, int, float)) or isinstance(value, bool):
            self.fail(key, f"expected text, got {value!r}")
        return str(value)

    def only_keys(self, mapping, allowed, prefix=""):
        for key in mapping:
            if key not in allowed:
                self.fail(f"{prefix}{key}", f"unknown key (allowed: {', '.join(sorted(allowed))})")


def _read_dh(r, doc, convention):
    """The canonical chain (DH) of the file's kinematic table."""
    dh_doc = r.mapping(doc, "dh")
    r.only_keys(dh_doc, {"d_mm", "a_mm", "alpha_deg", "home_deg"}, "dh.")
    d = r.vector(dh_doc, "d_mm", N_JOINTS, "dh.") / 1000.0
    a = r.vector(dh_doc, "a_mm", N_JOINTS, "dh.") / 1000.0
    alpha = np.deg2rad(r.vector(dh_doc, "alpha_deg", N_JOINTS, "dh."))
    home = np.deg2rad(r.vector(dh_doc, "home_deg", N_JOINTS, "dh."))
    if convention == "standard_dh":
        return DH(d_m=d, a_m=a, alpha_rad=alpha, home_rad=home)
    # Modified (Craig) DH: link i = Rx(alpha_{i-1}) Tx(a_{i-1}) Rz(theta_i) Tz(d_i),
    # rows i = 1..6 list (alpha_{i-1}, a_{i-1}, d_i, theta offset_i).  Regrouped,
    # the chain is Rx(alpha_0) Tx(a_0) (a fixed base transform), then standard
    # links i = 1..5 with (d_i, a_i, alpha_i) taken from rows i and i+1, and a
    # last link with d_6 only (Tx and Rx commute: both act along x).
    base = None
    if a[0] != 0.0 or alpha[0] != 0.0:
        base = np.eye(4)
        base[:3, :3] = _rot_x(alpha[0])
        base[0, 3] = a[0]
    return DH(d_m=d, a_m=np.r_[a[1:], 0.0], alpha_rad=np.r_[alpha[1:], 0.0], home_rad=home, base=base)


def _read_joint_map(r, doc):
    if "controller" not in doc:
        return IDENTITY_MAP
    c = r.mapping(doc, "controller")
    p = "controller."
    r.only_keys(c, {"sign", "offset_deg", "coupling"}, p)
    sign = r.vector(c, "sign", N_JOINTS, p) if "sign" in c else np.ones(N_JOINTS)
    if not np.all(np.isin(sign, (-1.0, 1.0))):
        r.fail(p + "sign", f"each sign must be +1 or -1, got {sign.tolist()}")
    offset = np.deg2rad(r.vector(c, "offset_deg", N_JOINTS, p)) if "offset_deg" in c else np.zeros(N_JOINTS)
    coupling = []
    raw = c.get("coupling") or []
    if not isinstance(raw, list):
        r.fail(p + "coupling", "expected a list of {joint: J, from: K, factor: F}")
    for n, entry in enumerate(raw):
        q = f"{p}coupling[{n}]."
        if not isinstance(entry, dict):
            r.fail(f"{p}coupling[{n}]", "expected {joint: J, from: K, factor: F}")
        r.only_keys(entry, {"joint", "from", "factor"}, q)
        j, k = r.number(entry, "joint", q), r.number(entry, "from", q)
        f = r.number(entry, "factor", q)
        if j not in range(1, 7) or k not in range(1, 7):
            r.fail(q + "joint", f"joints are numbered 1 to 6, got joint {j:g} from {k:g}")
        if j == k:
            r.fail(q + "from", "a joint cannot be coupled to itself (use sign)")
        coupling.append((int(j) - 1, int(k) - 1, f))
    jm = JointMap(sign, offset, tuple(coupling))
    if abs(np.linalg.det(jm.G)) < 1e-9:
        r.fail(p + "coupling", "the map from controller to model angles is singular (not invertible)")
    return jm


def _read_links(r, doc):
    links_doc = r.get(doc, "links")
    if not isinstance(links_doc, list) or len(links_doc) != N_JOINTS + 1:
        r.fail("links", f"expected a list of {N_JOINTS + 1} links (base and six moving links)")
    links = []
    for i, ld in enumerate(links_doc):
        p = f"links[{i}]."
        if not isinstance(ld, dict):
            r.fail(f"links[{i}]", "expected a mapping (name, mass_kg, com_mm, box_mm or cylinder_mm)")
        r.only_keys(ld, {"name", "mass_kg", "com_mm", "box_mm", "cylinder_mm", "inertia_kgm2"}, p)
        m = r.number(ld, "mass_kg", p, positive=True)
        com = r.vector(ld, "com_mm", 3, p) / 1000.0
        if "box_mm" in ld:
            size = r.vector(ld, "box_mm", 3, p) / 1000.0
            if np.any(size <= 0):
                r.fail(p + "box_mm", "every side must be > 0")
            inertia, shape, axis = _inertia_box(m, size), "box", "z"
        elif "cylinder_mm" in ld:
            cyl = r.mapping(ld, "cylinder_mm", p)
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
        if "inertia_kgm2" in ld:  # a published tensor instead of the shape's
            inertia = _inertia_tensor(r, r.vector(ld, "inertia_kgm2", 6, p), p + "inertia_kgm2")
        name = str(r.get(ld, "name", p))
        if not NAME_RE.fullmatch(name):
            r.fail(p + "name", f"{name!r}: use letters, digits and _ only")
        if name in [link.name for link in links] or name in ("flange", "spindle"):
            r.fail(p + "name", f"link name {name!r} is used twice (or is one of the reserved flange, spindle)")
        links.append(Link(name, m, com, inertia, size, shape, axis))
    return tuple(links)


def _check_not_singular(r, dh):
    """Refuse a chain that cannot place the flange: every length zero, or a
    Jacobian of rank below 6 at every one of a set of fixed configurations."""
    from robstiff_drake.model import kinematics as kin

    if not np.any(dh.a_m) and not np.any(dh.d_m) and (dh.base is None or not np.any(dh.base[:3, 3])):
        r.fail("dh", "every link length (a_mm, d_mm) is zero: the chain has no extent")
    qs = np.random.default_rng(0).uniform(-np.pi, np.pi, size=(20, N_JOINTS))  # fixed: same check every time
    J = kin.jacobian(dh, qs, np.zeros(3))
    scale = np.abs(np.r_[dh.a_m, dh.d_m]).max()
    # lengths in m: linear rows scale with the arm, angular rows are O(1)
    Jn = J.copy()
    Jn[:, :3, :] /= scale
    s = np.linalg.svd(Jn, compute_uv=False)
    if np.all(s[:, -1] < 1e-9 * s[:, 0]):
        r.fail("dh", "the kinematic table is singular: at every tested configuration the six joints move the "
                     "flange in fewer than six independent directions (two joint axes coincide?)")


def resolve_robot(spec=None):
    """A robot file's path from ``--robot``'s value: a library name (see
    ``robstiff robots``) or a path to a YAML file; None: the default robot."""
    if spec is None or str(spec) == "":
        return robot_file(DEFAULT_ROBOT_NAME)
    text = str(spec)
    path = Path(text)
    if path.suffix.lower() in (".yaml", ".yml") or path.exists() or "/" in text or "\\" in text:
        return path
    names = library_robots()
    if text in names:
        return robot_file(text)
    raise InputError(f"--robot {text}: not a library robot ({', '.join(names)}) and not a YAML file")


def load_robot(path=None):
    """Load a RobotModel: ``path`` is a library name, a YAML file, or None
    (the default robot, the paper's IRB6400)."""
    path = resolve_robot(path)
    try:
        text = path.read_text()
    except OSError as e:
        raise InputError(f"{path}: cannot read robot parameter file ({e.strerror})") from None
    except UnicodeDecodeError:
        raise InputError(f"{path}: not a text file") from None
    try:
        doc = yaml.safe_load(text)
    except yaml.YAMLError as e:
        mark = getattr(e, "problem_mark", None)
        where = f"line {mark.line + 1}, column {mark.column + 1}: " if mark else ""
        raise InputError(f"{path}: {where}invalid YAML ({getattr(e, 'problem', e)})") from None
    r = _Reader(path)
    if not isinstance(doc, dict):
        raise InputError(f"{path}: expected a mapping at the top level")
    r.only_keys(doc, TOP_KEYS)

    convention = r.text(doc, "convention", default="standard_dh")
    if convention not in CONVENTIONS:
        r.fail("convention", f"unknown convention {convention!r} (known: {', '.join(CONVENTIONS)})")
    dh = _read_dh(r, doc, convention)
    joint_map = _read_joint_map(r, doc)

    lim = r.mapping(doc, "joint_limits")
    r.only_keys(lim, {"lower_deg", "upper_deg", "speed_deg_per_s", "acceleration_deg_per_s2"}, "joint_limits.")
    lower = r.vector(lim, "lower_deg", N_JOINTS, "joint_limits.")
    upper = r.vector(lim, "upper_deg", N_JOINTS, "joint_limits.")
    for i in range(N_JOINTS):
        if not lower[i] < upper[i]:
            r.fail("joint_limits", f"joint {i + 1}: lower {lower[i]} >= upper {upper[i]}")
    rates = {}
    for key in ("speed_deg_per_s", "acceleration_deg_per_s2"):  # optional: `compensate` needs them
        if key in lim:
            rates[key] = r.vector(lim, key, N_JOINTS, "joint_limits.")
            if np.any(rates[key] <= 0):
                r.fail(f"joint_limits.{key}", f"every value must be > 0, got {rates[key].tolist()}")

    k = r.vector(doc, "joint_stiffness_Nm_per_rad", N_JOINTS)
    if np.any(k <= 0):
        j = int(np.argmax(k <= 0)) + 1
        r.fail("joint_stiffness_Nm_per_rad", f"joint {j} stiffness must be > 0")

    links = _read_links(r, doc)

    pl = r.mapping(doc, "payload")
    r.only_keys(pl, {"mass_kg", "com_mm", "tool_point_mm"}, "payload.")
    payload = Payload(
        mass_kg=r.number(pl, "mass_kg", "payload.", positive=True),
        com_m=r.vector(pl, "com_mm", 3, "payload.") / 1000.0,
        tool_point_m=(r.vector(pl, "tool_point_mm", 3, "payload.") / 1000.0 if "tool_point_mm" in pl else None),
    )

    ws = r.mapping(doc, "machining_workspace")
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

    _check_not_singular(r, dh)
    name = r.text(doc, "name")
    if not NAME_RE.fullmatch(name):
        r.fail("name", f"{name!r}: use letters, digits and _ only (it names files and the URDF)")
    return RobotModel(
        name=name,
        dh=dh,
        q_lower_rad=np.deg2rad(lower),
        q_upper_rad=np.deg2rad(upper),
        joint_stiffness_Nm_per_rad=k,
        links=links,
        payload=payload,
        workspace=workspace,
        source=str(path),
        manufacturer=r.text(doc, "manufacturer", default="-"),
        model=r.text(doc, "model", default=r.text(doc, "name")),
        citation=r.text(doc, "source", default="-"),
        convention=convention,
        joint_map=joint_map,
        speed_limit_deg_per_s=rates.get("speed_deg_per_s"),
        acceleration_limit_deg_per_s2=rates.get("acceleration_deg_per_s2"),
    )


def same_robot_file(a, b):
    """Whether two robot specs (names or paths) name the same robot file
    (the same path, or files with the same content)."""
    pa, pb = resolve_robot(a), resolve_robot(b)
    try:
        if pa.resolve() == pb.resolve():
            return True
        return pa.read_bytes() == pb.read_bytes()
    except OSError:
        return False
