"""The compensator as a process: one controller message in, one answer out.

For every message the controller sends (every 4 ms on an IRC5; RSI 4 or
12 ms; Stream Motion its own cycle) from the configured controller only
(cell/link.py drops anyone else's), the loop

1. checks the sequence number and clock (cell/session.py, its faults
   cell/session_faults.py): a duplicate or
   an older datagram is dropped unanswered; a jump or a clock that
   disagrees with the sequence is a fault; the reference advances by a
   bounded step, its time never ahead of the sequence's nor (but for
   the stamps' 2 ms and a stop's lead, cell/reference_rate.py: one step a
   period on an honest clock, a stalled clock's stop and restart within
   the robot's accelerations) of the controller's clock since the run's
   start;
2. reads the measured joint angles (the controller's degrees, mapped to
   the model's joints through the robot file's ``controller:`` block);
3. takes every Net F/T record received since the last message through
   the guard (int32-clipped records and moment spikes refused and
   counted) and the force filter;
4. runs model/compensator.Compensator (gravity removal, deflection
   prediction, saturation, delay, rate limit) and maps the correction to
   the controller's joints;
5. answers with target = reference(t) + correction through the link's one
   send path (cell/safety.py's check: working ranges, the reference and
   the arm's feedback); a refused target is never sent: a fault, the last
   safe target instead (or nothing), and the correction ramps down.

Faults.  Each is one log line when it starts and one when it ends, and
while any lasts the correction ramps to zero at the rate limit (never a
jump, never a stale correction held): the correction moving the tool
beyond its bound (cell/correction_bound.py); the sensor silent, invalid,
clipped or rejected by the guard for ``sensor_timeout_s`` (silent: on
this PC's clock and on the controller's), or with no valid record of that
age at the first message (cell/sensor_intake.py); its reading at the
start beyond the payload calibration's prediction, its record rate off
the configured one (cell/sensor_checks.py: both for the session); feedback not
finite or outside the working ranges; the controller silent; its sequence
or clock inconsistent (cleared after ``CLEAR_MESSAGES`` consistent
messages once the correction is zero); a target refused.

Units: q and corrections in rad inside (the model's joints), controller
degrees on the wire; wrenches in N and N*m, sensor frame; times in s.
"""

import math
import sys
import time

import numpy as np

from robstiff_drake.cell.correction_bound import CorrectionBound, bounded
from robstiff_drake.cell.health import Counters
from robstiff_drake.cell.loop_settings import LoopSettings  # noqa: F401 (tests and benchmarks import it here)
from robstiff_drake.cell.loop_stats import loop_stats
from robstiff_drake.cell.realtime_thread import collect_if_due
from robstiff_drake.cell.reference import Reference  # noqa: F401 (the loop's reference; commands import it here)
from robstiff_drake.cell.reference_rate import ReferenceRate
from robstiff_drake.cell.safety import Envelope, UnsafeTarget, clamp_deg, pose_limits_deg, pose_problem_within, \
    supervision_tolerances
from robstiff_drake.cell.sensor_checks import SensorChecks
from robstiff_drake.cell.sensor_intake import SensorIntake
from robstiff_drake.cell.session import SessionClock
from robstiff_drake.cell.session_faults import CLEAR_MESSAGES, SessionFaults
from robstiff_drake.cell.start_gate import LoopStart
from robstiff_drake.errors import Terminated

# The correction may move by at most this many controller periods' worth
# of its rate limit in one answer, whatever the time since the last one.
MAX_STEP_PERIODS = 2.0
STALE_PERIODS = 3.0  # a correction computed from a wrench older than this many periods is stale
START_BACKLOG_S = 1.0  # the most of the controller's messages (s of its clock) waiting at the start not counted late


class CompensatorLoop(LoopStart, SensorIntake, SensorChecks, SessionFaults):
    """The loop over a controller link (cell/link.PCLink) and a sensor
    reader (cell/rdt.NetFTReader, or stand-ins with the same methods)."""

    def __init__(self, compensator, link, sensor, reference, robot, settings, *, log=None, out=sys.stderr,
                 preview=None, start_jobs=()):
        settings = settings.resolved(compensator, robot)  # (the defaults that depend on the arm: max_jump_Nm)
        self.comp, self.link, self.sensor, self.ref, self.robot, self.s = (compensator, link, sensor, reference,
                                                                            robot, settings)
        self.preview = preview  # cell/preview_table.PreviewDeflection (the chain's model) or None: plain
        self.pending_preview = None  # cell/preview_job.BackgroundTable: the table on its way (plain meanwhile)
        self.log = log  # run_log.StreamLog or None
        # the start's slow work ([(what, function)]: cell/start_gate.py; the log folder's start is added), run
        # off this thread while the loop answers with zero correction; ``gate`` None once it has passed
        self.start_jobs = list(start_jobs)
        self.gate = None
        self._wrench_rows = []  # this cycle's sensor records for the log, written after the answer
        self.out = out
        self.end_hold = None  # cell/end_hold.EndHold: a stop request held once the loop has ended (the command's)
        self.n = Counters()
        self.clock = SessionClock(settings.period_s)
        # this PC's clock (s): every read the loop makes of it (the arrival stamps come with the messages and
        # records, on the same clock); time.monotonic, or a test's scripted clock, so that its verdicts do not
        # depend on where this PC's clock happens to stand
        self.pc_time = time.monotonic
        self.faults = {}  # name -> start time
        # (cell/session_faults.py: the clock faults in a row stepping alike, [step ms, sequence's ms, count] or
        # None, and whether the wrong --period-ms they show has been said: once a run)
        self._steady, self._wrong_period_said = None, False
        # (cell/session_faults.py ``_watch_cycle``, a link whose sequence is its clock over the period (RSI): the
        # last clock seen, the run of its steps alike, and the controller's cycle in periods once named, else 1)
        self._cycle_tm, self._cycle_run, self._cycle_periods = None, None, 1.0
        self.ok_since_fault = 0
        self.t_session = 0.0  # the controller's time since the session's start (s; cell/session.py)
        # the reference's played time (s): the session's allowance through the rate bounded by the robot's
        # accelerations (cell/reference_rate.py; None: no limits, or a held reference: the allowance as it is)
        self.t_ref = 0.0
        self.rate = ReferenceRate.of(settings.period_s, robot, reference, say=self.event)
        self.q = None  # the model's joint angles (rad)
        self.q_deg = None  # the controller's (deg)
        self.t_q_good = self.t_sensor_good = self.t_sensor_rejecting = self.t_sensor_invalid = None
        self.ts_sensor_good = 0.0  # the controller's time (t_session) of the last good record
        self.latest_sample_time = None
        self.last_raw = [float("nan")] * 6
        self.t_logged = 0.0  # the controller's time of the last wrench record logged
        self.t_sensor_grace = 0.0  # the first message after a gap in the controller's stream
        self.t_start = self.t_last_msg = None
        self.t_last_answer = 0.0
        self._caught_up = False  # (after the start's backlog: see run)
        self.pending_reseed = False
        self.reseed_candidate = None  # the first finite record while pending_reseed (the wrench, 6)
        self.saturated = False
        self.last_sent = None
        self._corr_sent = [0.0] * 6  # the correction (rad, model joints) of the last target sent
        self.ended_by = "interrupt"
        # cell/realtime_thread.quiet_gc's token when the automatic collector is off for the run: the loop
        # collects after its answers (``_safe_point``); None: the collector left as it is
        self.gc_token = None
        G = robot.joint_map.G
        self._identity = robot.joint_map.is_identity
        self._Ginv = np.linalg.inv(G)
        self._limits = pose_limits_deg(robot)  # (the working ranges in deg, once: not per message)
        self._lo, self._hi = self._limits[:2]
        self._clamp = clamp_deg(robot, settings.saturation_deg).tolist()
        self._supervision = supervision_tolerances(robot, settings.period_s)  # axis speeds and accelerations
        self._sat = [math.radians(settings.saturation_deg)] * 6
        self.bound = CorrectionBound.of(compensator, settings)  # (None: no bound)
        self._init_sensor_checks()
        # an answer later than this after its datagram's arrival (s) missed the controller's next cycle
        self.deadline_s = getattr(link, "answer_deadline_periods", 1.0) * settings.period_s

    # ------------------------------------------------------------ events

    def now(self):
        return self.pc_time() - self.t_start if self.t_start is not None else 0.0

    def event(self, text):
        t = self.now()
        if len(self.n.events) < Counters.MAX_EVENTS_KEPT:
            self.n.events.append((t, self.t_session, text))
        else:
            self.n.events_dropped += 1
        if self.log is not None:
            self.log.event(t, self.t_session, text)
        print(f"robstiff: compensate: t = {t:8.3f} s: {text}", file=self.out, flush=True)

    def fault_on(self, name, text):
        if name not in self.faults:
            self.faults[name] = self.now()
            self.n.fault_onsets += 1
            self.n.sensor_faults += name.startswith("sensor")  # (sensor, sensor start, sensor rate)
            self.event(f"{text}; the correction ramps to zero")
        self.ok_since_fault = 0

    def fault_off(self, name, text):
        if name in self.faults:
            t0 = self.faults.pop(name)
            self.event(f"{text} (after {self.now() - t0:.3f} s)")

    # ------------------------------------------------------------ one message

    def _feedback(self, joints_deg, t_now):
        """Take the controller's joint feedback if it is a pose inside the
        working ranges.  Non-finite feedback (a dropout) is a fault after
        ``feedback_timeout_s``; finite feedback outside the ranges (no arm
        is there: a lie or a corrupted message) at once.  Meanwhile the
        last good feedback stands."""
        problem = pose_problem_within(self._limits, joints_deg)
        if problem is None:
            self.q_deg = list(joints_deg)
            r = [math.radians(v) for v in joints_deg]
            self.q = r if self._identity else self.robot.joint_map.to_model(r).tolist()
            self.t_q_good = t_now
            self.fault_off("feedback", "feedback: joint angles inside the working ranges again")
        elif all(math.isfinite(v) for v in joints_deg):
            self.fault_on("feedback", f"feedback: {problem}")
        elif t_now - self.t_q_good > self.s.feedback_timeout_s:
            self.fault_on("feedback", f"feedback: {problem} for {self.s.feedback_timeout_s * 1e3:.0f} ms")

    def cycle(self, msg, t_arr, dt, late=False, judge=False):
        """Answer one controller message that the session clock accepted
        (``dt``: its step, s): returns whether its own target was sent.
        ``late``: the run counted it late already (the next message was
        waiting); ``judge``: an answer that leaves more than the deadline
        after the datagram's arrival (the kernel's stamp) counts late
        (``Counters.over_deadline``; not before the start's catch-up)."""
        self.n.received += 1
        self.t_session += dt
        self.t_ref += dt if self.rate is None else self.rate.step(dt, msg.seq, self.ref, self.t_ref)
        self._feedback(msg.joints_deg, t_arr)
        self._read_sensor(t_arr)
        if self.gate is not None:
            self._poll_gate()
        if self.pending_preview is not None and self.pending_preview.done:
            self._take_preview()
        if self.preview is not None:
            self.preview.update(self, msg)
        # (the bound's fault alone: the model runs on, its wish judged each cycle; cell/correction_bound.py)
        # (``correction_off``: the correction held at zero for the run, the model not run; cell/loop_settings.py)
        active = self.gate is None and all(name == "bound" for name in self.faults) and self.s.correction_off is None
        # (the correction's step: the reference's; a message that holds the reference under a fault, a clock
        # that stalled or went back, still ramps the correction one period's worth towards zero)
        step_s = min(dt if dt > 0.0 or not self.faults else self.s.period_s, MAX_STEP_PERIODS * self.s.period_s)
        corr = bounded(self, self.comp.tick(self.q, step_s, active), step_s, active, CLEAR_MESSAGES)
        if self._identity:
            corr_deg = [math.degrees(c) for c in corr]
        else:
            corr_deg = np.degrees(self._Ginv @ np.asarray(corr)).tolist()
        if self.preview is not None:
            self.preview.sent(corr_deg)
        ref_deg, m1, mf = self.ref.at(self.t_ref)
        target = [r + c for r, c in zip(ref_deg, corr_deg)]
        env = Envelope(self._lo, self._hi, tuple(ref_deg), tuple(c + m for c, m in zip(self._clamp, m1)),
                       tuple(self.q_deg), tuple(c + m for c, m in zip(self._clamp, mf)), *self._supervision)
        unanswered = self.n.unanswered_refused
        sent = self._send(msg, target, env)
        if sent:
            self._corr_sent = corr
            if self.bound is not None:
                self.bound.sent()
        else:  # the controller holds the last target sent: the ramp goes on from its correction (MAX_STEP_PERIODS)
            self.comp.correction = list(self._corr_sent)
        t_done = self.pc_time()
        self._count_saturation()  # (after the answer: counting only)
        age = t_done - self.latest_sample_time if self.latest_sample_time is not None else float("nan")
        self.n.compute_ms.add((t_done - t_arr) * 1e3)
        response_s = t_done - t_arr + msg.queued_s
        self.n.response_ms.add(response_s * 1e3)  # (NaN without the kernel's stamp: not added)
        # (an answer that left; NaN: unknown, not counted; a message left unanswered is counted there)
        if judge and not late and response_s > self.deadline_s and self.n.unanswered_refused == unanswered:
            self.n.over_deadline += 1
            late = True
        self.n.age_ms.add(age * 1e3)
        # (stale when old on both clocks, as the sensor's silence is judged: in lockstep on a loaded PC the
        # newest record can be old on this PC's clock and of this very cycle on the controller's)
        bound = STALE_PERIODS * self.s.period_s
        age_ctrl = self.t_session - self.ts_sensor_good if self.latest_sample_time is not None else float("nan")
        stale = bool(self.faults) or self.gate is not None or not sent or not (age <= bound or 0.0 <= age_ctrl <= bound)
        if stale:
            self.n.stale_s += dt
        self.n.lost_estimate.add(sum(abs(c) for c in self.comp.dq), stale, held=bool(self.faults))
        self.t_last_answer = t_done
        if self.log is not None:
            for t_w, w in self._wrench_rows:
                self.log.wrench(t_w, w)
            self._wrench_rows.clear()
            self.log.cycle(self, msg, t_arr, ref_deg, corr, corr_deg, target if sent else None, t_done - t_arr, age,
                           late)
        return sent

    def _count_saturation(self):
        """Count the cycles the model asked more than the clamp, and log its onsets."""
        if any(abs(d) >= s for d, s in zip(self.comp.dq, self._sat)):
            self.n.saturated_cycles += 1
            if not self.saturated:
                self.saturated = True
                self.n.saturation_onsets += 1
                if self.n.saturation_onsets <= 5 or self.n.saturation_onsets % 100 == 0:
                    j = max(range(6), key=lambda i: abs(self.comp.dq[i]) / self._sat[i])
                    self.event(f"correction saturated on q{j + 1} at {math.degrees(self._sat[j]):g} deg (the model "
                               f"asks more; onset {self.n.saturation_onsets}, {self.n.saturated_cycles} cycles so far)")
        else:
            self.saturated = False

    def _send(self, msg, target, env):
        try:
            self.link.send_targets(msg, target, env)
            self.last_sent = target
            self.n.answered += 1
            return True
        except UnsafeTarget as e:
            self.n.refused += 1
            self.fault_on("target", f"target refused, not sent: {e}")
        if self.last_sent is not None:
            try:
                self.link.send_targets(msg, self.last_sent, env)
                self.n.answered += 1
                return False
            except UnsafeTarget:
                pass
        self.n.unanswered_refused += 1
        return False

    def _safe_point(self):
        """After the answer has left and its log rows are made: the garbage
        collection due, if any (timed), never on the way to an answer."""
        if self.gc_token is not None:
            t0 = time.perf_counter()
            if collect_if_due(self.gc_token) >= 0:
                self.n.gc_ms.add((time.perf_counter() - t0) * 1e3)

    # ------------------------------------------------------------ the loop

    def _serve(self):
        """The loop: each message answered, until the duration or an idle
        controller ends it (or an exception: ``run``'s)."""
        T = self.s.period_s
        while True:
            got = self.link.receive(self.s.egm_timeout_s)
            now = self.pc_time()
            if self.s.duration_s and now - self.t_start >= self.s.duration_s:
                self.ended_by = "duration"
                break
            if not got:
                self.fault_on("silent", f"{self.link.name}: no message from the controller for "
                                        f"{self.s.egm_timeout_s * 1e3:.0f} ms")
                if self.s.idle_exit_s and now - self.t_last_msg > self.s.idle_exit_s:
                    self.ended_by = "idle"
                    self.event(f"{self.link.name}: no message for {self.s.idle_exit_s:g} s: the run ends")
                    break
                if self.log is not None:
                    self.log.tick(now)
                self._safe_point()
                continue
            accepted = []
            for m, t in got:  # every datagram's sequence and clock, oldest first
                ok, dt = self._session(m)
                if ok:
                    accepted.append((m, t, dt))
            if not accepted:
                continue  # duplicates or old datagrams only: nothing to answer
            # before the first answer reaches it the controller holds its own pose: the messages it sent
            # meanwhile, waiting here until this side first caught up (a message alone; at most a second of
            # them), are the start's backlog, not late answers, as the controller counts them (from its first
            # target on): the two sides' verdicts judge the same cycles whatever this PC's load
            started = self._caught_up
            if not started and self.n.answered > 0 and (
                    len(accepted) == 1 or self.n.start_backlog >= START_BACKLOG_S / self.s.period_s):
                self._caught_up = started = True
            for m, t, dt in accepted[:-1]:
                # older ones behind the newest (this PC fell behind): each answered in turn, late; a
                # controller that takes the newest target loses nothing by it, and one that reads the
                # targets a cycle after sending (the transport delay) gets the target it is due
                if started:
                    self.n.late += 1
                else:
                    self.n.start_backlog += 1
                self.cycle(m, t, dt, late=started)
            msg, t_arr, dt = accepted[-1]
            gap = t_arr - self.t_last_msg
            self.n.gap_ms.add(gap * 1e3)
            if gap > self.s.sensor_timeout_s:
                self.t_sensor_grace = t_arr
            if gap > 1.5 * T:
                self.n.gaps_over += 1
            late = self.t_last_answer > t_arr and started
            if late:
                self.n.late += 1
            self.t_last_msg = t_arr
            self.fault_off("silent", f"{self.link.name}: messages again")
            # (answered before the next message was read, but more than the controller's cycle after its
            # own arrival: late too, as the controller counts it: its cycle runs on its own clock)
            self.cycle(msg, t_arr, dt, late=late, judge=started)
            if self.log is not None:
                self.log.tick(self.pc_time())
            self._safe_point()

    def run(self, first):
        """Run from the first message (``first_message``'s result) until the
        duration, an idle controller or an interrupt ends it.  Once the loop
        has ended, ``end_hold`` (cell/end_hold.py; set by the command) holds a
        stop request until the run's end is written."""
        try:
            try:
                # (the start inside: a stop during the first message's answer ends the run as any other, logged)
                self.run_start(*first)
                self._serve()
            finally:
                if self.end_hold is not None:
                    self.end_hold.enter()
        except KeyboardInterrupt:
            self.event("interrupted: the run ends")
        except Terminated:  # a service manager's stop: end the run and write its log, as on Ctrl-C
            self.event("terminated: the run ends")
        if self.ended_by in ("idle", "interrupt") and "silent" in self.faults:
            # the controller stopped streaming: the program's normal end, not a fault (and so when a service
            # manager or Ctrl-C stops the run after that silence: its events keep both lines)
            self.faults.pop("silent")
            self.n.fault_onsets -= 1
        self.finish_start()
        return self.n

    def stats(self):
        """The run's figures and its health (a dict for the JSON: cell/loop_stats.py)."""
        return loop_stats(self)
