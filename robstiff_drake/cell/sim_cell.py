"""The simulated cell's network side: a station (anything with
``step(q_cmd_rad) -> (q_measured_rad, wrench_sensor)``, advanced one EGM
cycle per call) behind the two protocols a real cell speaks:

* the controller's EGM role: every ``period_s`` an EgmRobot to the
  compensator (feedBack.joints: the measured joint angles, motor side;
  planned.joints: the joint command in force), and the EgmSensor joint
  targets it answers are the next step's command (EGMRunJoint: the robot
  follows the PC).  Until the first answer the robot stands at its start
  position: the station's optional ``hold() -> (q_measured_rad,
  wrench_sensor)`` is called instead of ``step`` (a station without it
  is stepped with the start position);
* the Net F/T's RDT role: on a start request, every wrench sample the
  station returns is streamed as an RDT record (``wrench_sensor`` is one
  sample (6,) or the (k, 6) samples the sensor took during the cycle).

``CellNetwork.run`` keeps the cycle in real time (sleep, then a short spin
for the last half millisecond) and injects the faults of ``Faults``.
``robstiff sim-cell`` puts the Drake station here (see docs/real_cell.md);
the tests put a stand-in (``ServoArmStandIn``).  No Drake in this module.
"""

import math
import time
from dataclasses import dataclass, field

import numpy as np

from robstiff_drake.cell.egm import ControllerLink
from robstiff_drake.cell.rdt import RDTServer

SPIN_S = 0.0005  # spin (do not sleep) for the last part of each cycle


@dataclass
class Faults:
    """Faults to inject (times in s from when the compensator engaged: its
    first answer; the message faults act from the start)."""

    egm_drop_every: int = 0  # drop every n-th EgmRobot (0: none)
    egm_drop_probability: float = 0.0
    seed: int = 0
    sensor_silent: tuple = ()  # (t0, t1): no RDT record
    sensor_invalid: tuple = ()  # (t0, t1): records with a serious status (the sensor's "not a valid measurement")
    sensor_spikes: tuple = ()  # times of one-sample force spikes
    spike_N: float = 3000.0
    egm_nan: tuple = ()  # (t0, t1): joint feedback NaN
    restart_at: float = -1.0  # the controller restarts (sequence and clock from zero) after a pause
    restart_pause_s: float = 0.2
    rdt_wrong_header: bool = False  # answer with records that are not RDT
    egm_wrong_type: bool = False  # send EgmRobot with mtype MSGTYPE_COMMAND
    egm_joints: int = 6  # joints in the feedback

    def inside(self, window, t):
        return bool(window) and window[0] <= t < window[1]


@dataclass
class NetworkStats:
    cycles: int = 0
    answered: int = 0  # EGM messages followed by an answer before the next one
    unanswered: int = 0
    late_ticks: int = 0  # ticks sent more than half a period late
    skipped_ticks: int = 0  # periods the schedule slipped because the loop was more than a period late
    tick_error_s: list = field(default_factory=list)
    t: list = field(default_factory=list)
    q_cmd: list = field(default_factory=list)  # rad
    q_meas: list = field(default_factory=list)  # rad
    extra: list = field(default_factory=list)  # what the station reports (its `last_info`), per cycle


class CellNetwork:
    """The cell's network side: every period an EgmRobot to the compensator
    and the sensor's records as RDT, the station stepped with the newest
    joint targets.

    ``lockstep``: once engaged, step only when the answer to the last
    message has come (waiting up to ``answer_timeout_s``; none by then ends
    the run), not on the wall clock: the loop's physics without this
    machine's scheduling (a Python thread on shared cores is no hard
    real-time controller).  The controller's clock (header.tm) still
    advances by one period per message."""

    def __init__(self, station, *, egm_to, netft_port, period_s=0.004, faults=None, netft_host="127.0.0.1",
                 lockstep=False, answer_timeout_s=1.0):
        self.station = station
        self.lockstep = bool(lockstep)
        self.answer_timeout_s = float(answer_timeout_s)
        self.period_s = float(period_s)
        self.faults = faults or Faults()
        self.egm = ControllerLink(*egm_to)
        self.rdt = RDTServer(netft_port, host=netft_host)
        self.netft_port = self.rdt.port
        self.rng = np.random.default_rng(self.faults.seed)
        self.stats = NetworkStats()
        self.stop = False  # set from another thread to end run()

    def close(self):
        self.egm.close()
        self.rdt.close()

    def _send_wrench(self, w, t):
        f = self.faults
        rows = np.atleast_2d(np.asarray(w, dtype=float))
        for row in rows:
            if f.inside(f.sensor_silent, t):
                self.rdt.ft_sequence += 1
                continue
            row = row.copy()
            if any(abs(t - ts) < 0.5 * self.period_s for ts in f.sensor_spikes):
                row[0] += f.spike_N
            status = 0x80020000 if f.inside(f.sensor_invalid, t) else 0
            raw = b"\x12\x34garbage" if f.rdt_wrong_header else None
            self.rdt.send(row.tolist(), status, raw)

    def run(self, duration_s, q_start_rad):
        """Run for ``duration_s`` (s) of real time from ``q_start_rad``."""
        f = self.faults
        T = self.period_s
        q_cmd = np.asarray(q_start_rad, dtype=float).copy()
        t0 = time.monotonic()
        k = 0
        answered_since_last = True
        restarted = False
        engaged, t_eng = False, 0.0
        k_clock = 0  # the tick the controller's clock (header.tm) counts from: 0, or the last restart's
        hold = getattr(self.station, "hold", None)
        while True:
            t_tick = t0 + k * T
            now = time.monotonic()
            if self.stop or now - t0 >= duration_s:
                break
            stepped = self.lockstep and engaged
            if not stepped and t_tick - now > SPIN_S:
                time.sleep(t_tick - now - SPIN_S)
            while not stepped and time.monotonic() < t_tick:
                pass
            t = k * T if stepped else time.monotonic() - t0
            self.stats.tick_error_s.append(t - k * T)
            if t - k * T > 0.5 * T:
                self.stats.late_ticks += 1
                if t - k * T > T:
                    # more than a period behind: the schedule slips (no burst to catch up, and no
                    # cycles stepped through unannounced).  A real controller is never late; this
                    # simulated one only stretches its time, and its messages' clock (header.tm)
                    # still advances by one period per message, as the station does.
                    n_skip = int((t - k * T) / T)
                    self.stats.skipped_ticks += n_skip
                    t0 += n_skip * T
                    t -= n_skip * T
            self.rdt.poll()
            targets = self.egm.receive_targets(self.answer_timeout_s if stepped else 0.0)
            if stepped and targets is None and not answered_since_last:
                break  # the compensator stopped answering
            if targets is not None:
                q_cmd = np.radians(targets)
                answered_since_last = True
                if not engaged:
                    engaged, t_eng = True, t
            te = t - t_eng if engaged else -1.0  # fault clock
            if k > 0 and engaged:
                if answered_since_last:
                    self.stats.answered += 1
                else:
                    self.stats.unanswered += 1
            answered_since_last = False
            q_meas, w = self.station.step(q_cmd) if engaged or hold is None else hold()
            self._send_wrench(w, te)
            if f.restart_at >= 0 and not restarted and te >= f.restart_at:
                restarted = True
                self.egm.restart()
                pause_until = t_tick + f.restart_pause_s
                k = int(math.ceil((pause_until - t0) / T))
                k_clock = k
                answered_since_last = True
                continue
            q_deg = np.degrees(q_meas)
            if f.inside(f.egm_nan, te):
                q_deg = np.full(6, np.nan)
            joints = list(q_deg)[: f.egm_joints] + [0.0] * max(0, f.egm_joints - 6)
            drop = engaged and ((f.egm_drop_every and k % f.egm_drop_every == f.egm_drop_every - 1) or
                                (f.egm_drop_probability and self.rng.random() < f.egm_drop_probability))
            if not drop:
                mtype = self.egm.pb2.EgmHeader.MSGTYPE_COMMAND if f.egm_wrong_type else None
                # stamped with the cycle's own time: an IRC5 runs its 4 ms cycle in hard real time,
                # only this simulation's ticks jitter (stamping the wall clock made the targets'
                # spacing, and so the servo's velocity feed-forward, jitter by a millisecond)
                self.egm.send(self.egm.robot_message(joints, np.degrees(q_cmd), mtype, tm_ms=(k - k_clock) * T * 1e3))
            else:
                self.egm.seqno += 1
                answered_since_last = True  # nothing to answer
            self.stats.cycles += 1
            self.stats.t.append(t)
            self.stats.q_cmd.append(q_cmd.copy())
            self.stats.q_meas.append(np.asarray(q_meas, dtype=float).copy())
            self.stats.extra.append(getattr(self.station, "last_info", None))
            k += 1
        return self.stats


class ServoArmStandIn:
    """A stand-in for the Drake station in tests: the arm's motor angles
    follow the command through a first-order servo lag, the links deflect
    by the true joint compliance under a process wrench on the tool, and
    the wrist sensor reads the payload's weight, its bias and the process
    wrench (sensor frame), with Gaussian noise, ``sensor_samples`` times a
    cycle.

    ``process_wrench(t)`` -> (force N, moment N*m about the tool point),
    base frame.  ``reference(t)`` -> the joint reference (rad) the
    compensator streams; ``last_info``: (t, the tool point's error against
    the reference's tool point (m, base frame), 3 values)."""

    def __init__(self, *, robot, joint_stiffness_Nm_per_rad, calibration, process_wrench, reference,
                 q_start_rad, period_s=0.004, servo_lag_s=0.01, sensor_samples=4, noise_N=0.5, noise_Nm=0.05,
                 seed=0):
        from robstiff_drake.model.realtime import DeflectionPredictor

        self.kin = DeflectionPredictor(robot.dh, joint_stiffness_Nm_per_rad, robot.payload.tool_point_m)
        self.tool = tuple(float(v) for v in robot.payload.tool_point_m)
        self.cal = calibration
        self.W = process_wrench
        self.ref = reference
        self.T = float(period_s)
        self.alpha = 1.0 - math.exp(-self.T / servo_lag_s)
        self.theta = np.asarray(q_start_rad, dtype=float).copy()
        self.n = int(sensor_samples)
        self.noise = np.array([noise_N] * 3 + [noise_Nm] * 3)
        self.rng = np.random.default_rng(seed)
        self.k = 0
        self.last_info = None

    def hold(self):
        """At rest before EGM engages: the start pose, no process load, the clock stopped."""
        return self.theta.copy(), self._sensor(self.theta, np.zeros(6))

    def _sensor(self, q_link, W):
        from robstiff_drake.model.payload import payload_wrench
        from robstiff_drake.model.wrench_frames import to_sensor_frame

        R, _ = self.kin.flange_rotation_and_tool_point(q_link)
        w_sensor = payload_wrench(R, self.cal) + np.array(to_sensor_frame(R.ravel().tolist(), self.tool, W.tolist()))
        return w_sensor + self.rng.standard_normal((self.n, 6)) * self.noise

    def step(self, q_cmd_rad):
        t = self.k * self.T
        self.k += 1
        self.theta = self.theta + self.alpha * (np.asarray(q_cmd_rad, dtype=float) - self.theta)
        W = np.asarray(self.W(t), dtype=float)
        dq, _ = self.kin(self.theta, W)
        q_link = self.theta + dq
        _, p = self.kin.flange_rotation_and_tool_point(q_link)
        _, p_ref = self.kin.flange_rotation_and_tool_point(np.asarray(self.ref(t), dtype=float))
        self.last_info = (t, *(p - p_ref).tolist())
        return self.theta.copy(), self._sensor(q_link, W)
