"""The start's slow work, off the real-time path: a controller's first
message is answered within its cycle.

A controller that streams (KUKA RSI expects each answer within its 4 ms
cycle and stops after a few missed ones; EGM and Stream Motion time out
too) cannot wait for the work a compensator does once at the start: the
correction loop's stability check at the hold pose the first message
gives (cell/loop_guard.py: 70-220 ms on this project's 2-core test
machine), the log folder's start (cell/run_log.py: an earlier run folder
replaced, the inputs copied).  ``StartGate`` runs that work in a thread
of its own (below the loop's real-time priority: ``below_the_loop``; the
loop check's arithmetic itself in a process forked before the link opens,
cell/loop_guard.RemoteCheck, as its numerical calls hold Python's lock for
milliseconds at a time), while the loop answers every message with zero correction: the
controller's own pose (the hold pose, checked against the working
ranges, or the reference), through the same target checks as every
answer.  The loop compensates only once every job has passed, the
correction then ramping in from zero at its rate limit (the chain's own
rate limit: model/compensator.Compensator); a job that refuses the start
(an unstable loop without --allow-unstable-loop) ends the run with its
one line and exit status 2, nothing but zero correction having been sent.

The loop polls ``done`` (an attribute read) once per message; the thread
only sets attributes, so the loop never waits on it.
"""

import math
import os
import threading
import time

from robstiff_drake.cell.safety import pose_problem_within
from robstiff_drake.errors import InputError

MALFORMED_FIRST = 25  # unusable datagrams from the controller before its first good one: refused at once


class StartNote(str):
    """A start job's line that is a note of the run's course (the log's
    events.csv and the text, not the summary's list of faults and events):
    a warning the command also puts in summary.json's warnings."""


class StartGate:
    """``jobs``: [(what, function)], run in order in a thread; a function
    returns None, a line for the log's events (a warning) or a StartNote,
    or raises InputError (the start refused).  ``done``: set when all have run or
    one raised; then ``error`` (the InputError or None), ``notes`` (the
    lines returned) and ``seconds`` (the wall time it took)."""

    def __init__(self, jobs):
        self.jobs = list(jobs)
        self.done = False
        self.error = None
        self.notes = []
        self.seconds = float("nan")
        self.what = ", ".join(w for w, _ in self.jobs)
        self._thread = threading.Thread(target=self._run, name="robstiff-start", daemon=True)

    def start(self):
        self._thread.start()
        return self

    def _run(self):
        below_the_loop()
        t0 = time.monotonic()
        try:
            for _, fn in self.jobs:
                note = fn()
                if note:
                    self.notes.append(note)
        except InputError as e:
            self.error = e
        except Exception as e:  # (a bug or an OS error in the start's work: refused, never half-started)
            self.error = InputError(f"the start's work failed ({type(e).__name__}: {e}); nothing but zero "
                                    "correction was sent")
        finally:
            self.seconds = time.monotonic() - t0
            self.done = True

    def wait(self, timeout_s=None):
        """Wait for the work (at the run's end, off the loop); whether it is
        done.  Work never started (the run stopped inside its start, between
        the gate's making and its start) is started now: its log folder
        opens, and its refusal is the run's as ever."""
        if self._thread.ident is None:
            self._thread.start()
        self._thread.join(timeout_s)
        return self.done


def below_the_loop():
    """This thread (started by the loop's, whose scheduling it inherits) at
    the lowest real-time priority when the loop runs under SCHED_FIFO: above
    every normal process, so that it is never preempted by one while it
    holds Python's interpreter lock (the loop would wait for that process's
    time slice: 6.7 ms measured at load 5 with the normal policy), and
    below the loop and the sensor's reader, which preempt it; and back on
    every CPU when the loop's thread is pinned to one (``--cpu``: this
    thread inherited its pin)."""
    from robstiff_drake.cell.realtime_thread import unpin_this_thread

    unpin_this_thread()
    try:
        if os.sched_getscheduler(0) == os.SCHED_FIFO:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(os.sched_get_priority_min(os.SCHED_FIFO)))
    except (AttributeError, OSError):
        pass


class LoopStart:
    """The loop's start (a base of cell/compensate.CompensatorLoop): the
    controller's first message awaited and checked, answered at once, and
    the start's work (``StartGate``) begun and polled."""

    def first_message(self, timeout_s):
        """The controller's first usable message; InputError (before the
        loop: exit 2) when none comes, or its feedback is absurd."""
        t_end = time.monotonic() + timeout_s
        while True:
            got = self.link.receive(min(max(t_end - time.monotonic(), 0.0), 0.5))
            if not got:
                self.link.open()  # (again: a start request lost on the way, or sent before the robot listened)
            else:
                msg, t_arr = got[-1]
                break
            if time.monotonic() >= t_end or self.link.malformed >= MALFORMED_FIRST:
                who = f"{self.link.controller_ip}" + (f":{self.link.controller_port}" if self.link.controller_port
                                                      else "")
                extra = ""
                if self.link.strangers:
                    extra = (f"; {self.link.strangers} datagrams from other senders (e.g. {self.link.stranger_example}) "
                             "were dropped: give the controller's address with --controller HOST[:PORT]")
                elif self.link.malformed:
                    extra = f"; {self.link.malformed} datagrams from it were not usable ({self.link.malformed_example})"
                within = f"within {timeout_s:g} s" if self.link.malformed < MALFORMED_FIRST else "yet"
                raise InputError(f"{self.link.option} {self.link.port}: no usable {self.link.name} message from the "
                                 f"controller {who} {within}{extra}")
        problem = pose_problem_within(self._limits, msg.joints_deg)
        if problem:
            raise InputError(f"{self.link.option} {self.link.port}: the controller's first message has absurd joint "
                             f"feedback ({problem}); nothing was sent")
        return msg, t_arr

    def run_start(self, msg, t_arr):
        """Start the session on the first message: answered at once with
        zero correction, then the start's slow work begun off this thread
        (cell/start_gate.py; the loop compensates once it has passed)."""
        self.t_start = self.t_last_msg = self.t_q_good = t_arr
        self.t_sensor_good = self.pc_time()  # (the sensor's records are drained from now on)
        self.q_deg = list(msg.joints_deg)
        r = [math.radians(v) for v in msg.joints_deg]
        self.q = r if self._identity else self.robot.joint_map.to_model(r).tolist()
        jobs = list(self.start_jobs)
        if self.log is not None:
            self.log.bind(self)  # (rows are kept in memory until the folder is open)
            jobs.append(("the log folder's start", self.log.open))
        self.gate = StartGate(jobs) if jobs else None
        if self.s.correction_off is not None:
            self.note(f"the online correction is held at zero for the whole run: {self.s.correction_off}")
        self._start_on_recent_records()
        self.cycle(msg, t_arr, self._session(msg)[1])
        if self.gate is not None:
            self.gate.start()

    def _poll_gate(self):
        """Compensate from this message on once the start's work has passed
        (the correction ramps in from zero at the rate limit); its refusal
        (InputError) ends the run."""
        if self.gate.done:
            self._gate_ended("compensating from now on, the correction ramping in at the rate limit"
                             if self.s.correction_off is None else
                             f"the correction held at zero to the end ({self.s.correction_off})")

    def finish_start(self):
        """At the run's end: wait for the start's work if it has not ended
        (the log folder opens before it is closed); InputError when it
        refused the start."""
        if self.gate is not None:
            self.gate.wait()
            self._gate_ended("after the run's last message: the run answered with zero correction only")

    def _gate_ended(self, what_now):
        g = self.gate
        if g.error is not None:
            self.ended_by = "start refused"
            raise g.error
        self.gate = None
        for note in g.notes:
            (self.note if isinstance(note, StartNote) else self.event)(note)
        self.note(f"start: {g.what} done in {g.seconds:.3f} s (meanwhile answered with zero correction, the "
                  f"controller's own pose); {what_now}")

    def note(self, text):
        """A line of the run's course (events.csv and stderr), not a fault:
        not in the summary's list of faults and events."""
        t = self.now()
        if self.log is not None:
            self.log.event(t, self.t_session, text)
        print(f"robstiff: compensate: t = {t:8.3f} s: {text}", file=self.out, flush=True)

    def _take_preview(self):
        """The job's table computed in the background (cell/preview_job.
        BackgroundTable) is ready: preview from this message on (the
        correction moves from the plain chain's at the rate limit), or say
        why not (plain compensation to the end)."""
        bg, self.pending_preview = self.pending_preview, None
        bg.taken_at_s = self.t_session
        if bg.preview is None:
            self.event(f"preview: the job's table could not be computed ({bg.error}); plain compensation to the end")
            return
        pv = bg.preview
        pv.t_ctrl = self.t_ref  # (its check of the controller's clock counts from the played reference's time now)
        self.preview = self.comp.model = pv
        self.note(f"preview: the job's table is ready ({pv.n} cycles, computed in {bg.seconds:.2f} s in another "
                   "process); previewing from now on (the correction moves to the preview's at the rate limit)")
