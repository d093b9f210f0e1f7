"""More out-of-library campaigns for tests/open_world.py, with Drake's plant
and the generator's own laws (nothing from the diagnosis): the loads'
history, the clock, the force sensor and the loads' size.

  load_history    joint 2 remembers its torque history through a friction
                  element of Dahl's law: at every reading (the unloaded one at
                  tau = 0) its state moves toward s r, s the sign of the torque's
                  change, by 1 - exp(-|change| / tau_c) of the way (r = 300 N*m,
                  tau_c = 150 N*m), and the link sits g z / k beyond the spring's
                  tau / k; the share g is sized (0.05-0.5 of the spring's).  (The
                  dictionary's play operator is a sharp-cornered law; this one is
                  smooth.)
  periodic_drift  the measuring frame moves periodically in time (a cell's
                  cooling cycling): o(t) = A sin(2 pi t / P + phi), P 5-15 min,
                  30 s per reading, each pose's unloaded reading one step
                  before its first load; |A| sized (5-35 um)
  crosstalk       the force sensor reports (I + E)^-1 of the applied force, E
                  with random entries (largest sized, 0.5-3 %)
  preload         the stiffness of joints 1-3 grows with the load's size
                  (bearings preloaded by it): k (1 + b (|F| - mean) / mean),
                  loads of 300-1100 N; b sized (0.02-0.5)
  drift_no_seq    the measuring frame drifts linearly in time (0.5-3 um per
                  reading: at most 0.45 mm over the campaign, within the drift's
                  plausible 0.5 mm) and the file has no seq column (the rows are in
                  measurement order, which the file does not say)
Sizes as open_world.py's: the RMS beyond the six springs drawn in 2-5x the
noise within each range (where the range ends first, the case is smaller).
"""

import numpy as np

import open_world as ow
from robstiff_drake.identification.stiffness.campaign import StiffnessCampaign
from robstiff_drake.model.robot import load_robot

HISTORY_JOINT, HISTORY_PLAY_NM, HISTORY_SHARE_RANGE = 1, 300.0, (0.05, 0.5)
HISTORY_DAHL_NM = 150.0
PERIOD_RANGE_S = (300.0, 900.0)
STEP_S = 30.0
# Each range lies inside the diagnosis's plausibility bound (plausibility.py; judged at the estimate, so an
# effect planted at the bound itself would be estimated beyond it half the time):
PERIODIC_AMPLITUDE_RANGE_M = (5e-6, 35e-6)  # a cell's cooling cycling: tens of micrometres (bound 50 um)
CROSSTALK_RANGE = (0.005, 0.03)  # a calibrated load cell 1-2 %, a damaged one a few % (bound 5 %)
PRELOAD_RANGE = (0.02, 0.5)
PRELOAD_FORCE_RANGE_N = (300.0, 1100.0)
# a warm-up drift of 0.1-0.5 mm over hours (the bound's reasoning): at most 0.45 mm over a campaign's 150
# readings of 30 s (bound: 5 um per reading and 0.5 mm over the campaign)
DRIFT_RANGE_M_PER_STEP = (0.5e-6, 3e-6)


class HistoryPhysics(ow.Physics):
    """The six springs, joint ``j`` with a play operator's extra deflection."""

    def __init__(self, k, share):
        super().__init__(k)
        self.share, self.z = share, 0.0

    def deflection(self, j, tau, q_cmd, side=0.0):
        base = tau / self.k_Nm_per_rad[j]
        return base + (self.share * self.z / self.k_Nm_per_rad[j] if j == HISTORY_JOINT else 0.0)


def _history_displacements(robot, k, share, q_cmd, force, pose_idx):
    phys = HistoryPhysics(k, share)
    out = np.zeros((len(q_cmd), 3))
    last_pose, ref, last_tau = None, None, 0.0

    def dahl(tau):  # the friction element's state after the torque moves from last_tau to tau
        change = tau - last_tau
        if change:
            target = np.sign(change) * HISTORY_PLAY_NM
            phys.z = float(target - (target - phys.z) * np.exp(-abs(change) / HISTORY_DAHL_NM))
        return tau

    for i, (q, F) in enumerate(zip(q_cmd, force)):
        if pose_idx[i] != last_pose:  # the unloaded reading: torque 0 moves the element's state too
            last_tau = dahl(0.0)
            ref = robot.point(ow.equilibrium(robot, phys, q, np.zeros(3)), ow.TOOL_M)
            last_pose = pose_idx[i]
        last_tau = dahl(robot.load_torques(robot.full_q(q), F)[robot.arm[HISTORY_JOINT]])
        out[i] = robot.point(ow.equilibrium(robot, phys, q, F), ow.TOOL_M) - ref
    return out


def _reference_times(pose_idx):
    """Reading times (s) of each row and of its pose's unloaded reading."""
    t = np.arange(1, len(pose_idx) + 1) * STEP_S
    first = {}
    for i, p in enumerate(pose_idx):
        first.setdefault(p, t[i] - STEP_S)
    return t, np.array([first[p] for p in pose_idx])


def make_load_campaign(kind, seed, *, n=ow.N_ROWS, loads_per_pose=ow.LOADS_PER_POSE, noise_mm=ow.NOISE_MM,
                       size_range=(2.0, 5.0)):
    rng = np.random.default_rng(seed)
    model = load_robot()
    k = np.asarray(model.joint_stiffness_Nm_per_rad, dtype=float)
    plain = ow.DrakeRobot(model)
    n_poses = int(np.ceil(n / loads_per_pose))
    poses = ow.sample_poses(plain, rng, n_poses)
    pose_idx = np.repeat(np.arange(n_poses), loads_per_pose)[:n]
    q_cmd = poses[pose_idx]
    dirs = rng.normal(size=(n, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    mags = rng.uniform(*PRELOAD_FORCE_RANGE_N, n) if kind == "preload" else np.full(n, ow.FORCE_N)
    force = dirs * mags[:, None]
    target = float(rng.uniform(*size_range)) * noise_mm * 1e-3
    d0 = ow.displacements(plain, ow.Physics(k), q_cmd, force, pose_idx)
    reported = force
    seq = np.arange(1, n + 1, dtype=float)
    if kind == "load_history":
        cols = ow.spring_columns(plain, q_cmd, force, k)

        def make(g):
            return _history_displacements(plain, k, g, q_cmd, force, pose_idx)
        g, _ = ow._solve_size(lambda g: ow.visible_rms(make(g) - d0, cols), target, 0.2, *HISTORY_SHARE_RANGE)
        d = make(g)
        params = {"joint": HISTORY_JOINT + 1, "share": g, "play_Nm": HISTORY_PLAY_NM, "range": HISTORY_SHARE_RANGE}
    elif kind in ("periodic_drift", "drift_no_seq"):
        cols = ow.spring_columns(plain, q_cmd, force, k)
        t, t_ref = _reference_times(pose_idx)
        u = rng.normal(size=3)
        u /= np.linalg.norm(u)
        if kind == "periodic_drift":
            P, phi = rng.uniform(*PERIOD_RANGE_S), rng.uniform(0, 2 * np.pi)

            def offset(a):
                return a * np.outer(np.sin(2 * np.pi * t / P + phi) - np.sin(2 * np.pi * t_ref / P + phi), u)
            lo_hi, p0 = PERIODIC_AMPLITUDE_RANGE_M, 20e-6
        else:
            def offset(v):
                return v * np.outer((t - t_ref) / STEP_S, u)
            lo_hi, p0 = DRIFT_RANGE_M_PER_STEP, 0.5e-6
        a, _ = ow._solve_size(lambda a: ow.visible_rms(offset(a), cols), target, p0, *lo_hi)
        d = d0 + offset(a)
        params = ({"amplitude_m": a, "period_s": P, "direction": u.tolist(), "range_m": lo_hi}
                  if kind == "periodic_drift" else {"m_per_reading": a, "direction": u.tolist(), "range": lo_hi})
        if kind == "drift_no_seq":
            seq = None
    elif kind == "crosstalk":
        E0 = rng.normal(size=(3, 3))
        E0 /= np.max(np.abs(E0))

        def reported_of(s):
            return force @ np.linalg.inv(np.eye(3) + s * E0).T

        def visible(s):
            return ow.visible_rms(d0, ow.spring_columns(plain, q_cmd, reported_of(s), k))
        s, _ = ow._solve_size(visible, target, 0.02, *CROSSTALK_RANGE)
        d, reported = d0, reported_of(s)
        cols = ow.spring_columns(plain, q_cmd, reported, k)
        params = {"largest_entry": s, "range": CROSSTALK_RANGE}
    elif kind == "preload":
        cols = ow.spring_columns(plain, q_cmd, force, k)
        rel = (mags - mags.mean()) / mags.mean()

        def make(b):
            out = np.zeros((n, 3))
            last, ref = None, None
            for i in range(n):
                kk = k.copy()
                kk[:3] *= 1 + b * rel[i]
                phys = ow.Physics(kk)
                if pose_idx[i] != last:
                    ref = plain.point(plain.full_q(q_cmd[i]), ow.TOOL_M)
                    last = pose_idx[i]
                out[i] = plain.point(ow.equilibrium(plain, phys, q_cmd[i], force[i]), ow.TOOL_M) - ref
            return out
        b, _ = ow._solve_size(lambda b: ow.visible_rms(make(b) - d0, cols), target, 0.2, *PRELOAD_RANGE)
        d = make(b)
        params = {"joints": [1, 2, 3], "b": b, "range": PRELOAD_RANGE}
    else:
        raise ValueError(kind)
    visible = ow.visible_rms(d - ow.displacements(plain, ow.Physics(k), q_cmd, reported, pose_idx), cols) \
        if kind == "crosstalk" else ow.visible_rms(d - d0, cols)
    disp_mm = d * 1e3 + rng.normal(scale=noise_mm, size=d.shape)
    pose = [f"P{i + 1:03d}" for i in pose_idx]
    comments = [
        "Stiffness campaign made by tests/open_world_loads.py (Drake MultibodyPlant of models/irb6400, effect built "
        "into the physics or the measurement; see that file's docstring).",
        f"Effect: {kind}; parameters {params}; RMS beyond the six springs {visible * 1e3:.4f} mm; seed {seed}.",
        f"Loads at the tool point {ow.TOOL_M * 1e3} mm (flange frame), random directions, {loads_per_pose} per pose; "
        f"CMM noise {noise_mm} mm per component.",
    ]
    lines = np.arange(n) + 1 + len(comments) + 2
    camp = StiffnessCampaign("open_world", model.controller_deg(q_cmd), reported, np.zeros((n, 3)), disp_mm, None,
                             pose, seq, lines, comments, False, tool_mm=ow.TOOL_M * 1e3)
    return ow.OpenWorldCampaign(kind, camp, params, visible * 1e3, target * 1e3, [], comments)
