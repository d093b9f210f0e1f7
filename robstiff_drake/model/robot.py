"""The robot's parameters (kinematic table, controller convention, limits,
joint stiffness, inertias, payload), loaded from a YAML robot file: one of
the library in ``models/`` (``load_robot("irb6640")``) or any file of the
same form (``load_robot("my_robot.yaml")``); its keys, with their ranges
and units, are in model/robot_file.py (KEYS: one line to add a key).

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

from robstiff_drake.errors import InputError, excerpt
from robstiff_drake.command import input_warning
from robstiff_drake.model.robot_checks import plausibility, shape_inertia
from robstiff_drake.model.robot_file import N_JOINTS, check_units, read_robot_values
from robstiff_drake.model.robot_parts import (  # noqa: F401 (the parts are re-exported: callers import them from here)
    DH, IDENTITY_MAP, JointMap, Link, Payload, Workspace)
from robstiff_drake.paths import DEFAULT_ROBOT_NAME, library_robots, robot_file
from robstiff_drake.user_files import load_yaml, read_user_text

GRAVITY_BASE_M_PER_S2 = np.array([0.0, 0.0, -9.81])  # in the robot base frame
NAME_RE = re.compile(r"[A-Za-z][A-Za-z0-9_]*")  # robot and link names (file names, URDF names)


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
    # one line each: values that look like another unit, implausible physics
    # (model/robot_file.check_units, model/robot_checks.plausibility)
    warnings: tuple = ()
    # the motors' rotor inertias reflected to the joints (n^2 J_rotor, kg*m^2); None: not in the file
    # (the station then takes the rule of model/joint_dynamics.motor_inertia)
    motor_inertia_kgm2: np.ndarray | None = None
    # the controller's axis speed and acceleration limits (deg/s, deg/s^2,
    # controller convention; joint_limits.speed_deg_per_s and
    # .acceleration_deg_per_s2); None: the robot file does not give them
    speed_limit_deg_per_s: np.ndarray | None = None
    acceleration_limit_deg_per_s2: np.ndarray | None = None
    # the maker's rated wrist payload (kg, the data sheet's), or None when the file gives none
    rated_payload_kg: float | None = None

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

    @property
    def title(self):
        """'KUKA KR 240 R2900-2': the maker and model, without an unknown ('-') maker; else the name."""
        return " ".join(v for v in (self.manufacturer, self.model) if v and v != "-") or self.name

    def tool_point(self, tool_m=None, where="this command"):
        """``tool_m`` (m) when given, else the robot file's tool point; an
        InputError naming the file and key when neither is there."""
        if tool_m is not None:
            return np.asarray(tool_m, dtype=float)
        if self.payload.tool_point_m is None:
            raise InputError(f"{self.source}: key 'payload.tool_point_mm': missing, and {where} needs a tool "
                             "point (add it to the robot file or pass --tool X,Y,Z)")
        return self.payload.tool_point_m


def _inertia_tensor(values, key, v):
    """[ixx, iyy, izz, ixy, ixz, iyz] (kg m^2) -> 3x3, refused unless physical
    (positive principal moments, each no larger than the sum of the others)."""
    ixx, iyy, izz, ixy, ixz, iyz = v
    I = np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])
    w = np.linalg.eigvalsh(I)
    if w[0] <= 0 or w[0] + w[1] < w[2] * (1 - 1e-9):
        values.fail(key, f"not a physical inertia tensor (principal moments {np.round(w, 6).tolist()} kg m^2: each "
                         "must be > 0 and at most the sum of the other two)")
    return I


def _rot_x(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[1.0, 0, 0], [0, c, -s], [0, s, c]])


def _rot_y(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0, s], [0, 1.0, 0], [-s, 0, c]])


def _dh(values, convention):
    """The canonical chain (DH) of the file's kinematic table."""
    d = values["dh.d_mm"] / 1000.0
    a = values["dh.a_mm"] / 1000.0
    alpha = np.deg2rad(values["dh.alpha_deg"])
    home = np.deg2rad(values["dh.home_deg"])
    # optional: Hayati's tilt about y after each row's x-twist (a calibrated
    # arm's nearly parallel axes; `robstiff diagnose --write-robot` writes it)
    beta_deg = values.get("dh.beta_deg")
    beta = np.deg2rad(beta_deg) if beta_deg is not None and np.any(beta_deg) else None
    if convention == "standard_dh":
        return DH(d_m=d, a_m=a, alpha_rad=alpha, home_rad=home, beta_rad=beta)
    # Modified (Craig) DH: link i = Rx(alpha_{i-1}) Tx(a_{i-1}) Rz(theta_i) Tz(d_i),
    # rows i = 1..6 list (alpha_{i-1}, a_{i-1}, d_i, theta offset_i).  Regrouped,
    # the chain is Rx(alpha_0) Tx(a_0) (a fixed base transform), then standard
    # links i = 1..5 with (d_i, a_i, alpha_i) taken from rows i and i+1, and a
    # last link with d_6 only (Tx and Rx commute: both act along x).  A row's
    # beta_deg is Ry(beta_i) after its Rx(alpha_{i-1}) Tx(a_{i-1}), before Rz:
    # row 1's joins the base transform, row i+1's ends standard link i.
    base = None
    b = np.zeros(N_JOINTS) if beta is None else beta
    if a[0] != 0.0 or alpha[0] != 0.0 or b[0] != 0.0:
        base = np.eye(4)
        base[:3, :3] = _rot_x(alpha[0]) @ _rot_y(b[0])
        base[0, 3] = a[0]
    return DH(d_m=d, a_m=np.r_[a[1:], 0.0], alpha_rad=np.r_[alpha[1:], 0.0], home_rad=home, base=base,
              beta_rad=None if not np.any(b[1:]) else np.r_[b[1:], 0.0])


# The steepest a joint's periodic errors may be (d error / d angle, summed over its terms): beyond 1 the
# joint would turn backwards as its motor turns forwards; half of that bounds any reducer or encoder
MAX_PERIODIC_SLOPE = 0.5


def _periodic(values):
    out = tuple((int(e["joint"]) - 1, np.deg2rad(e["period_deg"]), e["sin_mrad"] * 1e-3, e["cos_mrad"] * 1e-3)
                for e in values.get("joint_periodic_errors", []))
    for j in range(N_JOINTS):
        slope = sum(np.hypot(s, c) * 2 * np.pi / p for k, p, s, c in out if k == j)
        if slope > MAX_PERIODIC_SLOPE:
            values.fail("joint_periodic_errors", f"joint {j + 1}'s periodic errors change its angle by up to "
                        f"{slope:.3g} rad per rad (at most {MAX_PERIODIC_SLOPE:g}: a joint does not turn backwards); "
                        "is an amplitude in rad instead of mrad, or a period in rad instead of deg?")
    return out


def _joint_map(values):
    if "controller" not in values and not any(k.startswith("controller.") for k in values):
        periodic = _periodic(values)
        return replace(IDENTITY_MAP, periodic=periodic) if periodic else IDENTITY_MAP
    p = "controller."
    sign = values.get(p + "sign", np.ones(N_JOINTS))
    if not np.all(np.isin(sign, (-1.0, 1.0))):
        values.fail(p + "sign", f"each sign must be +1 or -1, got {sign.tolist()}")
    offset = np.deg2rad(values.get(p + "offset_deg", np.zeros(N_JOINTS)))
    coupling = []
    for n, entry in enumerate(values.get(p + "coupling", [])):
        j, k = int(entry["joint"]), int(entry["from"])
        if j == k:
            values.fail(f"{p}coupling[{n}].from", "a joint cannot be coupled to itself (use sign)")
        coupling.append((j - 1, k - 1, entry["factor"]))
    jm = JointMap(sign, offset, tuple(coupling), _periodic(values))
    if abs(np.linalg.det(jm.G)) < 1e-9:
        values.fail(p + "coupling", "the map from controller to model angles is singular (not invertible)")
    return jm


def _links(values):
    links = []
    for i, ld in enumerate(values["links"]):
        p = f"links[{i}]."
        m = ld["mass_kg"]
        if "box_mm" in ld and "cylinder_mm.radius" in ld:
            values.fail(p + "cylinder_mm", "give box_mm or cylinder_mm, not both")
        if "box_mm" in ld:
            size, shape, axis = ld["box_mm"] / 1000.0, "box", "z"
        elif "cylinder_mm.radius" in ld:
            shape, axis = "cylinder", ld["cylinder_mm.axis"]
            size = np.array([ld["cylinder_mm.radius"] / 1000.0, ld["cylinder_mm.length"] / 1000.0, 0.0])
        else:
            values.fail(p + "box_mm", "each link needs box_mm or cylinder_mm")
        inertia = shape_inertia(m, shape, size, axis)
        if "inertia_kgm2" in ld:  # a published tensor instead of the shape's
            inertia = _inertia_tensor(values, p + "inertia_kgm2", ld["inertia_kgm2"])
        name = ld["name"]
        if not NAME_RE.fullmatch(name):
            values.fail(p + "name", f"{excerpt(name)}: use letters, digits and _ only")
        if name in [link.name for link in links] or name in ("flange", "spindle"):
            values.fail(p + "name", f"link name {name!r} is used twice (or is one of the reserved flange, spindle)")
        links.append(Link(name, m, ld["com_mm"] / 1000.0, inertia, size, shape, axis))
    return tuple(links)


def _check_not_singular(values, dh):
    """Refuse a chain that cannot place the flange: every length zero, or a
    Jacobian of rank below 6 at every one of a set of fixed configurations."""
    from robstiff_drake.model import kinematics as kin

    if not np.any(dh.a_m) and not np.any(dh.d_m) and (dh.base is None or not np.any(dh.base[:3, 3])):
        values.fail("dh", "every link length (a_mm, d_mm) is zero: the chain has no extent")
    qs = np.random.default_rng(0).uniform(-np.pi, np.pi, size=(20, N_JOINTS))  # fixed: same check every time
    J = kin.jacobian(dh, qs, np.zeros(3))
    scale = np.abs(np.r_[dh.a_m, dh.d_m]).max()
    # lengths in m: linear rows scale with the arm, angular rows are O(1)
    Jn = J.copy()
    Jn[:, :3, :] /= scale
    s = np.linalg.svd(Jn, compute_uv=False)
    if np.all(s[:, -1] < 1e-9 * s[:, 0]):
        values.fail("dh", "the kinematic table is singular: at every tested configuration the six joints move the "
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
    (the default robot, the paper's IRB6400).  The file is checked key by
    key against model/robot_file.KEYS (ranges and units), for values in
    another unit, and for plausible physics (model/robot_checks.py); the
    warnings are in the model's ``warnings`` and, inside a command, printed
    and added to its JSON (io.input_warning).  InputError (one line naming
    file, line and key) for anything wrong."""
    path = resolve_robot(path)
    doc, lines = load_yaml(read_user_text(path, "robot file"), path)
    values = read_robot_values(path, doc, lines)
    unit_warnings = check_units(values)
    convention = values.get("convention", "standard_dh")
    dh = _dh(values, convention)
    joint_map = _joint_map(values)
    lower, upper = values["joint_limits.lower_deg"], values["joint_limits.upper_deg"]
    for i in range(N_JOINTS):
        if not lower[i] < upper[i]:  # (at lower_deg's line; a pair the other way round is likely swapped)
            swapped = " (swapped? lower_deg takes each range's lower end)" if upper[i] < lower[i] else ""
            values.fail("joint_limits.lower_deg", f"joint {i + 1}: lower {lower[i]:g} >= upper {upper[i]:g} deg: "
                        f"the lower limit must be below the upper{swapped}")
    links = _links(values)
    payload = Payload(mass_kg=values["payload.mass_kg"], com_m=values["payload.com_mm"] / 1000.0,
                      tool_point_m=(values["payload.tool_point_mm"] / 1000.0 if "payload.tool_point_mm" in values
                                    else None),
                      measured_point_m=(values["payload.measured_point_mm"] / 1000.0
                                        if "payload.measured_point_mm" in values else None))
    box = {}
    for key in ("x_mm", "y_mm", "z_mm"):
        lo_hi = values[f"machining_workspace.{key}"] / 1000.0
        if not lo_hi[0] < lo_hi[1]:
            values.fail(f"machining_workspace.{key}", "expected [min, max] with min < max")
        box[key] = (float(lo_hi[0]), float(lo_hi[1]))
    workspace = Workspace(box["x_mm"], box["y_mm"], box["z_mm"],
                          values["machining_workspace.reference_tool_point_mm"] / 1000.0)
    _check_not_singular(values, dh)
    name = values["name"]
    if not NAME_RE.fullmatch(name):
        values.fail("name", f"{excerpt(name)}: use letters, digits and _ only (it names files and the URDF)")
    robot = RobotModel(
        name=name,
        dh=dh,
        q_lower_rad=np.deg2rad(lower),
        q_upper_rad=np.deg2rad(upper),
        joint_stiffness_Nm_per_rad=values["joint_stiffness_Nm_per_rad"],
        links=links,
        payload=payload,
        workspace=workspace,
        source=str(path),
        manufacturer=values.get("manufacturer", "-"),
        model=values.get("model", name),
        citation=values.get("source", "-"),
        convention=convention,
        joint_map=joint_map,
        motor_inertia_kgm2=values.get("motor_inertia_kgm2"),
        speed_limit_deg_per_s=values.get("joint_limits.speed_deg_per_s"),
        acceleration_limit_deg_per_s2=values.get("joint_limits.acceleration_deg_per_s2"),
        rated_payload_kg=values.get("rated_payload_kg"),
    )
    if "rated_payload_kg" in values and values["payload.mass_kg"] > values["rated_payload_kg"]:
        unit_warnings.append(f"{values.at('payload.mass_kg')}: payload.mass_kg {values['payload.mass_kg']:g} kg is "
                             f"over the arm's rated payload (rated_payload_kg {values['rated_payload_kg']:g} kg): "
                             "the maker's load and wrist-moment limits, on which its accuracy and its gearboxes' "
                             "life rest, are exceeded; the model computes it all the same")
    warnings = tuple(input_warning(w if w.startswith(str(path)) else f"{path}: {w}")
                     for w in unit_warnings + plausibility(robot))
    return replace(robot, warnings=warnings)


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
