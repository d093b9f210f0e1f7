"""Residual diagnosis of a machining run (``robstiff diagnose-run RUN_DIR``):
from what a cell records (docs/run_files.md: the wrist sensor's raw log, the
controller's joint angles and correction, the compensator's and the servo's
settings and the scan of the machined face) find what the compensated
surface error is, trace it to a cause, write each candidate fix as
compensator settings with a verification-cut plan, and decide from the
verification cuts' scans.  Nothing here reads the simulation's truth
(``sim_*`` files) or runs a simulation: a cell's own logs and the robot's
model are enough.  Plain numpy and scipy; the robot controller's model of
the arm (its weight, inertia and modes: diagrams/run_arm.ArmModel, Drake)
comes in as an object.

The joint (diagrams/station.py): the gear between the motor and the link
carries the total torque, weight + inertia + cut; the controller's gravity
model and a touch-off at the first path point put the tool where commanded
at rest; the correction reaches the motor after the servo's dead time
(``servo.interpolator_delay_ms``) through the position loop.

Signals (identification/arm_response.py).  The wrench log, gravity removed
with the settings' payload calibration and moved to the tool point (base
frame), is the process load W(t) (smoothed over SMOOTH_MM of feed); the
arm's time is the program's delayed by the dead time.  A linear model of
the joints (gears at the model's stiffness, the weight's stiffness, assumed
DAMPING_RATIO, the motor-side servo), linearised every SEGMENT_S, gives:
  the arm's own motion error (the path's acceleration through the soft
    gears and the servo, the gravity model's twist rate that gets no
    feed-forward): known, not a cause;
  the loop's tracking error: the logged correction through the servo plus
    the measured load through the gears (the payload's inertia taken out of
    the sensor's reading), the model's lost motion and coupling added.
The tool's vertical deviation is the sum of these and the causes' columns.

The loop's tracking error, scaled by a (1: as predicted, 0-1.5), is always
in the model; it is reported apart (``loop_lag``), with its fix (plain ->
predictive) offered when it moves the face by at least the floor.  Causes
(each a deviation dz(t) per unit parameter, beyond the model as set):
  stiffness_error_jN     r_N J_z,N c_N (tau_N - tau_inertia_N): joint N's
                         compliance off by r_N (the controller's gravity
                         model is calibrated on the arm: the weight's part
                         is not this cause's)
  lost_motion            sum_N b_N J_z,N (tanh(T0_N / 50) - tanh(T_N / 50)),
                         T the total torque the gear carries (weight +
                         inertia - J^T W), T0 at the touch-off: joints 1-6
                         (where T keeps its sign, or the joint cannot move
                         the tool vertically, there is no data)
  joint_coupling         c23 of the total torque's change since the touch-off
  setup_offset           a constant (tool length, workpiece height)
The surface at a scan point is the lowest the cutter's face went while it
covered the point (the envelope), so the error predicted there is
base(x) - min over covering t of (z_nom(t) + dz(t)).

Statistics (thresholds in the report): the noise floor is the scan noise,
stated (--noise-mm, or scan.csv's noise_mm) or estimated from the scan
(identification/scan_statistics.py), both reported.  Forward selection on
top of the loop: a cause is named when its nested F-test with the effective
number of independent points gives p < ALPHA, it moves the fitted face by
at least SIZE_FACTOR x the floor (RMS over the scan) from the smaller
model's, and it needs no parameter at a plausibility bound.  A fit that
extends a model starts from that model's solution (it is never worse); a
parameter that cannot move the surface by NO_DATA x the floor over its
whole range has no data in this run and is dropped.  Causes whose fits
differ by less than the floor (mean square) are alike: one pass cannot tell
them apart, and verification cuts decide (identification/run_verification.py:
scans and settings only).
"""

import copy
from dataclasses import dataclass, replace

import numpy as np
from scipy import signal
from scipy.optimize import least_squares

from robstiff_drake.errors import InputError
from robstiff_drake.identification import arm_response
from robstiff_drake.identification import run_files as rf
from robstiff_drake.identification import run_verification as rv
from robstiff_drake.identification import scan_statistics as ss
from robstiff_drake.identification.arm_response import SEGMENT_S, STEP_S, delayed
from robstiff_drake.model import kinematics as kin
from robstiff_drake.model.joint_dynamics import DEFAULT_MODAL_DAMPING_RATIO
from robstiff_drake.model.payload import PayloadCalibration, payload_wrench
from robstiff_drake.model.servo import ServoParameters
from robstiff_drake.model.transmission import static_deflection, twist
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
# The damping's profile (``profile_damping``): the ratios tried, and its likelihood interval (chi-square, one
# parameter, 95 %: the fit's residual sum of squares within 3.84 noise floors squared, per effective point,
# of the best).
DAMPING_GRID = np.array([0.02, 0.03, 0.05, 0.07, 0.10, 0.15, 0.20])
DAMPING_CHI2 = 3.84
ALPHA = 1e-3  # per test; about 10 causes are tried per round
SIZE_FACTOR = 1.0  # a named cause changes the surface by at least this many noise floors (RMS)
MAX_CAUSES = 2
MIN_FLOOR_MM = 5e-4  # below half a micrometre a machining question is not decided
EXPLAIN_ALPHA = 0.01  # the residual is consistent with the floor unless chi2 says otherwise at this level
NO_DATA = 0.1  # of the floor: what a parameter must move the surface by over its range to be kept
LOOP = "loop_lag"  # the loop's tracking error: always in the model, its fix offered when it matters
NOISE_DISAGREE = 2.0  # warn when the stated and the estimated noise differ by more than this factor
ALIKE = 1.0  # causes whose mean-square residuals differ by less than ALIKE x floor^2 are alike


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
                         "controller's servo settings (" + ", ".join(rf.SERVO_KEYS) + ") to know when a "
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
    full, bare, inertia_maps = [], [], []
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
    Ls = np.array(inertia_maps)[x["seg"]]
    motion_torque = damping_torque - x["velocity_terms"]
    motion = arm_response.responses(full, x["seg"], [(motion_torque, None, x["path"])])[..., 0]
    acc = np.gradient(np.gradient(x["q_arm"] + motion, STEP_S, axis=0), STEP_S, axis=0)
    W_cut = x["W_f"] - np.einsum("nrj,nj->nr", Ls, acc)
    tau_cut = np.einsum("nrj,nr->nj", x["J"], W_cut)
    dev = arm_response.responses(bare, x["seg"], [(tau_cut, None, None), (None, x["corr_servo"], None)])
    return motion, dev


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
            "corr": _resample(grid, t_j, _lowpass(c_j, 1.0 / float(np.median(np.diff(t_j))), cutoff))}


def signals_at(ctx, arm, damping_ratio, damping=None):
    """RunSignals of a run (``run_context``) with the gears' modal damping
    ratio ``damping_ratio``."""
    x, s, k = ctx, ctx["settings"], ctx["k"]
    motion, dev = _arm_response(arm, ctx, damping_ratio)
    J, Jg = x["J"], x["J"][k]
    dz = np.einsum("nj,njk->nk", J[:, 2, :], np.concatenate([dev, motion[..., None]], axis=2))
    # what the compensator predicts: its model's law under the process load (model/compensator.DeflectionModel)
    model_dq = static_deflection(x["g"], x["tau"], x["c"], s.lost_motion_rad, s.coupling_c23_rad_per_Nm)
    # the loop's tracking error with the plant as the model believes it: its stiffness (dynamic), and its
    # lost motion and coupling (quasi-static, the law of the total torque)
    believed = gear_law_deviation(x["g"], x["g0"], x["tau_i"], x["tau"], s.lost_motion_rad,
                                  s.coupling_c23_rad_per_Nm)
    dz_loop = dz[k, 0] + dz[k, 1] + np.einsum("nj,nj->n", Jg[:, 2, :], believed)
    return RunSignals(x["grid"], x["q_nom"], x["corr"], x["W_f"][k], x["tau"], x["g"], x["tau_i"], x["g0"],
                      Jg[:, 2, :], kin.tool_position(x["robot"].dh, x["q_nom"], x["tool"]), x["c"], model_dq,
                      dz[k, 2], dz_loop, x["servo"], damping_ratio, x["cutoff"], damping)


def gear_law_deviation(tau_static, tau_touch_off, tau_inertia, tau_process, lost_motion_rad, coupling_c23):
    """(n, 6) rad: how far the links move beyond the linear gears' deflection
    (the controller's gravity model and the compensator's stiffness cover
    that) from the gears' lost motion and 2-3 coupling (model/transmission.py),
    of the total torque the gears carry: the weight (its change from the
    touch-off, where the work offset was set), the inertia and the process
    load (a generalized force on the links: the gears carry minus it)."""
    carried = tau_static + tau_inertia - tau_process
    zero = np.zeros(6)
    return -(twist(carried, zero, lost_motion_rad, coupling_c23) - twist(tau_touch_off, zero, lost_motion_rad,
                                                                          coupling_c23))


@dataclass
class Param:
    name: str
    unit: str
    scale: float  # SI -> unit
    lo: float  # bounds, SI
    hi: float
    lo_is_limit: bool = False  # lo is a physical limit (b >= 0), not a plausibility bound
    nominal: float = 0.0  # SI: the value with nothing amiss (the loop's a: 1, as predicted)


@dataclass
class Candidate:
    name: str
    columns: np.ndarray  # (n, k): dz (m) per unit parameter (SI)
    params: list
    what: str


def loop_lag_ms(sig):
    """How far (ms) the correction lags the model's deflection where it acts,
    at the motor: the compensator's own lag (the shift, 0-500 ms, that best
    cancels the correction's vertical effect and the deflection's) plus the
    servo's (the interpolator's dead time and the position loop's 1 / Kp)."""
    corr_z = np.einsum("nj,nj->n", sig.Jz, sig.correction_rad)
    defl_z = np.einsum("nj,nj->n", sig.Jz, sig.model_dq_rad)
    if not np.any(defl_z):
        return sig.servo.low_frequency_lag_s * 1e3
    shifts = np.arange(0.0, 0.5, 1.0 / GRID_HZ)
    cost = [np.sum((corr_z + np.interp(sig.t_s - d, sig.t_s, defl_z)) ** 2) for d in shifts]
    return float((shifts[int(np.argmin(cost))] + sig.servo.low_frequency_lag_s) * 1e3)


def _along(sig, dq):
    """The tool's vertical deviation (m, (n,)) of joint deviations dq (n, 6) rad."""
    return np.einsum("nj,nj->n", sig.Jz, dq)


def candidates(sig):
    """The candidate causes' columns and parameters (see the module docstring)."""
    Jz, c = sig.Jz, sig.compliance
    # ASSUMPTION: a <= 1.5.  The prediction has the servo and the arm's modes; a tracking error that fits
    # only when scaled beyond 1.5 is not this one
    out = [Candidate(LOOP, sig.dz_loop_m[:, None], [Param("a", "x predicted", 1.0, 0.0, 1.5, True, 1.0)],
                     "the loop's tracking error (the correction's lag behind the load, through the compensator, "
                     "the interpolator and the servo), as the logs predict it")]
    # what a joint's gear carries beyond the weight: the process load (a generalized force on the links,
    # which the gear holds back) and the arm's inertia.  ASSUMPTION (as diagrams/station.py): the
    # controller's gravity model is calibrated on the arm, so a stiffness error leaves the weight's part
    # to it; lost motion and coupling are not in it (the touch-off takes their static part at the first
    # path point only)
    moved = sig.tau_Nm - sig.tau_inertia_Nm
    for j in range(6):
        # a joint softer (r > 0) or stiffer than the model; ASSUMPTION: -50 %..+100 % of the compliance
        # bounds what an identified model can be off by
        out.append(Candidate(f"stiffness_error_j{j + 1}", (Jz[:, j] * c[j] * moved[:, j])[:, None],
                             [Param(f"r{j + 1}", "%", 100.0, -0.5, 1.0)],
                             f"joint {j + 1}'s compliance differs from the model's"))
    law = (sig.tau_static_Nm, sig.tau_touch_off_Nm, sig.tau_inertia_Nm, sig.tau_Nm)
    unit = np.eye(6)
    # ASSUMPTION: lost motion up to 300 urad (1 arcmin); industrial gears are specified at 10-60 urad
    out.append(Candidate("lost_motion",
                         np.column_stack([_along(sig, gear_law_deviation(*law, unit[j], 0.0)) for j in range(6)]),
                         [Param(f"b{j + 1}", "urad", 1e6, 0.0, 3e-4, True) for j in range(6)],
                         "lost motion (backlash) in the gears beyond the model's, taken up where the total torque "
                         "a gear carries (weight, inertia and cut) changes sign"))
    # ASSUMPTION: |c23| <= 0.3 sqrt(c2 c3); a positive-definite compliance needs < 1
    c23 = 0.3 * np.sqrt(c[1] * c[2])
    out.append(Candidate("joint_coupling", _along(sig, gear_law_deviation(*law, None, 1.0))[:, None],
                         [Param("c23", "rad/(N*m)", 1.0, -c23, c23)],
                         "a joint 2-3 coupling beyond the model's (of the total torque)"))
    out.append(Candidate("setup_offset", -np.ones((len(sig.t_s), 1)), [Param("offset", "mm", 1e3, -1e-3, 1e-3)],
                         "a constant: tool length or workpiece height (+ = cut more)"))
    return out


class Envelope:
    """The face a deviation dz(t) leaves along the scan: each point is the
    lowest the cutter's face (radius R, centred on the program's tool point,
    moved by the arm's own motion error ``sig.dz_motion_m``) went while
    covering it."""

    def __init__(self, scan, sig, cutter_diameter_mm):
        x, y = scan.x_mm / 1e3, scan.y_mm / 1e3
        p = sig.p_nominal_m
        R = cutter_diameter_mm / 2e3
        cover = (x[:, None] - p[None, :, 0]) ** 2 + (y[:, None] - p[None, :, 1]) ** 2 <= R * R
        self.covered = cover.any(axis=1)  # scan points the pass went over
        cover = cover[self.covered]
        self.samples = np.flatnonzero(cover.any(axis=0))  # samples that cover a scan point
        cover = cover[:, self.samples]
        # the covering (point, sample) pairs, point by point: the envelope is a minimum over each point's run
        rows, cols = np.nonzero(cover)
        self._pair_samples = self.samples[cols]
        self._starts = np.flatnonzero(np.r_[True, np.diff(rows) > 0])
        z = p[self._pair_samples, 2]
        self.base = np.minimum.reduceat(z, self._starts)  # the programmed face
        self._Z = z + sig.dz_motion_m[self._pair_samples]

    def surface(self, dz):
        """Surface error (m, + = cut more) at the covered scan points."""
        return self.base - np.minimum.reduceat(self._Z + dz[self._pair_samples], self._starts)


@dataclass
class Fit:
    causes: list  # Candidate
    keep: list  # per cause: indices of its parameters kept
    theta: np.ndarray  # SI, concatenated
    rss: float
    residual: np.ndarray  # m

    def columns(self):
        return np.hstack([c.columns[:, k] for c, k in zip(self.causes, self.keep)]) if self.causes else None

    def params(self):
        return [p for c, k in zip(self.causes, self.keep) for p in (c.params[i] for i in k)]

    def slices(self):
        out, i = [], 0
        for k in self.keep:
            out.append(slice(i, i + len(k)))
            i += len(k)
        return out


def _solve(env, cols, params, y, starts):
    """Bounded least squares of surface(cols @ theta) = y from each start;
    (theta SI, rss m^2) of the best.  Solved for each parameter's fraction
    of its range and residuals in mm, so that the solver's tolerances (made
    for numbers of order one) stop it at the optimum, not at the start."""
    lo = np.array([p.lo for p in params])
    span = np.array([p.hi for p in params]) - lo

    def resid(u):
        return (env.surface(cols @ (lo + span * u)) - y) * 1e3

    best = None
    for start in starts:
        u0 = np.clip((np.asarray(start, dtype=float) - lo) / span, 0.0, 1.0)
        sol = least_squares(resid, u0, bounds=(0.0, 1.0), method="trf", x_scale="jac")
        if best is None or sol.cost < best.cost:
            best = sol
    return lo + span * best.x, float(2.0 * best.cost) * 1e-6


def fit_model(env, causes, keep, y, base=None):
    """Fit the causes (their kept parameters) to y.  ``base``: the fit of
    the model this one extends (its causes first): its solution, with the
    new parameters at zero, is the first start, so the extension is never
    worse; the new parameters also start at a quarter and three quarters of
    their range, and all parameters start once more at their nominal
    values (a fit through the face's envelope has local minima: an old
    parameter that absorbed what the new one explains may not come back
    from where the smaller model left it)."""
    fit = Fit(list(causes), [list(k) for k in keep], np.zeros(0), float(y @ y), -y)
    params = fit.params()
    if not params:
        return fit
    n_old = len(base.theta) if base is not None else 0
    head = base.theta if base is not None else np.zeros(0)
    new = params[n_old:]
    starts = [np.r_[head, [p.nominal for p in new]]]
    for frac in (0.25, 0.75):
        starts.append(np.r_[head, [p.lo + frac * (p.hi - p.lo) for p in new]])
    if n_old:
        starts.append(np.array([p.nominal for p in params]))
    fit.theta, fit.rss = _solve(env, fit.columns(), params, y, starts)
    fit.residual = env.surface(fit.columns() @ fit.theta) - y
    return fit


def _without(fit, i, value=None):
    """fit.theta with cause i's parameters set to zero (or parameter ``i``, a flat index, to ``value``)."""
    th = fit.theta.copy()
    if value is None:
        th[fit.slices()[i]] = 0.0
    else:
        th[i] = value
    return th


def _rms(v):
    return float(np.sqrt(np.mean(np.square(v)))) if np.size(v) else 0.0


def _no_data(env, fit, floor_m, first_new):
    """Flat indices (>= first_new) of parameters that cannot move the surface
    by NO_DATA x the floor over their whole range."""
    cols, params = fit.columns(), fit.params()
    out = []
    for i in range(first_new, len(params)):
        s_lo = env.surface(cols @ _without(fit, i, params[i].lo))
        s_hi = env.surface(cols @ _without(fit, i, params[i].hi))
        if _rms(s_hi - s_lo) < NO_DATA * floor_m:
            out.append(i)
    return out


def _identifiable(env, cols):
    X = cols[env.samples]
    norms = np.linalg.norm(X, axis=0)
    if np.any(norms == 0):
        return False
    return np.linalg.matrix_rank(X / norms, tol=1e-8) == X.shape[1]


def try_cause(env, base, cand, y, floor_m, stats_ctx):
    """Extend ``base`` by ``cand``: the fit, its test and whether it is named."""
    row = {"name": cand.name, "what": cand.what}
    keep = list(range(len(cand.params)))
    # a parameter whose column is zero over the covered samples cannot act here
    norms = np.linalg.norm(cand.columns[env.samples], axis=0)
    keep = [i for i in keep if norms[i] > 1e-9 * max(norms.max(), 1e-300)]
    n_old = len(base.theta)
    while True:
        if not keep:
            row["status"] = "no data in this run (the cause cannot change the surface here)"
            return row, None
        causes, keeps = base.causes + [cand], base.keep + [keep]
        trial = Fit(causes, keeps, np.zeros(0), 0.0, None)
        if not _identifiable(env, trial.columns()):
            row["status"] = "not identifiable from this run (its deviation is a combination of the model's)"
            return row, None
        fit = fit_model(env, causes, keeps, y, base)
        dropped = _no_data(env, fit, floor_m, n_old)
        if not dropped:
            break
        keep = [k for j, k in enumerate(keep) if n_old + j not in dropped]
    n = y.size
    n_eff, tau = ss.effective_points(fit.residual * 1e3, stats_ctx["segs"], stats_ctx["length_mm"],
                                     stats_ctx["cutter_mm"])
    F, p = ss.f_test(base.rss, fit.rss, len(keep), len(fit.theta), n, n_eff)
    # what the cause adds: how far the face it fits moves from the smaller model's own fit (a cause that
    # only trades places with one already in the model, as an offset and a stiffness error on a steady
    # cut, moves it little however large its parameter)
    before = env.surface(base.columns() @ base.theta) if base.causes else np.zeros(n)
    size = _rms(env.surface(fit.columns() @ fit.theta) - before)
    mine = fit.theta[fit.slices()[-1]]
    ps = [cand.params[i] for i in keep]
    at_bound = [q.name for q, v in zip(ps, mine)
                if (abs(v - q.hi) <= 1e-6 * (q.hi - q.lo)) or (not q.lo_is_limit and abs(v - q.lo) <= 1e-6 * (q.hi - q.lo))]
    row.update(status="ok", rms_mm=_rms(fit.residual) * 1e3, f_stat=F, p_value=p, n_effective=n_eff,
               size_mm=size * 1e3, params={f"{q.name} ({q.unit})": float(v * q.scale) for q, v in zip(ps, mine)},
               dropped_no_data=[cand.params[i].name for i in range(len(cand.params)) if i not in keep],
               at_bound=at_bound)
    reasons = []
    if p >= ALPHA:
        reasons.append(f"p = {p:.2g} >= {ALPHA:g}")
    if size < SIZE_FACTOR * floor_m:
        reasons.append(f"changes the surface by {size * 1e3:.4f} mm, below the noise floor")
    if at_bound:
        reasons.append(f"needs {', '.join(at_bound)} at its plausibility bound")
    row["named"] = not reasons
    row["why_not"] = "; ".join(reasons)
    return row, fit


def noise_floor(scan, segs, stated_mm, warnings):
    """(floor mm, source, stated mm or None, estimated mm or None)."""
    estimated = ss.noise_from_scan(scan.error_mm, segs)
    stated, source = stated_mm, "stated (--noise-mm)"
    if stated is None and scan.noise_mm is not None:
        stated, source = scan.noise_mm, f"stated ({rf.SCAN} noise_mm)"
    if stated is None:
        if estimated is None:
            raise InputError(f"{scan.path}: too few neighbouring points to estimate the scan's noise; "
                             "state it with --noise-mm SIGMA")
        floor, source = estimated, "estimated from the scan (second differences)"
    else:
        floor = stated
        if estimated is not None and stated > 0 and not 1 / NOISE_DISAGREE <= estimated / stated <= NOISE_DISAGREE:
            warnings.append(f"the scan's own noise ({estimated:.4f} mm, from its second differences) differs from "
                            f"the stated {stated:.4f} mm by more than {NOISE_DISAGREE:g}x")
    if floor < MIN_FLOOR_MM:
        warnings.append(f"noise floor {floor:.5f} mm raised to {MIN_FLOOR_MM} mm (nothing finer is decided)")
        floor = MIN_FLOOR_MM
    return floor, source, stated, estimated


def profile_damping(run_ctx, arm, scan, cutter_mm, y, floor_m, stats_ctx, model):
    """The gears' modal damping ratio that the run's face decides: the
    causes of ``model`` (a Fit: the loop's tracking error and the named
    causes) refitted with the arm's response at each ratio of DAMPING_GRID
    (the arm's own motion error and the loop's response ring more or less);
    the interval of ratios whose fit is within DAMPING_CHI2 noise floors
    squared (per effective point) of the best.  A dict: ratio (None when the
    interval covers the whole grid: the face does not decide it), interval,
    the fits' rms (mm) per ratio, source, used."""
    rss, residuals = [], []
    for z in DAMPING_GRID:
        sig = signals_at(run_ctx, arm, z)
        env = Envelope(scan, sig, cutter_mm)
        by_name = {c.name: c for c in candidates(sig)}
        causes = [by_name[c.name] for c in model.causes]
        r = (fit_model(env, causes, model.keep, y).residual if causes else env.surface(np.zeros_like(sig.t_s)) - y)
        residuals.append(r)
        rss.append(float(r @ r))
    rss = np.array(rss)
    i = int(np.argmin(rss))
    n_eff, _ = ss.effective_points(residuals[i] * 1e3, stats_ctx["segs"], stats_ctx["length_mm"], cutter_mm)
    chi2 = (rss - rss[i]) / floor_m**2 * n_eff / y.size
    inside = chi2 <= DAMPING_CHI2
    lo, hi = float(DAMPING_GRID[inside].min()), float(DAMPING_GRID[inside].max())
    # a fit that leaves more than the noise says the model lacks something: the damping would take its place
    explained = ss.consistent_with_floor(residuals[i] * 1e3, floor_m * 1e3, n_eff, EXPLAIN_ALPHA)
    decided = explained and not (lo == DAMPING_GRID[0] and hi == DAMPING_GRID[-1])
    ratio = float(DAMPING_GRID[i]) if decided else None
    if decided:
        source = "estimated from the run (the fit to the face at each ratio)"
    elif not explained:
        source = (f"assumed ({DAMPING_RATIO:g}): the run does not decide it (the best fit, at {DAMPING_GRID[i]:g}, "
                  f"leaves {_rms(residuals[i]) * 1e3:.4f} mm, more than the noise: the model lacks something the "
                  "damping would stand in for)")
    else:
        source = (f"assumed ({DAMPING_RATIO:g}): the run does not decide it (every ratio from {lo:g} to {hi:g} fits "
                  "the face as well)")
    return {"ratio": ratio, "interval": [lo, hi], "grid": DAMPING_GRID.tolist(),
            "rms_mm": (np.sqrt(rss / y.size) * 1e3).tolist(), "used": ratio if decided else DAMPING_RATIO,
            "source": source}


def trace(env, cands, y, floor_m, stats_ctx, base):
    """Forward selection of causes on top of ``base`` (the loop's tracking
    error: always in the model); returns (rounds, final Fit)."""
    fit = base
    rounds = []
    while len(fit.causes) - len(base.causes) < MAX_CAUSES:
        results, fits = [], {}
        for cand in cands:
            if any(c.name == cand.name for c in fit.causes):
                continue
            row, f = try_cause(env, fit, cand, y, floor_m, stats_ctx)
            results.append(row)
            if f is not None:
                fits[cand.name] = f
        rounds.append(results)
        named = [r for r in results if r.get("named")]
        if not named:
            break
        fit = fits[min(named, key=lambda r: fits[r["name"]].rss)["name"]]
    return rounds, fit


def alternatives(env, cands, y, floor_m, stats_ctx, final):
    """Models as good as the final one with one named cause swapped for
    another candidate: its fit's mean square within ALIKE x floor^2 of the
    final's, changing the surface by at least the floor, no parameter at a
    plausibility bound.  [(row, Fit)], the row naming the cause replaced."""
    out = []
    names = [c.name for c in final.causes]
    for i, c in enumerate(final.causes):
        if c.name == LOOP:
            continue  # always in the model
        rest = Fit([], [], np.zeros(0), float(y @ y), -y)
        others = [(cc, k) for j, (cc, k) in enumerate(zip(final.causes, final.keep)) if j != i]
        if others:
            rest = fit_model(env, [o[0] for o in others], [o[1] for o in others], y)
        for cand in cands:
            if cand.name in names:
                continue
            row, f = try_cause(env, rest, cand, y, floor_m, stats_ctx)
            if f is None or row["at_bound"] or row["size_mm"] < SIZE_FACTOR * floor_m * 1e3:
                continue
            if (f.rss - final.rss) / y.size <= ALIKE * floor_m**2:
                row["instead_of"] = c.name
                out.append((row, f))
    return out


def _cause_params(fit):
    """{cause name: {param (unit): value}} of a fit."""
    out = {}
    for c, k, sl in zip(fit.causes, fit.keep, fit.slices()):
        out[c.name] = {f"{c.params[i].name} ({c.params[i].unit})": float(v * c.params[i].scale)
                       for i, v in zip(k, fit.theta[sl])}
    return out


def _si_params(fit):
    out = {}
    for c, k, sl in zip(fit.causes, fit.keep, fit.slices()):
        out[c.name] = {c.params[i].name: float(v) for i, v in zip(k, fit.theta[sl])}
    return out


def fixed_settings(settings, causes):
    """The settings with the causes ({name: {param: SI value}}) added to the
    compensator: (settings, [changes in words], [causes with no compensator fix])."""
    s = copy.deepcopy(settings)
    s.path = ""
    changes, none = [], []
    for name, p in causes.items():
        if name == "loop_lag":
            if s.mode == "plain":
                s.mode = "predictive"
                changes.append("mode: plain -> predictive (the force model ahead of the measured force: no lag)")
            else:
                none.append("loop_lag: the predictive compensator still lags (check its force model scale and "
                            "its delay)")
        elif name.startswith("stiffness_error_j"):
            j = int(name[-1]) - 1
            k = list(s.joint_stiffness_Nm_per_rad)
            old = k[j]
            k[j] = old / (1.0 + p[f"r{j + 1}"])
            s.joint_stiffness_Nm_per_rad = k
            changes.append(f"joint {j + 1}'s model stiffness {old:.4g} -> {k[j]:.4g} N*m/rad")
        elif name == "lost_motion":
            b = list(s.lost_motion_rad)
            for j in range(6):
                b[j] = b[j] + p.get(f"b{j + 1}", 0.0)
            s.lost_motion_rad = b
            changes.append("lost motion in the model: " + ", ".join(f"{v * 1e6:.1f}" for v in b)
                           + " urad (joints 1-6)")
        elif name == "joint_coupling":
            s.coupling_c23_rad_per_Nm = s.coupling_c23_rad_per_Nm + p["c23"]
            changes.append(f"joint 2-3 coupling in the model: {s.coupling_c23_rad_per_Nm:.3g} rad/(N*m)")
        elif name == "setup_offset":
            none.append(f"setup_offset: no compensator change; the face sits {p['offset'] * 1e3:+.4f} mm off "
                        "(+ = cut more): check the tool length and the workpiece height")
    return s, changes, none


def _fix_causes(fit, loop_fix):
    """The causes of a fit whose fixes a candidate carries: its named causes,
    and the loop's lag when its fix (predictive mode) is offered."""
    return [c.name for c in fit.causes if c.name != LOOP] + ([LOOP] if loop_fix else [])


def _model_name(fit, loop_fix):
    return " + ".join(_fix_causes(fit, loop_fix))


def _where_they_differ(env, scan, fits):
    """(x mm, y mm, difference mm) where the candidates' predicted surfaces
    differ most on this pass, or None with one candidate."""
    if len(fits) < 2:
        return None
    preds = np.array([env.surface(f.columns() @ f.theta) for f in fits])
    spread = preds.max(axis=0) - preds.min(axis=0)
    i = int(np.argmax(spread))
    xs, ys = scan.x_mm[env.covered], scan.y_mm[env.covered]
    return float(xs[i]), float(ys[i]), float(spread[i]) * 1e3


def _slug(name):
    return name.replace(" + ", "+")


def diagnose_run(run_dir, robot, arm, *, noise_mm=None, verify=(), scan=None):
    """Trace a run's surface error; with ``verify`` (run folders of
    verification cuts), decide between the candidate fixes from their scans.
    Reads only the cell files (identification/run_files.py); ``robot``: the
    run's robot, ``arm``: the controller's model of it (a callable of the
    robot: diagrams/run_arm.ArmModel).  Returns (report dict, extras:
    candidate settings texts, plan, data for the plot)."""
    files = rf.load_run_files(run_dir, scan=scan)  # (scan: a file made outside the run, diagnose-run --scan)
    cuts = [rf.load_run_files(c, names=(rf.SETTINGS, rf.SCAN)) for c in verify]
    if noise_mm is not None and not (np.isfinite(noise_mm) and noise_mm > 0):
        raise InputError(f"--noise-mm: must be a positive number (mm), got {noise_mm}")
    warnings = []
    settings, scan = files.settings, files.scan
    D = settings.cutter_diameter_mm
    servo_of(settings)  # refused before any computation when the file does not state it
    model_of_arm = arm(robot)
    run_ctx = run_context(files, robot, model_of_arm)
    sig = signals_at(run_ctx, model_of_arm, DAMPING_RATIO)
    env = Envelope(scan, sig, D)
    if env.covered.sum() < rf.MIN_ROWS[rf.SCAN]:
        raise InputError(f"{scan.path}: only {int(env.covered.sum())} scan points lie under the logged pass "
                         f"(cutter {D:g} mm): the scan and the logs are not of the same cut")
    if not env.covered.all():
        warnings.append(f"{int((~env.covered).sum())} scan points lie outside the logged pass and are left out")
    x_c, y_c = scan.x_mm[env.covered], scan.y_mm[env.covered]
    segs = ss.segments(x_c, y_c)
    y = scan.error_mm[env.covered] * 1e-3
    floor_mm, source, stated, estimated = noise_floor(scan, ss.segments(scan.x_mm, scan.y_mm), noise_mm, warnings)
    floor = floor_mm * 1e-3
    ctx = {"segs": segs, "length_mm": ss.scan_length_mm(x_c, y_c, segs), "cutter_mm": D}
    empty = Fit([], [], np.zeros(0), float(y @ y), -y)

    def traced(sig_, env_):
        loop_, *cands_ = candidates(sig_)
        loop_row_, loop_fit_ = try_cause(env_, empty, loop_, y, floor, ctx)
        return (loop_, cands_, loop_row_, loop_fit_, *trace(env_, cands_, y, floor, ctx,
                                                              loop_fit_ if loop_fit_ is not None else empty))

    loop, cands, loop_row, loop_fit, rounds, final = traced(sig, env)
    # the arm's damping, from how well the traced model fits the face at each ratio; re-traced at the
    # best one when the run decides it
    damping = profile_damping(run_ctx, model_of_arm, scan, D, y, floor, ctx, final)
    if damping["ratio"] is not None and damping["ratio"] != DAMPING_RATIO:
        sig = signals_at(run_ctx, model_of_arm, damping["ratio"], damping)
        env = Envelope(scan, sig, D)
        loop, cands, loop_row, loop_fit, rounds, final = traced(sig, env)
    sig.damping = damping
    model = [c for c in final.causes if c.name != LOOP]
    alts = alternatives(env, cands, y, floor, ctx, final) if model else []
    n_eff, tau = ss.effective_points(final.residual * 1e3, segs, ctx["length_mm"], D)
    rms_after = _rms(final.residual) * 1e3
    named = _cause_params(final)
    sizes = {}
    for i, c in enumerate(final.causes):
        sizes[c.name] = _rms(env.surface(final.columns() @ final.theta)
                             - env.surface(final.columns() @ _without(final, i))) * 1e3
    if model and loop_fit is not None:  # the loop's test given the causes named with it
        rest = fit_model(env, model, [k for c, k in zip(final.causes, final.keep) if c.name != LOOP], y)
        loop_row, _ = try_cause(env, rest, loop, y, floor, ctx)
    loop_fix = bool(loop_row.get("named")) and settings.mode == "plain"
    report = {
        "run_dir": str(run_dir), "run_id": files.run_id,
        "noise_floor_mm": floor_mm, "noise_source": source, "noise_stated_mm": stated,
        "noise_estimated_mm": estimated,
        "n_scan_points": int(y.size), "scan_length_mm": ctx["length_mm"], "n_effective": n_eff,
        "thresholds": {"alpha": ALPHA, "size_factor": SIZE_FACTOR, "no_data_fraction": NO_DATA,
                       "alike_mean_square_floors": ALIKE, "explains_alpha": EXPLAIN_ALPHA,
                       "max_causes": MAX_CAUSES, "smooth_hz": sig.smooth_hz, "damping_ratio": sig.damping_ratio,
                       "candidates_per_round": len(cands),
                       "rule": (f"a cause is named when its nested F-test on the effective number of independent "
                                f"scan points gives p < {ALPHA:g} ({len(cands)} candidates tried in the first "
                                f"round), it changes the surface by at least {SIZE_FACTOR:g} x the noise floor "
                                "(RMS) and needs no parameter at its plausibility bound; the arm's own motion "
                                "error and the loop's tracking error, both predicted from the logs, are in the "
                                "model before any cause")},
        "loop_lag_ms": loop_lag_ms(sig),
        "damping": sig.damping or {"used": sig.damping_ratio, "source": "given"},
        "motion_error_mm": _rms(env.surface(np.zeros_like(sig.t_s))) * 1e3,
        "loop_lag": _loop_report(loop_row, named.get(LOOP), sizes.get(LOOP), settings.mode, loop_fix),
        "rms_before_mm": _rms(y) * 1e3, "rms_after_mm": rms_after,
        "unexplained_mm": float(np.sqrt(max(rms_after**2 - floor_mm**2, 0.0))),
        "explains_data": ss.consistent_with_floor(final.residual * 1e3, floor_mm, n_eff, EXPLAIN_ALPHA),
        "causes": [{"name": c.name, "size_mm": sizes[c.name], "params": named[c.name], "what": c.what}
                   for c in model],
        "also_consistent_with": [r["name"] for r, _ in alts],
        "alternatives": [{"name": r["name"], "instead_of": r["instead_of"], "rms_mm": r["rms_mm"],
                          "size_mm": r["size_mm"], "params": r["params"]} for r, _ in alts],
        "rounds": rounds, "candidates": [],
        "surface_error_before_mm": ss.surface_stats(scan.x_mm, scan.y_mm, scan.error_mm,
                                                    ss.segments(scan.x_mm, scan.y_mm), D),
    }
    extras = {"scan": scan, "covered": env.covered, "model_mm": env.surface(final.columns() @ final.theta) * 1e3
              if final.causes else env.surface(np.zeros_like(sig.t_s)) * 1e3,
              "settings": {}, "plan": None, "cut_scans": []}
    # candidate fixes: compensator settings each
    cand_settings, plan_rows, sets = [], [], []
    if model or loop_fix:
        for f in [final] + [f for _, f in alts]:
            name = _model_name(f, loop_fix)
            si = {k: v for k, v in _si_params(f).items() if k != LOOP or loop_fix}
            s, changes, none = fixed_settings(settings, si)
            params = {k: v for k, v in _cause_params(f).items() if k != LOOP or loop_fix}
            entry = {"name": name, "params": params, "changes": changes, "not_in_compensator": none}
            same = next((n for n, other in cand_settings if s.same_as(other)), None)
            if same is not None:  # the same compensator change: one cut cannot tell these apart
                entry["same_settings_as"] = same
            elif changes:
                rel = f"candidates/{_slug(name)}/{rf.SETTINGS}"
                entry["settings"] = rel
                cand_settings.append((name, s))
                plan_rows.append((name, rel, "; ".join(changes)))
                extras["settings"][rel] = s
                sets.append(f)
            report["candidates"].append(entry)
        if plan_rows:
            differ = _where_they_differ(env, scan, sets) if len(sets) > 1 else None
            extras["plan"] = rv.verification_plan(plan_rows, scan, differ, floor_mm)
            report["verification_plan"] = extras["plan"]
    report["fix"] = _fix(report)
    if cuts:
        matched = rv.match_cuts(cand_settings, settings, cuts)
        verdict = rv.decide(scan, [(n, c.scan) for n, c in matched], floor_mm, D)
        for row, (_, c) in zip(verdict["cuts"], matched):
            row["run_dir"] = str(c.folder)
        report["verification"] = verdict
        extras["cut_scans"] = [(n, c.scan) for n, c in matched]
        report["fix"] = _verified_fix(report, verdict)
    report["warnings"] = warnings
    return report, extras


def _loop_report(row, params, size_mm, mode, fix):
    """The ``loop_lag`` key: the loop's tracking error (predicted from the
    logs, scaled by a): its size in the final model, its test against the
    model of the named causes without it (``gain_mm``: how far it moves that
    model's face; p), and its fix."""
    out = {"what": row["what"], "status": row["status"]}
    if row["status"] != "ok":
        return out
    out.update(params=params or row["params"], size_mm=size_mm if size_mm is not None else row["size_mm"],
               gain_mm=row["size_mm"], p_value=row["p_value"], f_stat=row["f_stat"],
               significant=bool(row["named"]), why_not=row["why_not"])
    if fix:
        out["fix"] = "mode: plain -> predictive"
    elif row["named"]:
        out["fix"] = None
        out["note"] = ("the predictive loop's own tracking error: no settings change removes it (check the force "
                       "model's scale and the controller's dead time)")
    return out


def _fix(report):
    """The ``fix`` key before verification."""
    if not report["candidates"]:
        return None
    cands = report.get("candidates", [])
    with_settings = [c for c in cands if "settings" in c]
    if not with_settings:
        return {"status": "no compensator change", "candidate": cands[0]["name"] if cands else None,
                "changes": [], "settings": None, "notes": sum((c["not_in_compensator"] for c in cands), [])}
    if len(with_settings) == 1:
        c = with_settings[0]
        return {"status": "to verify with one cut", "candidate": c["name"], "changes": c["changes"],
                "settings": c["settings"], "notes": c["not_in_compensator"]}
    return {"status": "undecided: the run cannot tell the candidates apart; verification cuts decide",
            "candidate": None, "changes": [], "settings": None,
            "candidates": [c["name"] for c in with_settings]}


def _verified_fix(report, verdict):
    chosen = verdict["chosen"]
    cands = {c["name"]: c for c in report.get("candidates", [])}
    if chosen is None:
        tied = [verdict["best"]] + verdict["tied_with"]
        # the best cut must beat the first cut before anything counts as verified
        better = bool(verdict.get("vs_first_cut", {}).get("better", True))
        out = {"status": "undecided" if better and not verdict["decided"] else "no fix better than the first cut",
               "candidate": None, "changes": [], "settings": None, "reason": verdict["reason"], "tied": tied}
        if better and not verdict["decided"] and all(t in cands for t in tied):
            # the tied cuts share a cause: its fix is verified, the rest is not
            common = set.intersection(*(set(cands[t]["params"]) for t in tied))
            if common:
                out["status"] = "verified in part: " + ", ".join(sorted(common)) + " (the rest undecided)"
                out["verified_causes"] = sorted(common)
        return out
    c = cands[chosen]
    return {"status": "verified", "candidate": chosen, "changes": c["changes"], "settings": c["settings"],
            "reason": verdict["reason"]}
