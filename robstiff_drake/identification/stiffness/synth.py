"""Virtual measurement campaigns made from the model, for tests, demos and
for planning real campaigns.  Plain numpy; no Drake.

A stiffness campaign: poses with the tool point in a workspace box (spindle
axis within a tilt cone of straight down, random yaw), several loads of a
given magnitude in random directions per pose, CMM noise, and optionally
named effects from ``model.effects`` switched on.  A payload campaign: static
configurations with the wrist turned in many directions, the sensor's
reading of the payload's weight, bias and noise.

Every file written says in its comment lines how it was made.
"""

import shlex
import sys
from dataclasses import dataclass

import numpy as np

from robstiff_drake.identification.stiffness.campaign import tool_header_line
from robstiff_drake.identification.stiffness.payload import gravity_in_sensor
from robstiff_drake.model import effects as fx
from robstiff_drake.model import ik


def random_unit_vectors(rng, n):
    v = rng.normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def tilted_down_pose(p_m, yaw_rad, tilt_rad, tilt_dir_rad):
    """Tool frame at p with its z axis tilted by ``tilt_rad`` from straight down."""
    T = ik.tool_down_pose(p_m, yaw_rad)
    axis = np.array([np.cos(tilt_dir_rad), np.sin(tilt_dir_rad), 0.0])
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    R = np.eye(3) + np.sin(tilt_rad) * K + (1 - np.cos(tilt_rad)) * K @ K
    T[:3, :3] = R @ T[:3, :3]
    return T


def sample_poses(robot, n_poses, rng, tool_m, box=None, max_tilt_deg=25.0, max_yaw_deg=90.0):
    """n_poses configurations (rad) with the tool point in ``box`` (default:
    the robot's machining workspace), within the joint limits."""
    ws = robot.workspace
    box = box or (ws.x_m, ws.y_m, ws.z_m)
    qs = []
    tries = 0
    while len(qs) < n_poses:
        tries += 1
        if tries > 200 * n_poses:
            raise ValueError("could not find reachable poses in the workspace box")
        p = np.array([rng.uniform(*b) for b in box])
        T = tilted_down_pose(p, np.deg2rad(rng.uniform(-max_yaw_deg, max_yaw_deg)),
                             np.deg2rad(rng.uniform(0, max_tilt_deg)), rng.uniform(0, 2 * np.pi))
        try:
            qs.append(ik.solve_for(robot, T, tool_m))
        except ik.IKError:
            continue
    return np.array(qs)


@dataclass
class SynthStiffness:
    q_deg: np.ndarray  # controller convention (as a measurement file holds them)
    force_N: np.ndarray
    disp_mm: np.ndarray
    pose: list
    seq: np.ndarray
    effects: dict  # name -> params (SI)
    effect_rms_mm: dict  # name -> (RMS of the effect, RMS of its part the conventional model cannot absorb), mm
    true_stiffness_Nm_per_rad: np.ndarray
    tool_m: np.ndarray = None  # the tool point the displacements are measured at (flange frame, m)

    def to_campaign(self, path="synthetic"):
        """The campaign as `robstiff identify` reads it from a file."""
        from robstiff_drake.identification.stiffness.campaign import StiffnessCampaign

        n = len(self.seq)
        return StiffnessCampaign(path, self.q_deg, self.force_N, np.zeros((n, 3)), self.disp_mm, None,
                                 list(self.pose), np.asarray(self.seq, dtype=float), np.arange(n) + 1, [], False,
                                 tool_mm=None if self.tool_m is None else np.asarray(self.tool_m) * 1e3)


def stiffness_campaign(robot, *, n=120, loads_per_pose=4, force_N=300.0, noise_mm=0.01, seed=0,
                       tool_m=None, effects=None, true_stiffness_Nm_per_rad=None, effect_params=None):
    """A synthetic stiffness campaign.  ``effects``: {name: rms_mm} of effects
    to switch on (each sized to that RMS displacement); ``effect_params``:
    {name: params (SI, as model/effects.py takes them)} of effects switched
    on at the given size.  ``tool_m``: the measured point (flange frame, m;
    default the flange's origin).  The joint angles come out in the robot's
    controller convention."""
    rng = np.random.default_rng(seed)
    tool = np.zeros(3) if tool_m is None else np.asarray(tool_m, dtype=float)
    k_true = robot.joint_stiffness_Nm_per_rad if true_stiffness_Nm_per_rad is None else np.asarray(
        true_stiffness_Nm_per_rad, dtype=float)
    n_poses = int(np.ceil(n / loads_per_pose))
    poses_q = sample_poses(robot, n_poses, rng, tool)
    pose_idx = np.repeat(np.arange(n_poses), loads_per_pose)[:n]
    q = poses_q[pose_idx]
    force = random_unit_vectors(rng, n) * force_N
    wrench = np.hstack([force, np.zeros((n, 3))])
    seq = np.arange(1, n + 1)
    ctx = fx.EffectContext(robot.dh, k_true, q, wrench, seq, tool)
    disp = ctx.disp_from_wrench(wrench)
    applied, sizes = {}, {}
    for name, rms_mm in (effects or {}).items():
        params, extra, (raw, visible) = fx.sized_effect(name, ctx, rms_mm * 1e-3, rng)
        applied[name] = params
        sizes[name] = (raw * 1e3, visible * 1e3)
        disp = disp + extra
    A = fx.base_regressor(ctx)
    for name, params in (effect_params or {}).items():
        extra = fx.EFFECTS[name](ctx, params)
        applied[name] = params
        sizes[name] = (float(np.sqrt(np.mean(extra**2))) * 1e3,
                       float(np.sqrt(np.mean(fx.unexplained(extra, A) ** 2))) * 1e3)
        disp = disp + extra
    disp_mm = disp * 1e3 + rng.normal(scale=noise_mm, size=(n, 3))
    return SynthStiffness(robot.controller_deg(q), force, disp_mm, [f"P{i + 1:03d}" for i in pose_idx], seq,
                          applied, sizes, k_true, tool)


@dataclass
class SynthPayload:
    q_deg: np.ndarray
    force_N: np.ndarray
    torque_Nm: np.ndarray
    mass_kg: float
    com_m: np.ndarray
    force_bias_N: np.ndarray
    torque_bias_Nm: np.ndarray


def payload_readings(dh, q_rad, mass_kg, com_m, force_bias_N, torque_bias_Nm, R_mount=None):
    """Noise-free sensor wrench (sensor frame) of a payload under gravity."""
    f = mass_kg * gravity_in_sensor(dh, q_rad, R_mount)
    return f + force_bias_N, np.cross(com_m, f) + torque_bias_Nm


def payload_campaign(robot, *, n=15, mass_kg=None, com_m=None, noise_N=1.0, noise_Nm=0.1, seed=0):
    """Static configurations with the wrist turned widely (the paper used 15):
    arm joints 2 and 3 at 10 and 20 deg (controller convention; moved just
    inside the working range where that is outside it), joint 1 within
    +-29 deg, the wrist joints spread over their ranges."""
    rng = np.random.default_rng(seed)
    m = robot.payload.mass_kg if mass_kg is None else mass_kg
    c = robot.payload.com_m if com_m is None else np.asarray(com_m, dtype=float)
    lo, hi = robot.q_lower_rad, robot.q_upper_rad
    margin = np.deg2rad(1.0)
    base = np.clip(np.deg2rad([0.0, 10.0, 20.0, 0.0, 0.0, 0.0]), lo + margin, hi - margin)
    q = np.tile(base, (n, 1))
    q[:, 0] = rng.uniform(-0.5, 0.5, n)
    q[:, 3] = rng.uniform(-np.pi, np.pi, n)
    q[:, 4] = rng.uniform(max(lo[4], -2.0), min(hi[4], 2.0), n)
    q[:, 5] = rng.uniform(-np.pi, np.pi, n)
    bf = rng.normal(scale=5.0, size=3)
    bm = rng.normal(scale=0.5, size=3)
    f, t = payload_readings(robot.dh, robot.joint_map.to_model(q), m, c, bf, bm)
    f = f + rng.normal(scale=noise_N, size=f.shape)
    t = t + rng.normal(scale=noise_Nm, size=t.shape)
    return SynthPayload(np.rad2deg(q), f, t, m, c, bf, bm)


def _fmt(v):
    return f"{v:.6f}".rstrip("0").rstrip(".") if abs(v) >= 1e-3 else f"{v:.6g}"


def command_line():
    return "robstiff " + " ".join(shlex.quote(a) for a in sys.argv[1:])


def _robot_file_text(robot):
    """The robot file as the header names it: a library robot by its library name (this machine's install path
    means nothing to the file's reader), a user's file by its path."""
    from pathlib import Path

    from robstiff_drake.paths import MODELS_DIR

    src = Path(robot.source)
    return f"the library's {src.name}" if src.parent.resolve() == MODELS_DIR.resolve() else str(src)


def stiffness_csv(c, *, robot, noise_mm, seed, force_N, tool_m, how=None):
    """CSV text of a SynthStiffness, with comment lines saying how it was made."""
    lines = [
        "# Synthetic stiffness campaign made by robstiff-drake (robstiff_drake/identification/stiffness/synth.py).",
        f"# Made with: {how or command_line()}",
        f"# Robot model: {_robot_file_text(robot)} ({robot.name}; q1..q6 in its controller's convention, deg); "
        "true joint stiffness N*m/rad: " + ", ".join(f"{k:.6g}" for k in c.true_stiffness_Nm_per_rad),
        "# Poses: the tool point (the tool_mm line, flange frame) uniform in the machining workspace box, spindle "
        "axis tilted up to 25 deg from straight down, yaw within +-90 deg; IK.",
        tool_header_line(tool_m),
        f"# Loads: {force_N:g} N in uniformly random directions, {len(set(c.pose))} poses, rows grouped by 'pose'. "
        f"Displacements: conventional model dx = Jv diag(1/k) J^T F (mm), plus Gaussian CMM noise "
        f"sigma = {noise_mm:g} mm per component; random seed {seed}.",
    ]
    if noise_mm > 0:  # the instrument's noise as identify's test of the fit reads it (stiffness/lack_of_fit.py);
        lines.append(f"# noise_mm: {noise_mm:g}")  # (one line as before: the rows' file lines are unchanged)
    if c.effects:
        for name, params in c.effects.items():
            ptxt = "; ".join(f"{k} = {np.round(np.asarray(v), 12).tolist()}" for k, v in params.items())
            raw, vis = c.effect_rms_mm[name]
            lines.append(f"# Effect switched on: {name} (RMS {raw:.4f} mm; {vis:.4f} mm of it beyond what refitting "
                         f"the six joint compliances absorbs): {ptxt}")
    else:
        lines.append("# Effects switched on: none (the data follow the conventional model exactly, plus noise).")
    lines.append("pose,seq,q1,q2,q3,q4,q5,q6,fx,fy,fz,dx,dy,dz")
    for i in range(len(c.seq)):
        row = [c.pose[i], str(int(c.seq[i]))]
        row += [_fmt(v) for v in c.q_deg[i]] + [_fmt(v) for v in c.force_N[i]] + [_fmt(v) for v in c.disp_mm[i]]
        lines.append(",".join(row))
    return "\n".join(lines) + "\n"


def payload_csv(c, *, noise_N, noise_Nm, seed, how=None):
    lines = [
        "# Synthetic payload (gravity) campaign made by robstiff-drake (robstiff_drake/identification/stiffness/synth.py).",
        f"# Made with: {how or command_line()}",
        f"# Payload: mass {c.mass_kg:g} kg, centre of mass {np.round(c.com_m * 1e3, 3).tolist()} mm in the sensor "
        "frame (= DH frame 6); gravity (0, 0, -9.81) m/s^2 in the base frame.",
        f"# Sensor bias: force {np.round(c.force_bias_N, 4).tolist()} N, torque {np.round(c.torque_bias_Nm, 4).tolist()} N*m.",
        f"# Noise: Gaussian, {noise_N:g} N per force and {noise_Nm:g} N*m per torque component; random seed {seed}.",
        "# Configurations (controller convention): q1 in +-29 deg, q2 = 10, q3 = 20 deg (or just inside the working "
        "range), wrist q4, q6 in +-180 deg and q5 in +-115 deg.",
        "q1,q2,q3,q4,q5,q6,fx,fy,fz,mx,my,mz",
    ]
    for i in range(len(c.q_deg)):
        row = list(c.q_deg[i]) + list(c.force_N[i]) + list(c.torque_Nm[i])
        lines.append(",".join(_fmt(v) for v in row))
    return "\n".join(lines) + "\n"
