"""The signals of a machining run for its residual diagnosis
(identification/runs/diagnosis.py, whose docstring describes the method):
the wrench log with gravity removed and smoothed, the arm's linear model
along the run (identification/runs/arm_response.py), and the known and loop
parts of the tool's vertical deviation.  Plain numpy and scipy."""

from dataclasses import dataclass, replace

import numpy as np
from scipy import signal

from robstiff_drake.errors import InputError
from robstiff_drake.identification.runs import arm_response
from robstiff_drake.identification.runs import settings as rs
from robstiff_drake.identification.runs.arm_response import SEGMENT_S, STEP_S, delayed
from robstiff_drake.model import kinematics as kin
from robstiff_drake.model import play_hysteresis
from robstiff_drake.model.joint_dynamics import DEFAULT_MODAL_DAMPING_RATIO
from robstiff_drake.model.payload import PayloadCalibration, payload_wrench
from robstiff_drake.model.servo import ServoParameters
from robstiff_drake.model.transmission import fallback_take_up_Nm, gap_friction_Nm, static_deflection, twist
from robstiff_drake.model.wrench_frames import sensor_to_tool_base

# ASSUMPTION: the sensor's reading is smoothed (zero phase) before it drives the arm's model, over the
# time the cutter takes to move SMOOTH_MM at the program's feed (60 mm/s: 10 Hz; 20 mm/s: 3.3 Hz; within
# SMOOTH_HZ): what the cut puts on the arm changes with the cutter's engagement, over millimetres of travel
# (the steepest change, as the cutter leaves a face, over a few), while the sensor's noise, driven through
# the model's lightly damped first mode, would leave dips of a few micrometres that the face's envelope
# (the lowest the cutter went over its whole diameter) turns into a bias.  The correction is used as
# logged: it moved the arm.
SMOOTH_MM = 6.0
SMOOTH_HZ = (2.0, 10.0)
GRID_EVERY = 5  # the fit's grid: every 5th step of the arm's response (200 Hz; nothing faster is left)
GRID_HZ = 1.0 / (GRID_EVERY * STEP_S)
# ASSUMPTION, where the run does not decide the arm's damping (``profile_damping``): 5 % on every mode
# (model/joint_dynamics.DEFAULT_MODAL_DAMPING_RATIO gives the source); a settings file does not state it.  It
# sets how long the arm rings after the path accelerates (the arm's own motion error), not the size of the
# ringing's first swing.
DAMPING_RATIO = DEFAULT_MODAL_DAMPING_RATIO

@dataclass
class RunSignals:
    """A run's signals on a common time grid, the arm's time: at t the arm is
    meant to be at the program's angles of t - the interpolator's dead time
    (SI units)."""

    t_s: np.ndarray
    q_nominal_rad: np.ndarray  # (n, 6) where the arm is meant to be: the program's angles, delayed
    correction_rad: np.ndarray  # (n, 6) the logged correction, smoothed (as the compensator sent it)
    tool_wrench: np.ndarray  # (n, 6) process load at the tool point, base frame, smoothed
    tau_Nm: np.ndarray  # (n, 6) J^T W: the process load's generalized force
    tau_static_Nm: np.ndarray  # (n, 6) the arm's weight on the gears (the controller's gravity model)
    tau_inertia_Nm: np.ndarray  # (n, 6) M q'' + c(q, q') along the program
    tau_touch_off_Nm: np.ndarray  # (6,) the weight on the gears at the first path point (touch-off)
    Jz: np.ndarray  # (n, 6) the tool's vertical Jacobian row (m/rad)
    p_nominal_m: np.ndarray  # (n, 3) the program's tool point
    compliance: np.ndarray  # (6,) the model's, rad/(N*m)
    model_dq_rad: np.ndarray  # (n, 6) the deflection the compensator's model predicts (its own law)
    dz_motion_m: np.ndarray  # (n,) the arm's own motion error along the program (known, not a cause)
    dz_loop_m: np.ndarray  # (n,) the loop's tracking error the logs predict (the plant taken as the model)
    servo: ServoParameters
    damping_ratio: float  # the gears' modal damping ratio the model used
    smooth_hz: float  # the load's smoothing
    damping: dict = None  # estimate_damping's result (None: the ratio was given)
    # (n, 6, 3) N*m per N: the generalized force of a unit force in the sensor's frame (x, y, z), about the
    # sensor origin, at the arm's pose: what a bias of the sensor's force reading adds to tau_Nm
    tau_per_sensor_force: np.ndarray = None
    # (n, 6) kg*m^2: each gear's twist inertia (its link in series with its motor), what a link crossing its
    # gear's play moves (``play_crossing_deviation``)
    twist_inertia_kgm2: np.ndarray = None


def _fill_dropouts(t, w, path):
    bad = np.isnan(w).any(axis=1)
    if bad.all():
        raise InputError(f"{path}: every reading is a dropout")
    if bad.any():
        w = w.copy()
        for j in range(w.shape[1]):
            w[bad, j] = np.interp(t[bad], t[~bad], w[~bad, j])
    return w


def _lowpass(x, rate_hz, cutoff_hz):
    """Zero-phase low-pass at ``cutoff_hz`` along axis 0 (as is when too short)."""
    if cutoff_hz >= 0.5 * rate_hz:
        return x
    b, a = signal.butter(2, cutoff_hz, fs=rate_hz)
    if x.shape[0] <= 3 * max(len(a), len(b)):
        return x
    return signal.filtfilt(b, a, x, axis=0)


def _resample(t_new, t, x):
    return np.column_stack([np.interp(t_new, t, x[:, j]) for j in range(x.shape[1])])


def servo_of(settings):
    """The robot controller's servo of a settings file (InputError when the
    file does not state it)."""
    if settings.servo is None:
        raise InputError(f"{settings.path}: compensator: no 'servo' section; diagnose-run needs the robot "
                         "controller's servo settings (" + ", ".join(rs.SERVO_KEYS) + ") to know when a "
                         "correction reaches the motor (docs/run_files.md)")
    v = settings.servo
    extra = {} if "velocity_integral_hz" not in v else {"velocity_integral_hz": v["velocity_integral_hz"]}
    return ServoParameters(position_gain_per_s=v["position_gain_per_s"],
                           velocity_bandwidth_hz=v["velocity_bandwidth_hz"],
                           velocity_feedforward=v["velocity_feedforward"],
                           interpolator_delay_s=v["interpolator_delay_ms"] / 1e3, **extra)


def smoothing_hz(files, robot):
    """The cutoff (Hz) of the load's smoothing: the program's feed (its
    tool point's speed, 90th percentile) over SMOOTH_MM, within SMOOTH_HZ."""
    jl = files.joints
    tool = np.asarray(files.settings.tool_point_mm, dtype=float) / 1e3
    p = kin.tool_position(robot.dh, robot.joint_rad(jl.q_deg) - robot.model_delta_rad(jl.correction_deg), tool)
    speed = np.linalg.norm(np.diff(p, axis=0), axis=1) / np.diff(jl.t_s)
    return float(np.clip(np.percentile(speed, 90) * 1e3 / SMOOTH_MM, *SMOOTH_HZ))


def _process_wrench(files, robot, cutoff_hz):
    """(t (s), process wrench at the tool point, base frame, smoothed at
    ``cutoff_hz``) over the joint log's span."""
    s, wl, jl = files.settings, files.wrench, files.joints
    t_j = jl.t_s
    inside = (wl.t_s >= t_j[0]) & (wl.t_s <= t_j[-1])
    if inside.sum() < 10:
        raise InputError(f"{wl.path}: fewer than 10 readings within the joint log's time span "
                         f"({t_j[0]:g}-{t_j[-1]:g} s): the two logs are not of the same cut")
    t = wl.t_s[inside]
    w = _fill_dropouts(t, wl.wrench[inside], wl.path)
    rate = 1.0 / float(np.median(np.diff(t)))
    q = _resample(t, t_j, robot.joint_rad(jl.q_deg))  # the sensor turns with the arm
    cal = PayloadCalibration(**s.payload)
    arrays = cal.arrays()
    tool = np.asarray(s.tool_point_mm, dtype=float) / 1e3
    R6 = kin.frames(robot.dh, q)[:, 6, :3, :3]
    W = np.array([sensor_to_tool_base(wk - payload_wrench(R, cal, arrays), R, tool, arrays[4])
                  for wk, R in zip(w, R6)])
    return t, _lowpass(W, rate, cutoff_hz), rate


def _segments(n, step_s):
    """(segment index of each of n steps, first step of each segment)."""
    per = max(1, int(round(SEGMENT_S / step_s)))
    seg = np.arange(n) // per
    return seg, np.arange(0, n, per)


def _arm_response(arm, ctx, damping_ratio):
    """The arm's response at ``damping_ratio`` (the gears' modal ratio):
    (its own motion along the program (n, 6), its deviation under the
    measured load, the payload's inertia taken out, and under the logged
    correction (n, 6, 2))."""
    x = ctx
    full, bare, inertia_maps, twist_inertia = [], [], [], []
    damping_torque = np.empty_like(x["g_rate"])
    per = x["per"]
    for n0 in x["firsts"]:
        i = min(n0 + per // 2, len(x["tf"]) - 1)
        # the drives are tuned and the damping set at the first path point, as the station's
        jm = arm.joints_at(x["q_arm"][i], 1.0 / x["c"], damping_ratio, x["servo"], design_q_rad=x["q_arm"][0])
        L = arm.payload_map(x["q_arm"][i])
        full.append(arm_response.arm_matrices(jm, STEP_S))
        # the sensor's reading holds the payload's inertia: the load it measures drives the arm without it
        bare.append(arm_response.arm_matrices(replace(jm, M=jm.M + x["J"][i].T @ L), STEP_S))
        # the gears' damping of the gravity twist's rate, D d/dt(C g)
        damping_torque[n0:n0 + per] = (x["c"] * x["g_rate"][n0:n0 + per]) @ jm.D.T
        inertia_maps.append(L)
        # each gear's twist inertia there: its link (1 / (M^-1)_jj, the rest of the arm free) in series with its
        # motor: what a link crossing its play moves
        twist_inertia.append(jm.twist_inertia_kgm2())
    Ls = np.array(inertia_maps)[x["seg"]]
    motion_torque = damping_torque - x["velocity_terms"]
    motion = arm_response.responses(full, x["seg"], [(motion_torque, None, x["path"])])[..., 0]
    acc = np.gradient(np.gradient(x["q_arm"] + motion, STEP_S, axis=0), STEP_S, axis=0)
    W_cut = x["W_f"] - np.einsum("nrj,nj->nr", Ls, acc)
    tau_cut = np.einsum("nrj,nr->nj", x["J"], W_cut)
    dev = arm_response.responses(bare, x["seg"], [(tau_cut, None, None), (None, x["corr_servo"], None)])
    return motion, dev, np.array(twist_inertia)[x["seg"]]


def run_signals(files, robot, arm, damping_ratio=None):
    """RunSignals from a run's logs and settings.  ``robot``: the DH table;
    ``arm``: the controller's model of the arm (diagrams/run_arm.ArmModel:
    gravity and inertia torques, mass matrix at a pose); ``damping_ratio``:
    the gears' modal damping ratio (None: DAMPING_RATIO)."""
    return signals_at(run_context(files, robot, arm), arm, DAMPING_RATIO if damping_ratio is None else damping_ratio)


def run_context(files, robot, arm):
    """What the run's signals need that does not depend on the arm's
    damping (a dict for ``signals_at``)."""
    s, jl = files.settings, files.joints
    servo = servo_of(s)
    t_j, q_j, c_j = jl.t_s, robot.joint_rad(jl.q_deg), robot.model_delta_rad(jl.correction_deg)
    cutoff = smoothing_hz(files, robot)
    t, W, rate = _process_wrench(files, robot, cutoff)
    c = 1.0 / np.asarray(s.joint_stiffness_Nm_per_rad, dtype=float)
    tool = np.asarray(s.tool_point_mm, dtype=float) / 1e3
    # the fine grid of the arm's response
    h = STEP_S
    tf = np.arange(t_j[0], t_j[-1], h)
    lag = int(round(servo.interpolator_delay_s / h))
    q_prog = _resample(tf, t_j, q_j - c_j)
    q_arm = delayed(q_prog, lag)  # where the arm is meant to be
    held = np.clip(np.searchsorted(t_j, tf, side="right") - 1, 0, len(t_j) - 1)
    corr_servo = delayed(c_j[held], lag)  # the correction as the servo gets it
    J = kin.jacobian(robot.dh, q_arm, tool)
    W_f = _resample(tf, t, W)
    tau_f = np.einsum("nrj,nr->nj", J, W_f)
    # the controller's gravity model's twist along the program (its rate gets no feed-forward)
    g_f = delayed(_resample(tf, t_j, arm.gravity_torques(q_j - c_j)), lag)
    g_rate = np.gradient(g_f, h, axis=0)
    path = arm_response.path_terms(q_arm, h, servo.velocity_feedforward, g_f * c)
    # the fitting grid: every GRID_EVERY-th step
    k = np.arange(0, len(tf), GRID_EVERY)
    grid, q_nom = tf[k], q_arm[k]
    v_f = np.gradient(q_arm, h, axis=0)
    v, a = v_f[k], np.gradient(v_f, h, axis=0)[k]
    seg, firsts = _segments(len(tf), h)
    return {"settings": s, "robot": robot, "tool": tool, "tf": tf, "q_arm": q_arm, "J": J, "seg": seg,
            "firsts": firsts, "per": firsts[1] - firsts[0] if len(firsts) > 1 else len(tf), "c": c, "servo": servo,
            "g_rate": g_rate, "path": path, "W_f": W_f, "corr_servo": corr_servo, "cutoff": cutoff, "k": k,
            "grid": grid, "q_nom": q_nom, "tau": tau_f[k], "g": arm.gravity_torques(q_nom),
            "g0": arm.gravity_torques(q_j[:1] - c_j[:1])[0], "tau_i": arm.inertia_torques(q_nom, v, a),
            "velocity_terms": _resample(tf, grid, arm.inertia_torques(q_nom, v, np.zeros_like(a))),
            "corr": _resample(grid, t_j, _lowpass(c_j, 1.0 / float(np.median(np.diff(t_j))), cutoff)),
            "tau_per_sensor_force": _tau_per_sensor_force(robot, s, q_nom, J[k], tool)}


def _tau_per_sensor_force(robot, settings, q, J, tool_m):
    """(n, 6, 3) N*m per N: J^T of a unit force along each axis of the
    sensor's frame (applied at the sensor origin, the flange's), as the
    compensator's gravity removal passes a bias of the sensor's force
    reading on: at the tool point in the base frame, the force rotated into
    the base and its moment about the tool point."""
    R_mount = PayloadCalibration(**settings.payload).arrays()[4]
    Rs = kin.frames(robot.dh, q)[:, 6, :3, :3] @ R_mount  # base <- sensor
    r_b = Rs @ (R_mount.T @ tool_m)  # the tool point from the sensor origin, base frame
    f = Rs  # (n, 3, 3): column a is the unit force along sensor axis a, base frame
    m = -np.cross(r_b[:, :, None], f, axis=1)  # about the tool point: -(r x f)
    W = np.concatenate([f, m], axis=1)  # (n, 6, 3)
    return np.einsum("nrj,nra->nja", J, W)


def signals_at(ctx, arm, damping_ratio, damping=None):
    """RunSignals of a run (``run_context``) with the gears' modal damping
    ratio ``damping_ratio``."""
    x, s, k = ctx, ctx["settings"], ctx["k"]
    motion, dev, twist_inertia = _arm_response(arm, ctx, damping_ratio)
    J, Jg = x["J"], x["J"][k]
    dz = np.einsum("nj,njk->nk", J[:, 2, :], np.concatenate([dev, motion[..., None]], axis=2))
    # what the compensator predicts: its model's law under the process load (model/compensator.DeflectionModel)
    model_dq = model_deflection(s, x["g"], x["tau"], x["c"])
    # the loop's tracking error with the plant as the model believes it: its stiffness (dynamic), and its
    # lost motion and coupling (quasi-static, the law of the total torque; the play by the run's law)
    believed = believed_gear_deviation(s, x["g"], x["g0"], x["tau_i"], x["tau"], x["c"], twist_inertia[k],
                                       x["grid"])
    dz_loop = dz[k, 0] + dz[k, 1] + np.einsum("nj,nj->n", Jg[:, 2, :], believed)
    return RunSignals(x["grid"], x["q_nom"], x["corr"], x["W_f"][k], x["tau"], x["g"], x["tau_i"], x["g0"],
                      Jg[:, 2, :], kin.tool_position(x["robot"].dh, x["q_nom"], x["tool"]), x["c"], model_dq,
                      dz[k, 2], dz_loop, x["servo"], damping_ratio, x["cutoff"], damping,
                      x["tau_per_sensor_force"], twist_inertia[k])


def play_law_of(settings, compliance):
    """(law, take-up torques (6,) N*m, friction in the play (6,) N*m) of
    the run's compensator (its settings: the law it applied to the model's
    lost motion, and its identified take-up and friction, else the
    compensator's fallbacks from the model's compliance)."""
    c = np.asarray(compliance, dtype=float)
    law = getattr(settings, "lost_motion_law", "hysteretic")
    take_up = getattr(settings, "lost_motion_take_up_Nm", None)
    friction = getattr(settings, "lost_motion_friction_Nm", None)
    return (law, fallback_take_up_Nm(c) if take_up is None else np.asarray(take_up, dtype=float),
            gap_friction_Nm(1.0 / c) if friction is None else np.asarray(friction, dtype=float))


def model_deflection(settings, tau_static, tau_process, compliance):
    """(n, 6) rad: the deflection the run's compensator predicted from the
    process load (model/compensator.DeflectionModel): C tau with its lost
    motion and coupling by its law, from the gravity torque the gears carry
    (``tau_static``); with the hysteretic law each gear's place in its gap
    stepped along the run from rest under the first sample's torque (the
    diagram's block crosses with the link's inertia too: left out, this
    only aligns the correction in time, ``loop_lag_ms``)."""
    s, c = settings, np.asarray(compliance, dtype=float)
    b = np.asarray(s.lost_motion_rad, dtype=float)
    law, take_up, friction = play_law_of(s, c)
    if law == "smooth" or not np.any(b):
        return static_deflection(tau_static, tau_process, c, s.lost_motion_rad, s.coupling_c23_rad_per_Nm, take_up)
    # play_hysteresis.deflection at each sample: the held twist, plus the touch-off's place in the gaps, less the
    # twist of the torque carried, the gears stepped along the run (play_hysteresis.replay)
    g = np.atleast_2d(np.asarray(tau_static, dtype=float))
    carried = g - np.atleast_2d(np.asarray(tau_process, dtype=float))
    ref = play_hysteresis.start(carried[0], b)
    return (twist(g, c, None, s.coupling_c23_rad_per_Nm) + ref
            - play_hysteresis.replay(carried, b, friction, c, s.coupling_c23_rad_per_Nm))


def believed_gear_deviation(settings, tau_static, tau_touch_off, tau_inertia, tau_process, compliance,
                            twist_inertia_kgm2, t_s):
    """(n, 6) rad: ``gear_law_deviation`` of the model's lost motion and
    coupling with the play by the law the run's compensator used (its
    settings' ``lost_motion_law``): the smooth law's b tanh(tau / take-up),
    or the hysteretic law's links crossing their gaps with their twist
    inertia (``play_crossing_deviation``; without the inertia, the relay:
    ``play_relay_deviation`` times b)."""
    s = settings
    b = np.asarray(s.lost_motion_rad, dtype=float)
    law, take_up, friction = play_law_of(s, compliance)
    args = (tau_static, tau_touch_off, tau_inertia, tau_process)
    if law == "smooth" or not np.any(b):
        return gear_law_deviation(*args, s.lost_motion_rad, s.coupling_c23_rad_per_Nm, take_up)
    coupling = gear_law_deviation(*args, None, s.coupling_c23_rad_per_Nm, take_up)
    if twist_inertia_kgm2 is None:
        return coupling + play_relay_deviation(*args, friction) * b
    return coupling + play_crossing_deviation(*args, b, friction, twist_inertia_kgm2, t_s)


def carried_torque(tau_static, tau_inertia, tau_process):
    """(n, 6) N*m: the total torque the gears carry, the weight, the
    inertia and minus the process load (a generalized force on the links)."""
    return np.asarray(tau_static, dtype=float) + np.asarray(tau_inertia, dtype=float) \
        - np.asarray(tau_process, dtype=float)


def gear_law_deviation(tau_static, tau_touch_off, tau_inertia, tau_process, lost_motion_rad, coupling_c23,
                       take_up_Nm):
    """(n, 6) rad: how far the links move beyond the linear gears' deflection
    (the controller's gravity model and the compensator's stiffness cover
    that) from the gears' lost motion and 2-3 coupling (model/transmission.py),
    of the total torque the gears carry: the weight (its change from the
    touch-off, where the work offset was set), the inertia and the process
    load (a generalized force on the links: the gears carry minus it).
    ``take_up_Nm`` (6,): each joint's take-up torque of the lost motion
    (N*m; the compensator's: model/transmission.fallback_take_up_Nm of the
    model's compliance, as the settings carry no identified one)."""
    carried = carried_torque(tau_static, tau_inertia, tau_process)
    zero = np.zeros(6)
    return -(twist(carried, zero, lost_motion_rad, coupling_c23, take_up_Nm)
             - twist(tau_touch_off, zero, lost_motion_rad, coupling_c23, take_up_Nm))


def play_relay_deviation(tau_static, tau_touch_off, tau_inertia, tau_process, friction_Nm):
    """(n, 6) rad per rad of play: how far the links move, per unit half-width
    b of each gear's play, under the compensator's hysteretic law
    (model/play_hysteresis.py, the plant's own: systems/gear_transmission.py):
    each gear stays on the flank it last pressed until the total torque it
    carries (weight + inertia - process load, as ``gear_law_deviation``)
    passes its friction ``friction_Nm`` (6,) N*m the other way, a relay
    whose output is linear in b; the touch-off (``play_hysteresis.start``
    under ``tau_touch_off``) took up where each gear sat then.  The elastic
    twist the gear loses while inside its gap (C tau, |tau| <= T_c) is
    left out: under a micro-radian."""
    carried = carried_torque(tau_static, tau_inertia, tau_process)
    unit = np.ones(6)
    p0 = play_hysteresis.start(tau_touch_off, unit)
    p, out = p0, np.empty_like(carried)
    for i, tau in enumerate(carried):
        p = play_hysteresis.step(p, tau, unit, friction_Nm)
        out[i] = p
    return -(out - p0)


def play_crossing_deviation(tau_static, tau_touch_off, tau_inertia, tau_process, play_rad, friction_Nm,
                            twist_inertia_kgm2, t_s):
    """(n, 6) rad: how far the links move from the gears' play of half-width
    ``play_rad`` (6,) as the plant's gear (systems/gear_transmission.py) and
    the compensator's hysteretic law (model/play_hysteresis.crossing_step)
    move them: each link stays where it is in its gap while the total torque
    it carries (as ``play_relay_deviation``) is within its friction
    ``friction_Nm`` (6,) N*m, and crosses to the other flank with its twist
    inertia ``twist_inertia_kgm2`` ((n, 6) kg*m^2) under the torque beyond
    the friction when it passes it, landing on the flank (the plant's: no
    soft landing).  The touch-off took up where each gear sat then.  Not
    linear in b: a wider gap takes longer to cross (sqrt(4 b J / T))."""
    carried = carried_torque(tau_static, tau_inertia, tau_process)
    b = np.asarray(play_rad, dtype=float)
    J = np.broadcast_to(np.asarray(twist_inertia_kgm2, dtype=float), carried.shape)
    dt = np.diff(np.asarray(t_s, dtype=float), prepend=t_s[0])
    p0 = play_hysteresis.start(tau_touch_off, b)
    p, v, out = p0, np.zeros(6), np.empty_like(carried)
    for i, tau in enumerate(carried):
        p, v = play_hysteresis.crossing_step(p, v, tau, b, friction_Nm, J[i], dt[i])
        out[i] = p
    return -(out - p0)

