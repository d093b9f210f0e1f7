"""The compensation chain of the paper's Fig. 5 in plain Python, one
sensor sample or one controller cycle at a time: the guard, the force
filter, gravity removal, the deflection prediction, the saturation, the
transport delay and the rate-limited correction.  No Drake.

The Drake blocks of the simulated cell (systems/) call the same functions
(``guard_accepts``, ``rate_limited_step``, ``GravityRemover``,
``DeflectionModel``, model/filters), and ``Compensator`` strings them
together for the compensator process (cell/compensate.py), so the chain is
written once.

Units: wrenches (N, N*m) in the sensor frame unless named otherwise; q and
corrections in rad; times in s.
"""

import math
from collections import deque

import numpy as np

from robstiff_drake.model import play_hysteresis, transmission
from robstiff_drake.model.filters import SampleFilter
from robstiff_drake.model.kinematics import rpy_to_rotation
from robstiff_drake.model.payload import payload_weight
from robstiff_drake.model.wrench_frames import wrench_to_tool_base

# The compensator's lost-motion laws: "smooth" (model/transmission.twist: b tanh(tau / TAU_B), single-valued)
# and "hysteretic" (model/play_hysteresis.py: the gear's position in its gap tracked from the torque's history).
PLAY_LAWS = ("hysteretic", "smooth")


def guard_accepts(w, held, max_jump_N):
    """Whether the wrench guard takes sample ``w`` (6 floats) given the last
    good sample ``held``: every component finite and no force component
    jumping more than ``max_jump_N``.  (NaN fails every comparison, so a
    dropout is rejected here too.)"""
    x, y, z, a, b, c = w
    lx, ly, lz = held[0], held[1], held[2]
    return (abs(x - lx) <= max_jump_N and abs(y - ly) <= max_jump_N and abs(z - lz) <= max_jump_N
            and math.isfinite(a + b + c))


def rate_limited_step(held, dq, step):
    """The held correction (list, rad) moved towards -dq by at most
    ``step`` (rad, per joint) each: the reference correction's update."""
    return [x + min(s, max(-s, -d - x)) for x, d, s in zip(held, dq, step)]


class GravityRemover:
    """process wrench = measured wrench - bias - the payload's weight at q
    (sensor frame), in scalar arithmetic for the per-cycle path.
    ``kinematics``: a DeflectionPredictor (its ``pose(q)``)."""

    def __init__(self, calibration, kinematics):
        m, c, bf, bt, R_mount = calibration.arrays()
        self._m = m
        self._c = tuple(c.tolist())
        self._bias = tuple(np.concatenate([bf, bt]).tolist())
        self._R_mount = tuple(R_mount.ravel().tolist())
        self._kin = kinematics

    def __call__(self, wrench, q_rad):
        """The process wrench (list of 6) for a measured wrench and q (rad)."""
        R = self._kin.pose(q_rad)  # rotation in the first nine
        weight = payload_weight(R, self._R_mount, self._m, self._c)
        return [w - b - g for w, b, g in zip(wrench, self._bias, weight)]


class DeflectionModel:
    """dq = C_q J(q)^T W from a process wrench in the sensor frame, and with
    lost motion or coupling in the model the transmission law
    (model/transmission.static_deflection: the extra twist when the process
    torque adds to the static torque the gears already carry): the
    deflection prediction block's arithmetic.  ``predictor``: the
    compensator's DeflectionPredictor; ``tool_m``: the tool point in the
    flange frame (m); ``mount_rpy_deg``: the sensor frame's rotation on the
    flange (deg)."""

    def __init__(self, predictor, tool_m, mount_rpy_deg=(0.0, 0.0, 0.0), lost_motion_rad=None,
                 coupling_c23_rad_per_Nm=0.0, take_up_Nm=None, law="smooth", friction_Nm=None):
        """``take_up_Nm`` (6,): the smooth law's take-up torque per joint
        (N*m), identified from a campaign; None: the fallback
        (model/transmission.fallback_take_up_Nm, from the compliance).
        ``law``: "smooth" (model/transmission.twist, single-valued) or
        "hysteretic" (model/play_hysteresis.py: the gear's position in its
        gap is a state, which ``dq`` does not keep: see ``play_dq``);
        ``friction_Nm`` (6,) the hysteretic law's friction inside the play
        (N*m), identified from a campaign; None: 1.5 % of the rated torque
        (model/transmission.gap_friction_Nm, from the compliance)."""
        if law not in PLAY_LAWS:
            raise ValueError(f"lost-motion law {law!r}: one of {', '.join(PLAY_LAWS)}")
        self._pred = predictor
        self.lost = None if lost_motion_rad is None or not np.any(np.asarray(lost_motion_rad) != 0) else \
            np.asarray(lost_motion_rad, dtype=float)
        self.law = law
        self.take_up = self.friction = None
        if self.lost is not None:
            self.take_up = (transmission.fallback_take_up_Nm(predictor.joint_compliance) if take_up_Nm is None
                            or not len(take_up_Nm) else np.asarray(take_up_Nm, dtype=float))
            if law == "hysteretic":
                self.friction = (transmission.gap_friction_Nm(1.0 / np.asarray(predictor.joint_compliance))
                                 if friction_Nm is None or not len(friction_Nm)
                                 else np.asarray(friction_Nm, dtype=float))
        self.c23 = float(coupling_c23_rad_per_Nm)
        R_mount = rpy_to_rotation(np.deg2rad(mount_rpy_deg))
        self._R_mount = tuple(R_mount.ravel().tolist())
        self._r_s = tuple((R_mount.T @ np.asarray(tool_m, dtype=float)).tolist())  # tool point, sensor frame
        self._identity_mount = bool(np.allclose(R_mount, np.eye(3), rtol=0.0, atol=0.0))

    def tool_wrench(self, process_wrench, q):
        """The wrench at the tool point (base frame, list of 6) for a process
        wrench in the sensor frame at joint angles q (rad)."""
        R = self._pred.pose(q)
        if not self._identity_mount:
            M = self._R_mount
            R = [R[3 * i] * M[j] + R[3 * i + 1] * M[3 + j] + R[3 * i + 2] * M[6 + j] for i in range(3) for j in range(3)]
        w = process_wrench.tolist() if hasattr(process_wrench, "tolist") else process_wrench
        return wrench_to_tool_base(R, self._r_s, w)

    def dq(self, process_wrench, q, static_torque=None):
        """The predicted joint deflection (rad, list or array); with lost
        motion, ``static_torque`` (6, N*m) is the torque the gears hold the
        arm with before the cut (gravity compensation's)."""
        tau = self.process_torque(process_wrench, q)
        if self.lost is None and not self.c23:
            return [c * t for c, t in zip(self._pred.joint_compliance_list, tau)]
        if self.hysteretic:
            raise ValueError("the hysteretic play law needs the gears' positions in their gaps: play_dq")
        static = np.zeros(6) if static_torque is None else static_torque
        return transmission.static_deflection(static, tau, self._pred.joint_compliance, self.lost, self.c23,
                                              self.take_up)

    @property
    def hysteretic(self):
        """Whether the model has play with the hysteretic law."""
        return self.lost is not None and self.law == "hysteretic"

    def process_torque(self, process_wrench, q):
        """J(q)^T W (6, N*m): the process load's joint torques."""
        return self._pred.joint_torques(q, self.tool_wrench(process_wrench, q))

    def play_positions(self, tau_process, static_torque, positions=None):
        """(6,) the gears' positions in their gaps (rad) after they carry
        ``static_torque - tau_process`` (N*m) from ``positions`` (None: at
        rest under it, the touch-off)."""
        carried = np.asarray(static_torque, dtype=float) - np.asarray(tau_process, dtype=float)
        if positions is None:
            return play_hysteresis.start(carried, self.lost)
        return play_hysteresis.step(positions, carried, self.lost, self.friction)

    def play_crossing(self, tau_process, static_torque, positions, rates, inertia_kgm2, dt_s):
        """(positions, rates) of the gears in their gaps after ``dt_s``
        carrying ``static_torque - tau_process``, each link crossing its gap
        with its inertia ``inertia_kgm2`` (model/play_hysteresis.crossing_step)."""
        carried = np.asarray(static_torque, dtype=float) - np.asarray(tau_process, dtype=float)
        return play_hysteresis.crossing_step(positions, rates, carried, self.lost, self.friction, inertia_kgm2, dt_s,
                                             soft_landing=True)

    def play_dq(self, tau_process, static_torque, positions, reference):
        """The predicted joint deflection (rad, (6,)) with the hysteretic
        law: the gears at ``positions`` in their gaps (``play_positions``),
        the touch-off's at ``reference``."""
        return play_hysteresis.deflection(static_torque, tau_process, positions, reference,
                                          self._pred.joint_compliance, self.lost, self.c23)


class Compensator:
    """The whole chain for a process that gets the sensor's samples and the
    controller's cycles as they come.

    ``sensor_sample(w)``: guard and filter, at the sensor's rate.
    ``tick(q, dt_s)``: once per controller cycle with the measured joint
    angles: the latest filtered wrench, gravity removal, prediction,
    saturation, ``delay_steps`` cycles of delay and the rate-limited
    correction (moving at most ``rate_limit * dt_s`` per joint).
    ``tick(q, dt_s, active=False)``: a fault: the correction ramps to zero
    at the same rate limit (never a jump, never a stale correction held).
    """

    def __init__(self, *, predictor, calibration, tool_m, filter_ba, max_jump_N, saturation_rad,
                 rate_limit_rad_per_s, delay_steps, initial_wrench, lost_motion_rad=None, coupling_c23_rad_per_Nm=0.0):
        self.remove_gravity = GravityRemover(calibration, predictor)
        self.model = DeflectionModel(predictor, tool_m, calibration.sensor_mount_rpy_deg or (0.0, 0.0, 0.0),
                                     lost_motion_rad, coupling_c23_rad_per_Nm)
        self.filter = SampleFilter(*filter_ba)
        self.max_jump_N = float(max_jump_N)
        self.saturation = [float(v) for v in np.broadcast_to(saturation_rad, 6)]
        self.rate = [float(v) for v in np.broadcast_to(rate_limit_rad_per_s, 6)]
        self.delay_steps = int(delay_steps)
        self.rejected = 0
        self.reseed(initial_wrench)

    def reseed(self, w):
        """Guard and filter settled on the wrench ``w`` (at the start, and
        after the sensor comes back from a fault)."""
        self.held = [float(v) for v in w]
        self.filter.reset(self.held)
        self.filtered = list(self.held)
        self._delay = deque([[0.0] * 6] * self.delay_steps)
        self.correction = getattr(self, "correction", [0.0] * 6)
        self.dq = [0.0] * 6
        self.process_wrench = [0.0] * 6

    def sensor_sample(self, w):
        """One raw sample (6 floats, sensor frame; NaN for a dropout).
        Returns whether the guard took it."""
        ok = guard_accepts(w, self.held, self.max_jump_N)
        if ok:
            self.held = list(w)
        else:
            self.rejected += 1
        self.filtered = self.filter.step(self.held)
        return ok

    def tick(self, q_rad, dt_s, active=True):
        """One controller cycle: the correction (list of 6, rad) to add to
        the joint reference."""
        step = [r * dt_s for r in self.rate]
        if not active:
            self.correction = rate_limited_step(self.correction, [0.0] * 6, step)
            return self.correction
        self.process_wrench = self.remove_gravity(self.filtered, q_rad)
        dq = self.model.dq(self.process_wrench, q_rad)
        self.dq = [min(s, max(-s, float(d))) for d, s in zip(dq, self.saturation)]
        if not all(math.isfinite(float(d)) for d in dq):
            # when in doubt, towards zero: a deflection not finite on any joint targets none on every joint
            # (min(s, max(-s, nan)) would be -s, a full saturation the arm would follow)
            self.dq = [0.0] * 6
        if self.delay_steps:
            self._delay.append(self.dq)
            dq_used = self._delay.popleft()
        else:
            dq_used = self.dq
        self.correction = rate_limited_step(self.correction, dq_used, step)
        return self.correction
