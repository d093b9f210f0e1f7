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
the tests put a stand-in (``cell/stand_in_arm.ServoArmStandIn``).  No Drake in this module.
"""

import math
import time
from dataclasses import dataclass, field

import numpy as np

from robstiff_drake.cell.egm import ControllerLink
from robstiff_drake.cell.rdt import DEFAULT_COUNTS_PER_UNIT, RDTServer
from robstiff_drake.cell.safety import SUPERVISION_ACCEL  # the controller's motion supervision (cell/safety.py)

SPIN_S = 0.0005  # spin (do not sleep) for the last part of each cycle
TRANSPORT_DELAY_CYCLES = 0


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
    stop_reason: str = ""  # why the simulated controller stopped before the run's end ("" : it did not)
    t_stop: float = float("nan")  # when (s of the cut, from engagement)
    last_answer_t: float = float("nan")  # the last answer's time (s of the cut)
    refused: int = 0  # targets the controller's supervision refused
    late_answers: int = 0  # ticks that took an answer to an older message (the one due came late)
    answered: int = 0  # EGM messages followed by an answer before the next one
    unanswered: int = 0
    # of ``unanswered``, those since the last answer: a run whose compensator stopped on purpose (its
    # --duration-s) while this controller streams on ends with them; a gap it answered after is not among them
    trailing_unanswered: int = 0
    late_ticks: int = 0  # ticks sent more than half a period late
    # per unanswered tick (the first MAX_DETAIL): (tick k, ms from the send of the message whose answer was due
    # to this tick: the time the compensator had, a period or two at a hard real-time controller; ms that
    # message left after its own schedule: this simulated controller's lateness, not the compensator's)
    unanswered_detail: list = field(default_factory=list)
    MAX_DETAIL = 1000
    skipped_ticks: int = 0  # periods the schedule slipped because the loop was more than a period late
    tick_error_s: list = field(default_factory=list)
    step_ms: list = field(default_factory=list)  # the station's computation per engaged cycle (ms)
    t: list = field(default_factory=list)
    q_cmd: list = field(default_factory=list)  # rad
    q_meas: list = field(default_factory=list)  # rad
    extra: list = field(default_factory=list)  # what the station reports (its `last_info`), per cycle

    def lost_fraction(self):
        """The controller's side of the compensation lost: the share of the
        engaged cycles that ran on a stale target (late or held)."""
        n = self.answered + self.unanswered + self.late_answers
        return (self.unanswered + self.late_answers) / n if n else 0.0


class CellNetwork:
    """The cell's network side: every period an EgmRobot to the compensator
    and the sensor's records as RDT, the station stepped with the newest
    joint targets.

    ``lockstep``: once engaged, step only when the answer to the last
    message has come (waiting up to ``answer_timeout_s``; none by then ends
    the run), and never sooner than a period after the last step: the
    loop's physics without this machine's scheduling (a Python thread on
    shared cores is no hard real-time controller), at a controller's pace
    or slower.  The controller's clock (header.tm) still
    advances by one period per message.

    ``spread_records``: in real time (not lockstep once engaged), a cycle's
    sensor records leave at their own instants, one every period / n (a Net
    F/T streams each record as it samples it: every 1 ms at 1 kHz, in no
    phase with the controller's cycle), the first at the tick; the default
    sends them together just before the controller's message (lockstep
    needs them in before it), so that the compensator's reader thread wakes
    with its loop at every message, which a real cell's does not."""

    def __init__(self, station, *, egm_to, netft_port, period_s=0.004, faults=None, netft_host="127.0.0.1",
                 lockstep=False, answer_timeout_s=1.0, limits=None, netft_http_port=None, netft_units=("N", "N-m"),
                 netft_counts=None, link=None, transport_delay_cycles=None, spread_records=False):
        """``limits``: (lower deg, upper deg, axis speed deg/s) of the
        robot (controller convention): a target outside the working
        ranges, or one further from the last than the axis speed allows in
        a period, stops the controller (its motion supervision) and the
        run; None: no supervision.  ``answer_timeout_s``: once engaged, no
        answer for this long stops the controller (EGM's CommTimeout)."""
        self.station = station
        # the transport delay (cycles) from a message to the tick its answer
        # acts at, beyond the next one (see ``run``; TRANSPORT_DELAY_CYCLES)
        self.delay_cycles = TRANSPORT_DELAY_CYCLES if transport_delay_cycles is None else int(transport_delay_cycles)
        self.limits = None if limits is None else tuple(np.asarray(x, dtype=float) for x in limits)
        self._q_prev = None  # the target before the last (deg), for the acceleration supervision
        self.lockstep = bool(lockstep)
        self.spread_records = bool(spread_records)
        self._pending = []  # (time due on this PC's clock, record row, fault clock) of a spread cycle's records
        self.answer_timeout_s = float(answer_timeout_s)
        self.period_s = float(period_s)
        self.faults = faults or Faults()
        self.egm = link or ControllerLink(*egm_to)
        counts = netft_counts or (DEFAULT_COUNTS_PER_UNIT, DEFAULT_COUNTS_PER_UNIT)
        try:
            self.rdt = RDTServer(netft_port, host=netft_host, counts_per_force=counts[0], counts_per_torque=counts[1],
                                 units=netft_units, http_port=netft_http_port)
        except BaseException:
            self.egm.close()
            raise
        self.netft_port = self.rdt.port
        self.rng = np.random.default_rng(self.faults.seed)
        self.stats = NetworkStats()
        self.stop = False  # set from another thread to end run()

    def close(self):
        self.egm.close()
        self.rdt.close()

    def refuse(self, targets_deg, q_cmd_deg):
        """Why the controller's supervision refuses ``targets_deg`` after
        ``q_cmd_deg`` (None: it follows them): outside the working ranges,
        a step faster than the axis speed, or (with acceleration limits) a
        change of the step beyond SUPERVISION_ACCEL times the acceleration
        limit."""
        if self.limits is None:
            return None
        lo, hi, speed = self.limits[:3]
        acc = self.limits[3] if len(self.limits) > 3 else None
        t = np.asarray(targets_deg, dtype=float)
        if not np.all(np.isfinite(t)):
            return "a target that is not a finite number"
        out = np.flatnonzero((t < lo - 1e-6) | (t > hi + 1e-6))
        if out.size:
            j = int(out[0])
            return f"q{j + 1} target {t[j]:.4g} deg outside the working range [{lo[j]:g}, {hi[j]:g}] deg"
        step = np.abs(t - q_cmd_deg)
        fast = np.flatnonzero(step > speed * self.period_s + 1e-6)
        if fast.size:
            j = int(fast[0])
            return (f"q{j + 1} target {step[j]:.4g} deg from the last in one {self.period_s * 1e3:g} ms cycle "
                    f"(the axis speed {speed[j]:g} deg/s allows {speed[j] * self.period_s:.4g})")
        if acc is not None and self._q_prev is not None:
            a = np.abs(t - 2.0 * q_cmd_deg + self._q_prev) / self.period_s**2
            hard = np.flatnonzero(a > SUPERVISION_ACCEL * acc)
            if hard.size:
                j = int(hard[0])
                return (f"q{j + 1} accelerates at {a[j]:.4g} deg/s^2 between targets, more than "
                        f"{SUPERVISION_ACCEL:g} x its {acc[j]:g} deg/s^2 limit")
        return None

    def _send_wrench(self, w, t, t_tick=None):
        """The cycle's records ``w`` (rows) at the fault clock ``t``: all now, or (``t_tick``: spread_records)
        the first now and the others queued for t_tick + i period / n (sent by _wait_sending)."""
        rows = np.atleast_2d(np.asarray(w, dtype=float))
        if t_tick is None:
            for row in rows:
                self._send_row(row, t)
            return
        self._send_row(rows[0], t)
        n = len(rows)
        self._pending += [(t_tick + i * self.period_s / n, rows[i], t) for i in range(1, n)]

    def _send_row(self, row, t):
        f = self.faults
        if f.inside(f.sensor_silent, t):
            self.rdt.ft_sequence += 1
            return
        row = row.copy()
        if any(abs(t - ts) < 0.5 * self.period_s for ts in f.sensor_spikes):
            row[0] += f.spike_N
        status = 0x80020000 if f.inside(f.sensor_invalid, t) else 0
        raw = b"\x12\x34garbage" if f.rdt_wrong_header else None
        self.rdt.send(row.tolist(), status, raw)

    def _send_due(self, now):
        """The queued records due by ``now`` (this PC's monotonic clock), in order."""
        pending = self._pending
        while pending and pending[0][0] <= now:
            _, row, t = pending.pop(0)
            self._send_row(row, t)

    def _wait_sending(self, t_until):
        """Wait until ``t_until`` (this PC's monotonic clock: sleep, then spin for the last SPIN_S), sending the
        queued records as they fall due (slept to, not spun)."""
        pending = self._pending
        while True:
            now = time.monotonic()
            self._send_due(now)
            if now >= t_until:
                return
            if pending and pending[0][0] < t_until - SPIN_S:
                time.sleep(pending[0][0] - now)  # (a record's instant: a sleep's lateness is its jitter)
            elif t_until - now > SPIN_S:
                time.sleep(t_until - now - SPIN_S)

    def _collect(self, answers):
        for km, targets in self.egm.answers():
            if km is not None:
                answers[km] = targets

    def run(self, duration_s, q_start_rad, cut_s=None):
        """Run for ``duration_s`` (s) of real time from ``q_start_rad``
        (``cut_s``: or until this much of the controller's time has passed
        once engaged: a lockstep run's length whatever this machine's load).

        Tick k: the answer to message k - 1 - D (D: the transport delay in
        cycles) is the target of the period k -> k+1 (none: the last target
        is held, the cycle is late or unanswered); the station is stepped
        with it and message k carries the state it reaches.  In lockstep
        the tick waits for that answer instead of the wall clock."""
        f = self.faults
        T = self.period_s
        D = self.delay_cycles
        st = self.stats
        q_cmd = np.asarray(q_start_rad, dtype=float).copy()
        t0 = time.monotonic()
        k = 0
        restarted = False
        engaged, t_eng = False, 0.0
        t_stepped = 0.0  # (this PC's clock at the last tick)
        k_clock = 0  # the tick the controller's clock (header.tm) counts from: 0, or the last restart's
        answers = {}  # message k -> targets (deg) received
        sent_at = {}  # message k -> (this PC's clock when it left, s after its schedule): the last few
        dropped = set()  # messages lost on the way (nothing to answer)
        hold = getattr(self.station, "hold", None)
        while True:
            t_tick = t0 + k * T
            now = time.monotonic()
            if self.stop or now - t0 >= duration_s or (cut_s is not None and engaged and k * T - t_eng >= cut_s):
                break
            stepped = self.lockstep and engaged
            if stepped and t_stepped + T > now:
                # lockstep is never faster than real time either (a tick at least a period after the last,
                # no burst after a stall): the sensor's records and the compensator's clocks keep a
                # controller's pace, whatever this machine's load
                time.sleep(t_stepped + T - now)
            if not stepped:
                self._wait_sending(t_tick)
            self._send_due(math.inf)  # (a spread cycle's records left when lockstep took over: now, in order)
            t_stepped = time.monotonic()
            t = k * T if stepped else t_stepped - t0
            st.tick_error_s.append(t - k * T)
            if t - k * T > 0.5 * T:
                st.late_ticks += 1
                if t - k * T > T:
                    # more than a period behind: the schedule slips (no burst to catch up, and no
                    # cycles stepped through unannounced).  A real controller is never late; this
                    # simulated one only stretches its time, and its messages' clock (header.tm)
                    # still advances by one period per message, as the station does.
                    n_skip = int((t - k * T) / T)
                    st.skipped_ticks += n_skip
                    t0 += n_skip * T
                    t -= n_skip * T
            self.rdt.poll()
            need = k - 1 - D  # the message whose answer is due now
            q_before = q_cmd.copy()
            self._collect(answers)
            last = k - 1  # lockstep: the answer to the last message sent before the station moves on
            if stepped and last not in answers and last not in dropped and last >= 0 and last >= need:
                t_wait = time.monotonic() + self.answer_timeout_s
                while last not in answers and time.monotonic() < t_wait and not self.stop:
                    self.egm.wait(min(0.05, max(t_wait - time.monotonic(), 0.0)))
                    self._collect(answers)
                if self.stop:
                    break  # the run's end (the pass is over), not the compensator's silence
                if last not in answers:
                    st.stop_reason = (f"no answer from the compensator for {self.answer_timeout_s:g} s after "
                                      f"t = {st.last_answer_t:.3f} s of the cut")
                    st.t_stop = st.last_answer_t
                    break
            # the newest answer to a message up to `need` (a controller takes the latest target it has;
            # an answer to an older message than `need` came late), answers to later ones wait their tick
            usable = [km for km in answers if km <= need]
            targets, fresh = None, False
            if usable:
                km = max(usable)
                targets, fresh = answers[km], km == need
                for x in usable:
                    answers.pop(x)
            if engaged and not fresh and need not in dropped:
                # lockstep waited for the last message's answer: none to `need` and none newer is the
                # compensator's silence; a newer one in hand is a message it skipped (one that answers only
                # the newest after a stall, as compensate does), a cycle unanswered as a controller counts it
                silent = stepped and not answers
                if targets is None and (silent or t - t_eng - st.last_answer_t > self.answer_timeout_s):
                    st.stop_reason = (f"no answer from the compensator for {self.answer_timeout_s:g} s after "
                                      f"t = {st.last_answer_t:.3f} s of the cut")
                    st.t_stop = st.last_answer_t
                    break  # the compensator stopped answering (EGM's CommTimeout)
                if targets is None:
                    st.unanswered += 1
                    st.trailing_unanswered += 1
                    if need in sent_at and len(st.unanswered_detail) < st.MAX_DETAIL:
                        t_sent, late = sent_at[need]
                        st.unanswered_detail.append((k, (t_stepped - t_sent) * 1e3, late * 1e3))
                else:
                    st.late_answers += 1
            dropped.discard(need)
            if targets is not None:
                why = self.refuse(targets, np.degrees(q_cmd))
                if why is not None:
                    st.refused += 1
                    st.stop_reason = f"the controller refused a target: {why}"
                    st.t_stop = t - t_eng if engaged else 0.0
                    break  # the controller's motion supervision stops the robot
                q_cmd = np.radians(targets)
                if not engaged:
                    engaged, t_eng = True, t
                elif fresh:
                    st.answered += 1
                st.last_answer_t = t - t_eng
                st.trailing_unanswered = 0
            self._q_prev = np.degrees(q_before) if engaged else None  # the command of the tick before
            te = t - t_eng if engaged else -1.0  # fault clock
            t_s0 = time.perf_counter()
            q_meas, w = self.station.step(q_cmd) if engaged or hold is None else hold()
            if engaged:
                st.step_ms.append((time.perf_counter() - t_s0) * 1e3)
            self._send_wrench(w, te, t_tick if self.spread_records and not stepped else None)
            if f.restart_at >= 0 and not restarted and te >= f.restart_at:
                restarted = True
                self.egm.restart()
                pause_until = t_tick + f.restart_pause_s
                if stepped:
                    # a restart is silent on every clock: in lockstep the pause passes on this PC's clock too
                    # (before, the controller's clock jumped with one period of silence here, which a compensator
                    # rightly takes for a time stamp that jumped, not a restart: it refused the new session)
                    t_stepped = time.monotonic() + f.restart_pause_s - T
                k = int(math.ceil((pause_until - t0) / T))
                k_clock = k
                answers.clear()
                dropped.update(range(k - 2 - D, k))
                continue
            q_deg = np.degrees(q_meas)
            if f.inside(f.egm_nan, te):
                q_deg = np.full(6, np.nan)
            joints = list(q_deg)[: f.egm_joints] + [0.0] * max(0, f.egm_joints - 6)
            drop = engaged and ((f.egm_drop_every and k % f.egm_drop_every == f.egm_drop_every - 1) or
                                (f.egm_drop_probability and self.rng.random() < f.egm_drop_probability))
            if not drop:
                # stamped with the cycle's own time: an IRC5 runs its 4 ms cycle in hard real time,
                # only this simulation's ticks jitter (stamping the wall clock made the targets'
                # spacing, and so the servo's velocity feed-forward, jitter by a millisecond)
                self.egm.send_state(k, joints, np.degrees(q_cmd), (k - k_clock) * T * 1e3, f.egm_wrong_type)
                t_sent = time.monotonic()
                sent_at[k] = (t_sent, t_sent - t0 - k * T)
                sent_at.pop(k - 8 - D, None)
            else:
                self.egm.skip()
                dropped.add(k)  # nothing to answer
            st.cycles += 1
            st.t.append(t)
            st.q_cmd.append(q_cmd.copy())
            st.q_meas.append(np.asarray(q_meas, dtype=float).copy())
            st.extra.append(getattr(self.station, "last_info", None))
            k += 1
        return self.stats
