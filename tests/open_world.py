"""Stiffness campaigns with effects that `robstiff diagnose` does not name,
made by Drake with the effect built into the robot's physics.

Nothing here comes from the diagnosis's candidates or dictionary
(robstiff_drake/identification/{candidates,dictionary,terms}.py) nor from
the package's own kinematics: the IRB6400 is Drake's MultibodyPlant parsed
from models/ (the same URDF as `robstiff_drake.plant`), and

  * the load is a 700 N force at the spindle's tool point (0, 0, 350) mm on
    the flange, turned into joint torques by Drake
    (MultibodyPlant.CalcGeneralizedForces of a spatial force on the flange);
  * each joint is a spring between the commanded (motor-side) angle and the
    link; the generator's own torque-deflection law gives the deflection,
    and the static equilibrium  law(q - q_cmd) = tau_load(q)  is solved by
    fixed-point iteration at the loaded configuration (so the geometric
    stiffness of the load, at its physical factor 1, is in it);
  * the displacement is Drake's forward kinematics of the measured point,
    loaded minus unloaded, plus Gaussian CMM noise (0.01 mm per component).

Gravity is off: the campaign measures the change under the applied load; a
real robot's gravity preload would hide a joint's lost motion wherever the
load does not reverse the joint's torque (one reason the lost-motion case is
in the wrist, where the spindle hangs nearly below the joint).

Effects (each sized so that the part of its displacement the six springs
cannot absorb, computed here by a least-squares fit of Drake's spring
columns, has an RMS drawn in 2-5x the noise; the parameter that gives it is
reported with its physical range):

  none           the six springs only (nominal stiffness of models/irb6400.yaml)
  base           the base tilts on its foundation: two extra revolute joints
                 at the floor (x and y axes) with torsional springs k_f
  wrist_lost_motion  joint 5 with a two-slope torsion curve: soft up to a
                 knee torque (+-3 % of a rated 1300 N*m, 40 N*m), then the
                 nominal stiffness; the lost motion b is the extra angle at the knee
  frame          displacements measured in a frame turned by 1-5 deg
                 (mostly about the vertical) against the base
  hysteresis     joint 1 with a play of +-w held by friction: each load that
                 exceeds 20 N*m pushes the link to the side of its torque and
                 it stays there; the pose's unloaded reference is read before
                 its first load, so it keeps the side of the last load before
  outliers       the six springs, and 4 of the rows with a gross reading
                 error of 0.1-0.4 mm (a slipped probe, a mistyped digit)
  angle_j3       joint 3 driven through a parallel rod: its compliance is the
                 reducer's plus the rod's, c_rod / cos^2(q3 - q_ref); the rod
                 share is sized
  point_offset   the measured point (a tracker target on the spindle housing)
                 is 10-150 mm away from the loaded point at the cutter
and tests/open_world_loads.py's: load_history, periodic_drift, crosstalk,
preload, drift_no_seq.
"""

from dataclasses import dataclass

import numpy as np
from pydrake.math import RigidTransform
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import RevoluteJoint, SpatialInertia, UnitInertia

from robstiff_drake.diagrams.tracker_world import FlangeQueries
from robstiff_drake.identification.stiffness.campaign import StiffnessCampaign, tool_header_line
from robstiff_drake.model.robot import load_robot
from robstiff_drake.plant import JOINT_NAMES, robot_urdf

NOISE_MM = 0.01
# Loads: 700 N.  At 300 N the foundation and the rod drive of the cases below
# would stay under twice the noise at any physical size; at 1000 N the
# geometric stiffness of the load (the CCT term at its physical factor 1,
# which the equilibrium below contains) would itself reach 0.004 mm RMS
# beyond the six springs, 0.4x the noise; at 700 N it is 0.002 mm.
FORCE_N = 700.0
TOOL_M = np.array([0.0, 0.0, 0.35])
N_ROWS, LOADS_PER_POSE = 120, 4
# tests/open_world_loads.py: the loads' history, the clock, the force sensor, the loads' size
LOAD_KINDS = ("load_history", "periodic_drift", "crosstalk", "preload", "drift_no_seq")
KINDS = ("none", "base", "wrist_lost_motion", "frame", "hysteresis", "outliers", "angle_j3", "point_offset") + LOAD_KINDS
OUT_OF_LIBRARY = KINDS[1:]

# Physical ranges of the effects' parameters (what each case reports against).
# Each lies inside the diagnosis's plausibility bound
# (robstiff_drake/identification/diagnosis/plausibility.py), which is the limit of what
# is physically possible, judged at the estimate: an effect planted at the
# limit itself would be estimated beyond it half the time.
# Foundation tilt stiffness: 1.5e7-3e8 N*m/rad (bolted plate on concrete
# ~1.5e8, a 1 m footing ~5e7, a steel riser softer; 1.5e7 rocks a 2 t robot
# at 11 Hz, just above the 10 Hz of the bound's 1e7).
BASE_K_RANGE = (1.5e7, 3e8)
LOST_MOTION_RANGE_RAD = (10e-6, 870e-6)  # 10 urad to 3 arc-min (strain-wave wrist gears: 1-3 arc-min)
KNEE_TORQUE_NM = 40.0  # +-3 % of an assumed 1300 N*m rated torque of the axis-5 gear
FRAME_RANGE_DEG = (1.0, 5.0)  # a frame from the cell drawings a few degrees off (bound 5.7 deg)
HYSTERESIS_RANGE_RAD = (10e-6, 300e-6)
FRICTION_NM = 20.0
OUTLIER_RANGE_MM = (0.1, 0.4)
N_OUTLIERS = 4
ROD_SHARE_RANGE = (0.02, 0.6)  # rod's share of joint 3's compliance at q_ref
POINT_OFFSET_DIR = np.array([0.6, 0.0, -0.8])  # target on the spindle housing: out from the axis, up from the cutter
# a target on the spindle's nose while the load acts at the cutter: the holder's gauge length and the tool's
# stick-out, 10-150 mm (bound 200 mm)
POINT_OFFSET_RANGE_M = (0.01, 0.15)


class DrakeRobot(FlangeQueries):
    """The IRB6400 in Drake, optionally on a compliant base (two extra
    revolute joints at the floor)."""

    def __init__(self, robot, compliant_base=False):
        self.plant = plant = MultibodyPlant(time_step=0.0)
        (instance,) = Parser(plant).AddModels(str(robot_urdf(robot)))
        base = plant.GetFrameByName(robot.links[0].name, instance)
        if compliant_base:
            inertia = SpatialInertia(1.0, np.zeros(3), UnitInertia(0.01, 0.01, 0.01))
            bx = plant.AddRigidBody("tilt_x", instance, inertia)
            by = plant.AddRigidBody("tilt_y", instance, inertia)
            plant.AddJoint(RevoluteJoint("floor_x", plant.world_frame(), bx.body_frame(), [1.0, 0.0, 0.0]))
            plant.AddJoint(RevoluteJoint("floor_y", bx.body_frame(), by.body_frame(), [0.0, 1.0, 0.0]))
            plant.WeldFrames(by.body_frame(), base, RigidTransform())
        else:
            plant.WeldFrames(plant.world_frame(), base, RigidTransform())
        plant.Finalize()
        self.base_joints = [plant.GetJointByName(n).position_start() for n in ("floor_x", "floor_y")] \
            if compliant_base else []
        self.context = plant.CreateDefaultContext()
        self.arm = [plant.GetJointByName(n).position_start() for n in JOINT_NAMES]
        self.flange = plant.GetBodyByName("flange")
        self.nq = plant.num_positions()

    def full_q(self, q_arm, q_base=(0.0, 0.0)):
        q = np.zeros(self.nq)
        q[self.arm] = q_arm
        if self.base_joints:
            q[self.base_joints] = q_base
        return q

    def load_torques(self, q, force_N, p_flange=TOOL_M):
        """Generalized forces (nq,) of a force (world frame) at a flange point (m), by Drake."""
        return super().load_torques(q, force_N, p_flange)


@dataclass
class Physics:
    """The generator's own joint and base laws: deflection (rad) of a joint
    under torque tau (N*m); ``state`` carries a hysteretic joint's side."""

    k_Nm_per_rad: np.ndarray
    base_k_Nm_per_rad: float = None
    lost_motion: tuple = None  # (joint index, b rad, knee N*m)
    hysteresis: tuple = None  # (joint index, w rad)
    rod: tuple = None  # (joint index, share, q_ref rad)

    def deflection(self, j, tau, q_cmd, side=0.0):
        k = self.k_Nm_per_rad[j]
        if self.lost_motion and self.lost_motion[0] == j:
            _, b, knee = self.lost_motion
            soft = b / knee + 1.0 / k  # compliance below the knee
            if abs(tau) <= knee:
                return tau * soft
            return np.sign(tau) * knee * soft + (tau - np.sign(tau) * knee) / k
        if self.rod and self.rod[0] == j:
            _, share, q_ref = self.rod
            c = 1.0 / k
            return tau * (c * (1 - share) + c * share / np.cos(q_cmd[j] - q_ref) ** 2)
        if self.hysteresis and self.hysteresis[0] == j:
            return tau / k + self.hysteresis[1] * side
        return tau / k


def equilibrium(robot, physics, q_cmd, force_N, sides=None, iterations=8):
    """Loaded configuration (full q) of the arm commanded to q_cmd under the
    force at the tool point: the fixed point of q = q_cmd + law^-1(tau(q))."""
    sides = np.zeros(6) if sides is None else sides
    q = robot.full_q(q_cmd)
    for _ in range(iterations):
        tau = robot.load_torques(q, force_N)
        q_new = robot.full_q(q_cmd + np.array([physics.deflection(j, tau[robot.arm[j]], q_cmd, sides[j])
                                                for j in range(6)]))
        if robot.base_joints:
            q_new[robot.base_joints] = tau[robot.base_joints] / physics.base_k_Nm_per_rad
        if np.max(np.abs(q_new - q)) < 1e-13:
            q = q_new
            break
        q = q_new
    return q


def sample_poses(robot, rng, n_poses):
    """Joint angles (rad) of machining-like poses: the tool point in front of
    the robot (x 0.9-2.2 m, z 0.2-1.6 m), the wrist away from its singularity."""
    out = []
    while len(out) < n_poses:
        q = np.deg2rad([rng.uniform(-30, 30), rng.uniform(-5, 45), rng.uniform(-20, 40),
                        rng.uniform(-120, 120), rng.choice([-1, 1]) * rng.uniform(30, 100), rng.uniform(-180, 180)])
        p = robot.point(robot.full_q(q), TOOL_M)
        if 0.9 <= p[0] <= 2.2 and 0.2 <= p[2] <= 1.6:
            out.append(q)
    return np.array(out)


def spring_columns(robot, q_cmd, force_N, k):
    """The six springs' columns (3N, 6) by Drake: J_v(q) e_j tau_j / k_j."""
    cols = np.zeros((len(q_cmd), 3, 6))
    h = 1e-7
    for i, (q, F) in enumerate(zip(q_cmd, force_N)):
        qf = robot.full_q(q)
        tau = robot.load_torques(qf, F)[robot.arm]
        p0 = robot.point(qf, TOOL_M)
        for j in range(6):
            dq = np.zeros(robot.nq)
            dq[robot.arm[j]] = h
            cols[i, :, j] = (robot.point(qf + dq, TOOL_M) - p0) / h * tau[j] / k[j]
    return cols.reshape(-1, 6)


def visible_rms(extra, cols):
    """RMS (m) of the part of a displacement set the six springs cannot absorb."""
    y = extra.reshape(-1)
    keep = np.linalg.norm(cols, axis=0) > 1e-12 * np.linalg.norm(cols, axis=0).max()
    coef, *_ = np.linalg.lstsq(cols[:, keep], y, rcond=None)
    return float(np.sqrt(np.mean((y - cols[:, keep] @ coef) ** 2)))


def displacements(robot, physics, q_cmd, force_N, pose_idx, measured_point=TOOL_M):
    """Noise-free displacements (N, 3) m, loaded minus the pose's unloaded
    reading, rows in measurement order (a hysteretic joint's side carried on)."""
    out = np.zeros((len(q_cmd), 3))
    sides = np.zeros(6)
    ref_point, last_pose = None, None
    hyst = physics.hysteresis[0] if physics.hysteresis else None
    for i, (q, F) in enumerate(zip(q_cmd, force_N)):
        if pose_idx[i] != last_pose:  # a new pose: read the unloaded reference
            q_ref = robot.full_q(q)
            if hyst is not None:
                q_ref[robot.arm[hyst]] += physics.hysteresis[1] * sides[hyst]
            ref_point = robot.point(q_ref, measured_point)
            last_pose = pose_idx[i]
        if hyst is not None:
            tau = robot.load_torques(robot.full_q(q), F)[robot.arm[hyst]]
            if abs(tau) > FRICTION_NM:
                sides[hyst] = np.sign(tau)
        q_load = equilibrium(robot, physics, q, F, sides)
        out[i] = robot.point(q_load, measured_point) - ref_point
    return out


@dataclass
class OpenWorldCampaign:
    kind: str
    campaign: StiffnessCampaign
    params: dict  # the effect's parameters, SI, with its physical range
    visible_mm: float  # RMS of the effect's part the six springs cannot absorb
    target_mm: float
    outlier_rows: list
    comments: list


def _solve_size(make, target, p0, lo, hi):
    """Parameter p in [lo, hi] whose visible RMS is ``target`` (secant on logs); (p, size)."""
    p, s = p0, make(p0)
    for _ in range(6):
        if s <= 0:
            break
        p_new = float(np.clip(p * target / s, lo, hi))
        if abs(p_new / p - 1) < 0.02:
            p = p_new
            break
        p = p_new
        s = make(p)
    return p, make(p)


def make_campaign(kind, seed, *, n=N_ROWS, loads_per_pose=LOADS_PER_POSE, noise_mm=NOISE_MM, size_range=(2.0, 5.0),
                  repeats=1, shared_reference=False):
    """One campaign of ``kind`` (see the module docstring); with ``repeats``
    > 1 each load is read that many times in a row (replicate rows: same
    pose and load, independent noise).  The noise is ``noise_mm`` per
    displacement component; with ``shared_reference`` it is the loaded
    reading's noise minus the pose's one unloaded reading's (each
    noise_mm / sqrt(2)), so the rows of a pose share part of it."""
    if kind not in KINDS:
        raise ValueError(f"unknown kind {kind}")
    if kind in LOAD_KINDS:
        from open_world_loads import make_load_campaign

        if repeats != 1 or shared_reference:
            raise ValueError(f"{kind}: one reading per load, independent noise")
        return make_load_campaign(kind, seed, n=n, loads_per_pose=loads_per_pose, noise_mm=noise_mm,
                                  size_range=size_range)
    rng = np.random.default_rng(seed)
    model = load_robot()
    k = np.asarray(model.joint_stiffness_Nm_per_rad, dtype=float)
    plain = DrakeRobot(model)
    n_poses = int(np.ceil(n / loads_per_pose))
    poses = sample_poses(plain, rng, n_poses)
    pose_idx = np.repeat(np.arange(n_poses), loads_per_pose)[:n]
    q_cmd = poses[pose_idx]
    dirs = np.repeat(rng.normal(size=(-(-n // repeats), 3)), repeats, axis=0)[:n]
    force = dirs / np.linalg.norm(dirs, axis=1, keepdims=True) * FORCE_N
    target = float(rng.uniform(*size_range)) * noise_mm * 1e-3
    d0 = displacements(plain, Physics(k), q_cmd, force, pose_idx)
    cols = spring_columns(plain, q_cmd, force, k)
    params, outlier_rows, d = {}, [], d0
    if kind == "base":
        robot = DrakeRobot(model, compliant_base=True)

        def make(kf):
            return displacements(robot, Physics(k, base_k_Nm_per_rad=kf), q_cmd, force, pose_idx)
        kf, _ = _solve_size(lambda c: visible_rms(make(1.0 / c) - d0, cols), target, 1e-8, 1.0 / BASE_K_RANGE[1],
                            1.0 / BASE_K_RANGE[0])
        kf = 1.0 / kf
        d = make(kf)
        params = {"foundation_tilt_stiffness_Nm_per_rad": kf, "range": BASE_K_RANGE}
    elif kind == "wrist_lost_motion":
        def make(b):
            return displacements(plain, Physics(k, lost_motion=(4, b, KNEE_TORQUE_NM)), q_cmd, force, pose_idx)
        b, _ = _solve_size(lambda b: visible_rms(make(b) - d0, cols), target, 50e-6, *LOST_MOTION_RANGE_RAD)
        d = make(b)
        params = {"joint": 5, "lost_motion_rad": b, "knee_torque_Nm": KNEE_TORQUE_NM, "range": LOST_MOTION_RANGE_RAD}
    elif kind == "frame":
        axis = np.array([rng.normal(0, 0.3), rng.normal(0, 0.3), 1.0])
        axis /= np.linalg.norm(axis)
        K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])

        def make(a):
            R = np.eye(3) + np.sin(a) * K + (1 - np.cos(a)) * K @ K  # measuring frame turned by R
            return d0 @ R  # components in the turned frame: R^T d
        a, _ = _solve_size(lambda a: visible_rms(make(a) - d0, cols), target, np.deg2rad(3),
                           *np.deg2rad(FRAME_RANGE_DEG))
        d = make(a)
        params = {"angle_deg": np.rad2deg(a), "axis": axis.tolist(), "range_deg": FRAME_RANGE_DEG}
    elif kind == "hysteresis":
        def make(w):
            return displacements(plain, Physics(k, hysteresis=(0, w)), q_cmd, force, pose_idx)
        w, _ = _solve_size(lambda w: visible_rms(make(w) - d0, cols), target, 30e-6, *HYSTERESIS_RANGE_RAD)
        d = make(w)
        params = {"joint": 1, "play_half_width_rad": w, "friction_Nm": FRICTION_NM, "range": HYSTERESIS_RANGE_RAD}
    elif kind == "angle_j3":
        q_ref = float(np.mean(q_cmd[:, 2]))

        def make(share):
            return displacements(plain, Physics(k, rod=(2, share, q_ref)), q_cmd, force, pose_idx)
        share, _ = _solve_size(lambda s: visible_rms(make(s) - d0, cols), target, 0.2, *ROD_SHARE_RANGE)
        d = make(share)
        params = {"joint": 3, "rod_share": share, "q_ref_deg": np.rad2deg(q_ref), "range": ROD_SHARE_RANGE}
    elif kind == "point_offset":
        def make(r):
            return displacements(plain, Physics(k), q_cmd, force, pose_idx,
                                 measured_point=TOOL_M + r * POINT_OFFSET_DIR)
        r, _ = _solve_size(lambda r: visible_rms(make(r) - d0, cols), target, 0.05, *POINT_OFFSET_RANGE_M)
        d = make(r)
        params = {"offset_m": (r * POINT_OFFSET_DIR).tolist(), "range_m": POINT_OFFSET_RANGE_M}
    visible = visible_rms(d - d0, cols) if kind not in ("none", "outliers") else 0.0
    if shared_reference:
        reference = rng.normal(scale=noise_mm / np.sqrt(2), size=(n_poses, 3))[pose_idx]
        disp_mm = d * 1e3 + rng.normal(scale=noise_mm / np.sqrt(2), size=d.shape) - reference
    else:
        disp_mm = d * 1e3 + rng.normal(scale=noise_mm, size=d.shape)
    if kind == "outliers":
        outlier_rows = sorted(rng.choice(n, N_OUTLIERS, replace=False).tolist())
        for r in outlier_rows:
            v = rng.normal(size=3)
            disp_mm[r] += v / np.linalg.norm(v) * rng.uniform(*OUTLIER_RANGE_MM)
        params = {"rows": outlier_rows}
        target = float("nan")
    if kind == "none":
        target = float("nan")
    pose = [f"P{i + 1:03d}" for i in pose_idx]
    comments = [
        "Stiffness campaign made by tests/open_world.py (Drake MultibodyPlant of models/irb6400, effect built into "
        "the physics; see that file's docstring).",
        f"Effect: {kind}; parameters {params}; RMS beyond the six springs {visible * 1e3:.4f} mm; seed {seed}.",
        f"Loads: {FORCE_N:g} N at the tool point {TOOL_M * 1e3} mm (flange frame), random directions, "
        f"{loads_per_pose} per pose" + (f" (each load read {repeats} times)" if repeats > 1 else "")
        + f"; CMM noise {noise_mm} mm per component"
        + (" (loaded minus the pose's one unloaded reading, each noise/sqrt(2))." if shared_reference else "."),
    ]
    lines = np.arange(n) + 1 + len(comments) + 2  # file lines when written by to_csv (comments, tool line, header)
    camp = StiffnessCampaign("open_world", model.controller_deg(q_cmd), force, np.zeros((n, 3)), disp_mm, None, pose,
                             np.arange(1, n + 1, dtype=float), lines, comments, False, tool_mm=TOOL_M * 1e3)
    return OpenWorldCampaign(kind, camp, params, visible * 1e3, target * 1e3, outlier_rows, comments)


def to_csv(c):
    """CSV text of an OpenWorldCampaign (comment lines first, then the header)."""
    cp = c.campaign
    out = [f"# {line}" for line in c.comments] + [tool_header_line(TOOL_M),
                                                   "pose," + ("seq," if cp.seq is not None else "")
                                                   + "q1,q2,q3,q4,q5,q6,fx,fy,fz,dx,dy,dz"]
    for i in range(len(cp)):
        row = [cp.pose[i]] + ([str(int(cp.seq[i]))] if cp.seq is not None else []) + \
              [f"{v:.9g}" for v in cp.q_deg[i]] + [f"{v:.9g}" for v in cp.force_N[i]] + \
              [f"{v:.9g}" for v in cp.disp_mm[i]]
        out.append(",".join(row))
    return "\n".join(out) + "\n"


if __name__ == "__main__":  # python3 tests/open_world.py KIND SEED OUT.csv
    import sys

    kind, seed, out = sys.argv[1], int(sys.argv[2]), sys.argv[3]
    c = make_campaign(kind, seed)
    with open(out, "x") as f:  # never overwrites
        f.write(to_csv(c))
    print(f"{out}: {kind}, {c.visible_mm:.4f} mm RMS beyond the six springs; {c.params}")
