"""A robot file from a URDF (``robstiff import-urdf``), read with Drake's
parser (pydrake.multibody.parsing.Parser): the chain of six revolute
joints, its kinematic table from the joint axes (model/dh_from_axes.py),
the links' masses and inertias moved into the robot file's link frames
(DH frame i-1 turned by joint i: model/robot.Link), the joint limits.

What a URDF does not hold (joint stiffness, motor inertias, the machining
payload and workspace) comes from a template robot file, said so in the
written file.  A ``spindle`` body welded to the ``flange`` (what
``robstiff make-urdf`` writes) is read as the payload.  The joint angles of
the written file are the URDF's (no ``controller`` block): check them
against your controller's.

Visual and collision elements are left out before parsing (their meshes
need the robot's ROS package; the robot file's shapes are stand-ins,
boxes of each link's inertia)."""

import hashlib
import re
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import BodyIndex

from robstiff_drake.errors import InputError
from robstiff_drake.model import kinematics as kin
from robstiff_drake.model.dh_from_axes import dh_from_axes
from robstiff_drake.model.robot import DH, N_JOINTS, NAME_RE
from robstiff_drake.urdf_checks import check_urdf

FLANGE_FRAMES = ("tool0", "flange")  # ROS-Industrial's tool frame (z out of the flange), make-urdf's
PAYLOAD_BODY = "spindle"
DROPPED = ("visual", "collision", "gazebo")


@dataclass
class LinkInertia:
    name: str
    mass_kg: float
    com_m: np.ndarray  # in the robot file's link frame
    inertia_kgm2: np.ndarray  # (3, 3) about the centre of mass, link frame


@dataclass
class ImportedRobot:
    name: str
    convention: str
    dh: DH
    dh_rows: tuple  # (d, a, alpha, home) as the robot file writes them (m, rad)
    lower_rad: np.ndarray
    upper_rad: np.ndarray
    links: list  # LinkInertia, base and six moving links
    payload: LinkInertia | None  # the spindle body, in the flange frame
    plant: object  # Drake's plant of the URDF (finalized)
    flange_frame: str
    digest: str
    instance_name: str
    # what the import absorbed of a CAD export's offsets (one line each, for the file's comments and the report)
    notes: list = None


def _fail(path, what):
    raise InputError(f"{path}: {what}")


def _stripped_urdf(path):
    """The URDF's text without visual and collision elements; one-line
    InputError when it is no readable URDF."""
    try:
        raw = Path(path).read_bytes()
    except OSError as e:
        _fail(path, f"cannot read ({e.strerror})")
    try:
        root = ET.fromstring(raw)
    except ET.ParseError as e:
        line, col = e.position
        _fail(f"{path}:{line}", f"column {col + 1}: not well-formed XML ({str(e).split(':')[0]})")
    if root.tag != "robot":
        _fail(path, f"not a URDF (its top element is <{root.tag}>, not <robot>)")
    check_urdf(path, raw, root)  # the numbers Drake would raise on, or replace (a bad inertia by 1 kg)
    for parent in root.iter():
        for child in list(parent):
            if child.tag in DROPPED:
                parent.remove(child)
    # a joint that mimics another (a balancing cylinder's, say) moves no link of the chain: left out with
    # what hangs from it
    drop = {j.find("child").get("link") for j in root.findall("joint") if j.find("mimic") is not None}
    while True:
        more = {j.find("child").get("link") for j in root.findall("joint")
                if j.find("parent") is not None and j.find("parent").get("link") in drop} - drop
        if not more:
            break
        drop |= more
    for j in root.findall("joint"):
        if j.find("child") is not None and j.find("child").get("link") in drop:
            root.remove(j)
    for link in root.findall("link"):
        if link.get("name") in drop:
            root.remove(link)
    return ET.tostring(root, encoding="unicode"), root.get("name") or Path(path).stem, hashlib.sha256(raw).hexdigest()


def _chain(path, plant):
    """The six revolute joints from the root outwards, and each body's link
    index (0: the base, i: moves with revolute joint i)."""
    joints = [plant.get_joint(j) for j in plant.GetJointIndices()]
    movable = [j for j in joints if j.num_velocities() > 0]
    kinds = sorted({j.type_name() for j in movable} - {"revolute"})
    if kinds:
        _fail(path, f"the chain has {', '.join(kinds)} joints: a robot file is six revolute joints")
    if len(movable) != N_JOINTS:
        _fail(path, f"{len(movable)} revolute joints ({', '.join(j.name() for j in movable)}): a robot file has "
                    f"{N_JOINTS} in a chain")
    by_child = {int(j.child_body().index()): j for j in joints}
    link_of, levels = {}, {}

    def level(body):
        idx = int(body.index())
        if idx not in link_of:
            j = by_child.get(idx)
            if j is None:
                link_of[idx] = 0
            else:
                below = level(j.parent_body())
                link_of[idx] = below + (1 if j.num_velocities() else 0)
                if j.num_velocities():
                    levels.setdefault(below + 1, []).append(j)
        return link_of[idx]

    for i in range(plant.num_bodies()):
        level(plant.get_body(BodyIndex(i)))
    ordered = []
    for i in range(1, N_JOINTS + 1):
        js = levels.get(i, [])
        if len(js) != 1:
            _fail(path, f"the revolute joints do not form one chain ({len(js)} at depth {i}): a robot file is a "
                        "serial arm")
        ordered.append(js[0])
    return ordered, link_of


def read_urdf(path):
    """The URDF at ``path`` as an ImportedRobot (InputError, one line, when
    it is unreadable or no six-joint serial arm a robot file describes)."""
    text, name, digest = _stripped_urdf(path)
    notes = []
    plant, instance = _plant(path, text)
    joints, link_of = _chain(path, plant)
    X_base = _base_correction(path, text, plant, joints[0], notes)
    if X_base is not None:  # the URDF's base frame a little off joint 1's axis: the robot file's base on it
        plant, instance = _plant(path, text, X_base)
        joints, link_of = _chain(path, plant)
    ctx = plant.CreateDefaultContext()
    W = plant.world_frame()
    points, dirs, lower, upper = [], [], [], []
    for j in joints:
        X = plant.CalcRelativeTransform(ctx, W, j.frame_on_child())
        points.append(X.translation())
        dirs.append(X.rotation().matrix() @ j.revolute_axis())
        lo, hi = j.position_lower_limits()[0], j.position_upper_limits()[0]
        if not (np.isfinite(lo) and np.isfinite(hi)):
            _fail(path, f"joint {j.name()} has no position limits (a continuous joint): give it <limit lower= "
                        "upper=>")
        lower.append(lo)
        upper.append(hi)
    flange = next((f for f in FLANGE_FRAMES if plant.HasFrameNamed(f)), None)
    X_WF = plant.CalcRelativeTransform(ctx, W, plant.GetFrameByName(flange) if flange else joints[-1].frame_on_child())
    R_WF = _flange_convention(X_WF.rotation().matrix(), dirs[-1], flange, notes)
    try:
        convention, d, a, alpha, home, (alpha0, a0) = dh_from_axes(points, dirs, R_WF, X_WF.translation())
    except ValueError as e:
        snapped = _snap_flange(R_WF, dirs[-1])
        if snapped is None:
            _fail(path, _plain(e, path, joints, flange))
        R_WF, residual_deg = snapped
        try:
            convention, d, a, alpha, home, (alpha0, a0) = dh_from_axes(points, dirs, R_WF, X_WF.translation())
        except ValueError:
            _fail(path, _plain(e, path, joints, flange))
        notes.append(f"the flange frame '{flange}' is turned {residual_deg:.3g} deg off joint 6's axis (a CAD "
                     "export's rounding): the robot file's flange has its z axis along the axis (its origin is the "
                     "URDF's)")
    base = None
    if convention == "modified_dh":
        base = np.eye(4)
        base[:3, :3] = kin.rpy_to_rotation([alpha0, 0.0, 0.0])
        base[0, 3] = a0
    dh = DH(d_m=d, a_m=a, alpha_rad=alpha, home_rad=home, base=base)
    frames = kin.frames(dh, np.zeros(N_JOINTS))
    # the robot file's link frames at the zero configuration: the base, then DH frame i-1 turned by home_i
    link_frames = [np.eye(4)]
    for i in range(N_JOINTS):
        Rz = np.eye(4)
        c, s = np.cos(home[i]), np.sin(home[i])
        Rz[:2, :2] = [[c, -s], [s, c]]
        link_frames.append(frames[i] @ Rz)
    parts = []
    payload = None
    for bi in range(plant.num_bodies()):
        body = plant.get_body(BodyIndex(bi))
        if body.index() == plant.world_body().index():
            continue
        M = body.default_spatial_inertia()
        m = M.get_mass()
        if m <= 0:
            continue
        X_WB = plant.EvalBodyPoseInWorld(ctx, body)
        c_B = M.get_com()
        I_Bo = M.CalcRotationalInertia().CopyToFullMatrix3()
        I_cm_B = I_Bo - m * (np.dot(c_B, c_B) * np.eye(3) - np.outer(c_B, c_B))
        R = X_WB.rotation().matrix()
        item = (m, X_WB.multiply(c_B), R @ I_cm_B @ R.T, body.name())
        if body.name() == PAYLOAD_BODY and flange == "flange":
            payload = item
            continue
        parts.append((link_of[int(body.index())], item))
    links = []
    for i in range(N_JOINTS + 1):
        members = [it for k, it in parts if k == i]
        if not members:
            _fail(path, f"link {i} of the chain has no mass (no <inertial>; ROS-Industrial's URDFs carry none): "
                        "a robot file needs each link's mass and inertia (the maker's CAD)")
        links.append(_composite(members, link_frames[i], _link_name(members, i)))
    pl = None
    if payload is not None:
        pl = _composite([payload], frames[N_JOINTS], PAYLOAD_BODY)
    return ImportedRobot(name=_clean_name(name), convention=convention, dh=dh, dh_rows=(d, a, alpha, home, alpha0, a0),
                         lower_rad=np.array(lower), upper_rad=np.array(upper), links=links, payload=pl, plant=plant,
                         flange_frame=flange or joints[-1].frame_on_child().name(), digest=digest,
                         instance_name=plant.GetModelInstanceName(instance), notes=notes)


# A CAD export's base frame off joint 1's axis, and a flange frame off joint
# 6's, by up to this much are absorbed (the robot file's base put on the axis,
# its flange's z along it) and said; beyond, the URDF is refused naming the
# joint and its line.  5 mm / 1 deg: what a model placed by hand in CAD is
# off by; more is a different design, not a rounding.
ABSORB_MM, ABSORB_DEG = 5.0, 1.0


def _plant(path, text, X_base=None):
    """Drake's plant of the URDF's text, its root welded to the world (at
    ``X_base``, 4x4, when given: the robot file's base frame)."""
    from pydrake.math import RigidTransform

    plant = MultibodyPlant(0.0)
    try:
        (instance,) = Parser(plant).AddModelsFromString(text, "urdf")
        roots = _root_links(text)
        if roots and roots[0] != "world":
            X = RigidTransform() if X_base is None else RigidTransform(X_base)
            plant.WeldFrames(plant.world_frame(), plant.GetFrameByName(roots[0], instance), X)
        plant.Finalize()
    except RuntimeError as e:
        _fail(path, "Drake's URDF parser: " + " ".join(str(e).split())[:300])
    return plant, instance


def _turn_onto(a, b):
    """The smallest rotation (3x3) that turns unit vector a onto b."""
    v, c = np.cross(a, b), float(np.dot(a, b))
    if np.linalg.norm(v) < 1e-15:
        return np.eye(3)
    K = np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])
    return np.eye(3) + K + K @ K / (1.0 + c)


def _base_correction(path, text, plant, joint1, notes):
    """None when joint 1's axis is the base's z axis (or one a DH base row
    reaches); else the transform (4x4) of the base frame onto it, when it is
    within ABSORB_MM / ABSORB_DEG (said in ``notes``); else an InputError
    naming joint 1 and its line."""
    ctx = plant.CreateDefaultContext()
    X = plant.CalcRelativeTransform(ctx, plant.world_frame(), joint1.frame_on_child())
    p, z = X.translation(), X.rotation().matrix() @ joint1.revolute_axis()
    z = z / np.linalg.norm(z)
    tilt = float(np.degrees(np.arccos(min(1.0, abs(z[2])))))
    off = p - z * np.dot(p, z)  # the axis' nearest point to the origin
    if tilt < 1e-7 and np.hypot(*off[:2]) < 1e-9:
        return None
    if abs(z[0]) < 1e-9:  # an axis at right angles to the base x axis that meets it: a modified DH base row
        k = -p[1] / z[1] if abs(z[1]) > 1e-9 else -p[2] / z[2]
        hit = p + k * z
        if abs(hit[1]) < 1e-9 and abs(hit[2]) < 1e-9:
            return None
    ez = np.array([0.0, 0.0, 1.0 if z[2] >= 0 else -1.0])
    R = _turn_onto(z, ez)
    q = R @ p
    t = -np.array([q[0], q[1], 0.0])
    shift_mm = float(np.hypot(t[0], t[1]) * 1e3)
    where = _joint_line(path, joint1.name())
    if tilt > ABSORB_DEG or shift_mm > ABSORB_MM:
        _fail(path, f"joint 1 ('{joint1.name()}'{where}) turns about an axis {shift_mm:.3g} mm from the base frame's "
                    f"origin and {tilt:.3g} deg from its z axis, more than a CAD export's offset ({ABSORB_MM:g} mm, "
                    f"{ABSORB_DEG:g} deg): a robot file's base frame has z along joint 1's axis; change that joint's "
                    "<origin xyz=... rpy=...> (or the base link's) to put the axis there")
    notes.append(f"joint 1's axis ('{joint1.name()}'{where}) is {shift_mm:.3g} mm from the URDF's base frame origin "
                 f"(x {-t[0] * 1e3:+.3g}, y {-t[1] * 1e3:+.3g} mm) and {tilt:.3g} deg from its z axis: the robot "
                 "file's base frame is on the axis; positions in the URDF's base frame differ by this offset")
    out = np.eye(4)
    out[:3, :3], out[:3, 3] = R, t
    return out


def _flange_convention(R, z6, flange, notes):
    """The flange frame with its z axis out of the flange: ROS-Industrial's
    KUKA URDFs put tool0's x axis along joint 6 (KUKA's own flange frame);
    that frame is read turned (z = its x, x = -its z) and said in ``notes``."""
    z6 = np.asarray(z6, dtype=float) / np.linalg.norm(z6)
    if flange is None or abs(np.dot(R[:, 0], z6)) < np.cos(np.radians(ABSORB_DEG)) or \
            abs(np.dot(R[:, 2], z6)) > np.sin(np.radians(ABSORB_DEG)):
        return R
    M = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])  # columns: -z, y, x of the frame
    notes.append(f"the flange frame '{flange}' has its x axis along joint 6 (the KUKA convention of ROS-Industrial's "
                 "URDFs): the robot file's flange frame has z along it (z = its x, x = minus its z)")
    return R @ M


def _snap_flange(R, z6):
    """(the flange frame turned so its z axis is along joint 6's, the angle
    in deg) when it is within ABSORB_DEG of it; None otherwise."""
    z6 = np.asarray(z6, dtype=float) / np.linalg.norm(z6)
    zf = R[:, 2]
    target = z6 if np.dot(zf, z6) >= 0 else -z6
    angle = float(np.degrees(np.arccos(min(1.0, abs(np.dot(zf, z6))))))
    if angle > ABSORB_DEG or angle < 1e-12:
        return None
    return _turn_onto(zf, target) @ R, angle


def _joint_line(path, name):
    """', line N' of a joint's element in the URDF file, or ''."""
    try:
        text = Path(path).read_text(encoding="utf-8", errors="replace")
    except OSError:
        return ""
    for n, line in enumerate(text.splitlines(), start=1):
        if re.search(rf'<joint\s+name\s*=\s*["\']{re.escape(name)}["\']', line):
            return f", line {n}"
    return ""


def _plain(error, path, joints, flange):
    """dh_from_axes' reason, said of the URDF: which joint and what to change."""
    msg = str(error)
    m = re.search(r"joint (\d)'s axis", msg)
    if "flange" in msg:
        return (f"the flange frame '{flange or joints[-1].name()}' cannot be a robot file's flange: {msg}; its z axis "
                "(or, as ROS-Industrial's KUKA URDFs, its x axis) must run along joint 6's axis: change the "
                f"<origin rpy=...> of the joint that places '{flange or 'the flange'}'")
    if m:
        j = joints[int(m.group(1)) - 1]
        return (f"joint {m.group(1)} ('{j.name()}'{_joint_line(path, j.name())}): {msg}; change its <origin> or "
                "<axis> (a robot file's kinematics are Denavit-Hartenberg rows: each axis at a right angle to the "
                "common normal from the one before, or parallel to it)")
    return msg


def _root_links(text):
    """The URDF's links that are no joint's child (its roots), in order."""
    root = ET.fromstring(text)
    children = {j.find("child").get("link") for j in root.iter("joint") if j.find("child") is not None}
    return [link.get("name") for link in root.iter("link") if link.get("name") not in children]


def _composite(items, X_WL, name):
    """LinkInertia of rigid parts ((mass, com_W, I_cm_W, name), world frame)
    in the frame X_WL (4x4)."""
    m = sum(it[0] for it in items)
    com_W = sum(it[0] * it[1] for it in items) / m
    I_W = np.zeros((3, 3))
    for mi, ci, Ii, _ in items:
        r = ci - com_W
        I_W += Ii + mi * (np.dot(r, r) * np.eye(3) - np.outer(r, r))
    R, p = X_WL[:3, :3], X_WL[:3, 3]
    return LinkInertia(name, float(m), R.T @ (com_W - p), R.T @ I_W @ R)


def _clean_name(text):
    name = re.sub(r"[^A-Za-z0-9_]", "_", str(text))
    if not name or not name[0].isalpha():
        name = "robot_" + name
    return name


def _link_name(members, i):
    heaviest = max(members, key=lambda it: it[0])[3]
    name = _clean_name(heaviest)
    return name if NAME_RE.fullmatch(name) and name not in ("flange", PAYLOAD_BODY) else f"link_{i}"


def box_of(mass, inertia):
    """Sides (m) of the solid box with the principal moments of ``inertia``
    (a stand-in shape for a link known by its inertia only)."""
    w = np.linalg.eigvalsh(inertia)
    s = np.array([w[1] + w[2] - w[0], w[0] + w[2] - w[1], w[0] + w[1] - w[2]]) * 6.0 / mass
    return np.sqrt(np.maximum(s, 1e-6))
