"""The compensator as a process: one EGM message in, one EGM answer out.

For every EgmRobot the controller sends (every 4 ms on an IRC5), the loop

1. reads the measured joint angles (motor side, what the encoders give);
2. takes every Net F/T record received since the last message through the
   wrench guard and the force filter (at the sensor's rate);
3. runs the chain of model/compensator.Compensator (gravity removal,
   deflection prediction, saturation, delay, rate-limited correction);
4. answers with joint targets = the joint reference at this moment + the
   correction (EGMRunJoint: the PC streams the path).

Faults.  Each is one log line when it starts and one when it ends, and
while any lasts the correction ramps to zero at the rate limit (never a
jump, never a stale correction held):

* the sensor is silent (no valid record for ``sensor_timeout_s``), or its
  records are invalid (status flags, a NaN burst) or rejected by the guard
  for that long; when it comes back, the guard and filter are reseeded on
  the new reading;
* the joint feedback is not finite for ``feedback_timeout_s``;
* the controller restarted (its sequence number or clock went back);
* a message of the wrong type or joint count (skipped, counted).

The rate limit acts on the controller's own clock (header.tm): a lost
message does not let the correction move by more than
``rate_limit * MAX_STEP_PERIODS * period`` in one answer.

Units: q and corrections in rad inside, degrees on the wire; wrenches in N
and N*m, sensor frame; times in s.
"""

import bisect
import math
import sys
import time
from dataclasses import dataclass, field

import numpy as np

from robstiff_drake.cell.egm import EgmMessageError, parse_robot_message
from robstiff_drake.errors import InputError, Terminated

# The correction may move by at most this many controller periods' worth
# of its rate limit in one answer, whatever the time since the last one.
MAX_STEP_PERIODS = 2.0


@dataclass
class LoopSettings:
    period_s: float = 0.004
    sensor_timeout_s: float = 0.02  # 5 IRC5 cycles without a valid record
    feedback_timeout_s: float = 0.02
    egm_timeout_s: float = 0.1  # "no message" log line after this
    idle_exit_s: float = 0.0  # end the run after this long without a message (0: never)
    duration_s: float = 0.0  # end the run after this long (0: never)
    rate_limit_rad_per_s: float = math.radians(5.0)


@dataclass
class LoopLog:
    """What the loop records, one row per answered message (see run_log.py)."""

    rows: list = field(default_factory=list)  # per cycle
    wrench: list = field(default_factory=list)  # per sensor record: (t_s, 6 values)
    events: list = field(default_factory=list)  # (t_s, text)
    compute_s: list = field(default_factory=list)
    age_s: list = field(default_factory=list)
    gaps_s: list = field(default_factory=list)  # time between consecutive messages
    gaps_over: int = 0  # messages that arrived more than 1.5 periods after the previous one (the controller's side)
    skipped: int = 0  # messages that arrived while the compensator was busy and were never answered
    late_answers: int = 0  # answers sent after the next message had arrived
    wrong_messages: int = 0


class Reference:
    """The joint reference (rad) against time since the EGM session started:
    a trajectory (times s, q (N, 6) rad), held at its ends; or a constant."""

    def __init__(self, times_s=None, q_rad=None):
        self.t = None if times_s is None else np.asarray(times_s, dtype=float)
        self.q = None if q_rad is None else np.asarray(q_rad, dtype=float).reshape(-1, 6)
        self._lists()

    def _lists(self):
        self._t = None if self.t is None else self.t.tolist()
        self._rows = None if self.q is None else self.q.tolist()

    def hold(self, q_rad):
        self.t = np.array([0.0])
        self.q = np.asarray(q_rad, dtype=float).reshape(1, 6)
        self._lists()

    def at(self, t_s):
        """q (list, rad) at t_s: linear between samples (scalar code: a
        few microseconds, not six numpy calls)."""
        t, rows = self._t, self._rows
        if t_s <= t[0] or len(t) == 1:
            return list(rows[0])
        if t_s >= t[-1]:
            return list(rows[-1])
        i = bisect.bisect_right(t, t_s) - 1
        f = (t_s - t[i]) / (t[i + 1] - t[i])
        a, b = rows[i], rows[i + 1]
        return [x + f * (y - x) for x, y in zip(a, b)]

    @property
    def duration_s(self):
        return float(self.t[-1])


class CompensatorLoop:
    """The loop over an EGM link and a sensor reader (``cell.egm.SensorLink``
    and ``cell.rdt.NetFTReader``, or stand-ins with the same methods)."""

    def __init__(self, compensator, link, sensor, reference, settings, *, log=None, out=sys.stderr):
        self.comp = compensator
        self.link = link
        self.sensor = sensor
        self.ref = reference
        self.s = settings
        self.log = log or LoopLog()
        self.out = out
        self.faults = {}  # name -> start time
        self.t_session = 0.0  # reference time (s): advanced on the controller's clock
        self.last_tm = None
        self.last_seq = None
        self.q = None
        self.t_q_good = None
        self.t_sensor_good = None
        self.t_sensor_rejecting = None
        self.t_sensor_invalid = None
        self.latest_sample_time = None
        self.t_start = None
        self.t_last_msg = None
        self.t_last_answer = 0.0
        self.pending_reseed = False

    # ------------------------------------------------------------ events

    def event(self, text):
        t = self.now()
        self.log.events.append((t, text))
        print(f"robstiff: compensate: t = {t:8.3f} s: {text}", file=self.out, flush=True)

    def now(self):
        return time.monotonic() - self.t_start if self.t_start is not None else 0.0

    def fault_on(self, name, text):
        if name not in self.faults:
            self.faults[name] = self.now()
            self.event(f"{text}; the correction ramps to zero")

    def fault_off(self, name, text):
        if name in self.faults:
            t0 = self.faults.pop(name)
            self.event(f"{text} (after {self.now() - t0:.3f} s)")

    # ------------------------------------------------------------ the start

    def first_message(self, timeout_s):
        """Wait for the controller's first message; InputError when none
        comes or it is not a usable EgmRobot (before the loop: exit 2)."""
        got = self.link.receive(timeout_s)
        if got is None:
            raise InputError(f"--egm-port {self.link.port}: no EGM message from the controller within {timeout_s:g} s "
                             "(is the RAPID program in EGMRunJoint, its UDP device pointing at this PC and port?)")
        data, t_arr = got
        try:
            seq, tm, joints, _ = parse_robot_message(data, self.link.pb2)
        except EgmMessageError as e:
            raise InputError(f"--egm-port {self.link.port}: the first message is not usable: {e}") from None
        if not all(math.isfinite(v) for v in joints):
            raise InputError(f"--egm-port {self.link.port}: the first message's joint feedback is not finite")
        return data, t_arr, seq, tm, np.radians(joints)

    # ------------------------------------------------------------ one cycle

    def _read_sensor(self, t_now):
        """Feed every record received since the last cycle to the chain."""
        records = self.sensor.drain()
        got_good = False
        for w, t_arr, status in records:
            finite = all(v == v for v in w)
            if finite and self.pending_reseed:
                self.comp.reseed(list(w))
                self.pending_reseed = False
                self.fault_off("sensor", "sensor: valid records again; guard and filter restarted on the new reading")
            accepted = self.comp.sensor_sample(list(w)) if not self.pending_reseed else False
            self.log.wrench.append((t_arr - self.t_start, *w))
            if not finite:
                self.t_sensor_invalid = t_arr
            if accepted:
                got_good = True
                self.t_sensor_good = t_arr
                self.t_sensor_rejecting = None
                self.latest_sample_time = t_arr
            elif finite and self.t_sensor_rejecting is None:
                self.t_sensor_rejecting = t_arr
        to = self.s.sensor_timeout_s
        if self.t_sensor_rejecting is not None and t_now - self.t_sensor_rejecting > to and records:
            # the guard has refused every sample for a while: the force really changed, or the sensor is bad
            self.fault_on("sensor", f"sensor: the guard rejected every sample for {to * 1e3:.0f} ms (a jump of more "
                                    f"than {self.comp.max_jump_N:g} N)")
            self.pending_reseed = True
            self.t_sensor_rejecting = None
        if not got_good and self.t_sensor_good is not None and t_now - self.t_sensor_good > to:
            invalid = self.t_sensor_invalid is not None and self.t_sensor_invalid >= self.t_sensor_good
            what = "invalid records (status flags or NaN), then none" if invalid else "no record"
            self.fault_on("sensor", f"sensor: {what} for {to * 1e3:.0f} ms")
            self.pending_reseed = True

    def _feedback(self, joints_deg, t_now):
        if all(math.isfinite(v) for v in joints_deg):
            self.q = [math.radians(v) for v in joints_deg]
            self.t_q_good = t_now
            self.fault_off("feedback", "EGM: finite joint feedback again")
        elif t_now - self.t_q_good > self.s.feedback_timeout_s:
            self.fault_on("feedback", f"EGM: joint feedback not finite for {self.s.feedback_timeout_s * 1e3:.0f} ms")

    def _clock(self, seq, tm):
        """Advance the reference time on the controller's clock; detect a restart."""
        T = self.s.period_s
        restarted = self.last_seq is not None and (seq < self.last_seq - 10 or (tm < self.last_tm and seq <= 2))
        if restarted:
            self.fault_on("restart", f"EGM: the controller restarted (sequence {seq} after {self.last_seq})")
            dt = T
        elif self.last_tm is None:
            dt = 0.0
        else:
            d = (tm - self.last_tm) * 1e-3
            dt = d if 0.0 < d <= 100 * T else T  # a clock without ms (tm = 0) or one that wrapped: nominal
        self.last_seq, self.last_tm = seq, tm
        self.t_session += dt
        return dt

    def cycle(self, data, t_arr):
        """One message: returns whether it was answered."""
        t_now = t_arr
        try:
            seq, tm, joints, _ = parse_robot_message(data, self.link.pb2)
        except EgmMessageError as e:
            self.log.wrong_messages += 1
            if self.log.wrong_messages <= 5 or self.log.wrong_messages % 1000 == 0:
                self.event(f"EGM: message skipped: {e} ({self.log.wrong_messages} so far)")
            return False
        dt = self._clock(seq, tm)
        if "restart" in self.faults and all(abs(c) < 1e-12 for c in self.comp.correction):
            self.fault_off("restart", "EGM: after the controller's restart the correction is zero; compensating again")
        self._feedback(joints, t_now)
        self._read_sensor(t_now)
        active = not self.faults
        step_dt = min(dt, MAX_STEP_PERIODS * self.s.period_s)
        corr = self.comp.tick(self.q, step_dt, active)
        q_ref = self.ref.at(self.t_session)
        target = [math.degrees(r + c) for r, c in zip(q_ref, corr)]
        self.link.send_joints(target)
        t_done = time.monotonic()
        self.log.compute_s.append(t_done - t_arr)
        self.t_last_answer = t_done
        age = t_done - self.latest_sample_time if self.latest_sample_time is not None else float("nan")
        self.log.age_s.append(age)
        self.log.rows.append((self.t_session, t_arr - self.t_start, *q_ref, *self.q, *corr, *self.comp.dq,
                              *self.comp.filtered, *self.comp.process_wrench, float(bool(self.faults)),
                              t_done - t_arr, age, seq))
        return True

    # ------------------------------------------------------------ the loop

    def run(self, first):
        """Run from the first message (``first_message``'s result) until the
        duration, an idle controller or an interrupt ends it."""
        data, t_arr, seq, tm, q0 = first
        newer = self.link.receive(0.0)  # the checks since the first message took time: start on the newest
        if newer is not None:
            data, t_arr = newer
        self.t_start = t_arr
        self.q = q0.tolist()
        self.t_q_good = t_arr
        self.t_sensor_good = t_arr
        self.t_last_msg = t_arr
        self.cycle(data, t_arr)
        T = self.s.period_s
        try:
            while True:
                got = self.link.receive(self.s.egm_timeout_s)
                now = time.monotonic()
                if self.s.duration_s and now - self.t_start >= self.s.duration_s:
                    break
                if got is None:
                    self.fault_on("egm", f"EGM: no message from the controller for {self.s.egm_timeout_s * 1e3:.0f} ms")
                    if self.s.idle_exit_s and now - self.t_last_msg > self.s.idle_exit_s:
                        self.event(f"EGM: no message for {self.s.idle_exit_s:g} s: the run ends")
                        break
                    continue
                data, t_arr = got
                gap = t_arr - self.t_last_msg
                self.log.gaps_s.append(gap)
                if gap > 1.5 * T:
                    self.log.gaps_over += 1
                if self.log.compute_s and self.t_last_answer > t_arr:
                    self.log.late_answers += 1
                self.t_last_msg = t_arr
                self.fault_off("egm", "EGM: messages again")
                self.cycle(data, t_arr)
        except KeyboardInterrupt:
            self.event("interrupted: the run ends")
        except Terminated:  # a service manager's stop: end the run and write its log, as on Ctrl-C
            self.event("terminated: the run ends")
        self.log.skipped = getattr(self.link, "skipped", 0)
        return self.log


def cycle_stats(log, period_s):
    """Median, p99 and largest computation time per message (ms), the
    correction's age (ms), missed cycles and the number of messages."""
    c = np.asarray(log.compute_s) * 1e3
    a = np.asarray(log.age_s) * 1e3
    a = a[np.isfinite(a)]
    g = np.asarray(log.gaps_s) * 1e3

    def q(x, p):
        return float(np.percentile(x, p)) if x.size else float("nan")

    return {"messages": int(c.size), "compute_ms": {"median": q(c, 50), "p99": q(c, 99), "max": float(c.max()) if c.size
                                                    else float("nan")},
            "correction_age_ms": {"median": q(a, 50), "p99": q(a, 99), "max": float(a.max()) if a.size else float("nan")},
            "message_gap_ms": {"median": q(g, 50), "p99": q(g, 99), "max": float(g.max()) if g.size else float("nan")},
            # a missed cycle: a message never answered (it came while the compensator was busy) or answered after
            # the next one had arrived
            "missed_cycles": int(log.skipped + log.late_answers), "controller_gaps": int(log.gaps_over),
            "over_budget": int(np.sum(c > period_s * 1e3)),
            "wrong_messages": int(log.wrong_messages), "sensor_records": len(log.wrench),
            "faults": [{"t_s": t, "event": e} for t, e in log.events]}
