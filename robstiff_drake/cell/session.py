"""The controller's sequence number and clock, checked message by message.

Nothing a datagram says about time is trusted alone: the sequence number
(EGM's header.seqno; RSI's IPOC and Stream Motion's sequence_no and time
stamp likewise) and the controller's clock (ms) must advance together.

* the same sequence number again: a duplicate, dropped (never answered);
* an older one (up to ``REORDER_WINDOW`` behind): a reordered datagram,
  dropped;
* a jump of more than ``MAX_JUMP`` cycles forward, or further back than
  the window: a fault (a controller restart looks like this); the session
  takes the new numbering as its own and the run's time starts again
  there (below); the reference advances by one period at most, by none
  where the clock went back;
* a clock that disagrees with the sequence (its step differs from the
  sequence's step times the period by more than the tolerance,
  ``tol_ms``): a fault; the clock's step counts for the reference as far
  as it went forward (below: a clock set back or stalled holds the
  reference; one that jumped ahead lets it follow the sequence, not the
  jump);
* a clock whose steps each pass but add up away from the sequence's
  (their sum since the session's start or restart, forgetting over
  ``PACE_HORIZON_S``, more than the tolerance, and ``PACE_TOL`` of the
  time summed, off the sequence's steps times the period; a step beyond
  the tolerance, the step's fault, counted in it up to the tolerance: a
  clock running 6 ms a 4 ms message, or a --period-ms the controller does
  not run): a fault on every message while it lasts.  The sum is the
  clock's own, never clamped: a clock 0.75 % fast (4.03 ms a 4 ms
  message, rounded to whole ms: 4 ms steps for 32 messages, then a 5)
  stays the fault once it is one (before, the sum stopped at the
  tolerance, the 4 ms steps passed and the fault cleared 446 times in a
  minute); a clock within ``PACE_TOL`` of the sequence's pace is no fault
  (before, one 100 ppm fast faulted once every 20 s, 500 ppm once every
  4 s, each ramping the correction to zero and back);
* a run of older ones numbered on from 0 or 1 (``RESTART_RUN`` in a row,
  each one after the last, their clock with them, none newer between):
  a controller that restarted within the first ``REORDER_WINDOW``
  messages (its numbering and clock from the start again, behind the
  last seen): taken as a "jump" (its restart) on the run's last message,
  the ones before it dropped; a run numbered from elsewhere stays "old"
  (``behind_run`` counts it: the loop logs it).

The reference's time (the sum of the ``dt_s`` returned) is the slower of
the two: since the run's start (the session's first message, or its
last jump or restart) it is at most the sequence's steps times the
period and at most the clock's time elapsed, from the first message on,
whatever the verdicts (``_pace``).  Each of the two is summed apart and
the reference advances by what both allow, so an honest clock's 1 ms
resolution and jitter (steps of 3, 5, 4, 4 ms) cost at most one stamp's
lag, never a lag that grows; the time one allows beyond the other is
kept up to the tolerance (a clock ahead by a few ms, or a sequence ahead
of a slow clock, never plays a burst later).  A ``--period-ms 8``
against a controller at 4 ms (EGM; Stream Motion at 250 Hz) plays its
reference at the clock's 4 ms a message from the first one (before, at
8 ms a message, twice the program's feed, until the clock's drift was
the fault and 25 messages more named the period:
tests/test_reference_pace.py); a clock slower than the sequence (a slow
or lying clock, or a controller whose cycle is shorter than
--period-ms) plays it at the clock's pace (before, at the sequence's
within the tolerance, or at it whenever a fault was on); a clock ahead
of the sequence within the tolerance no longer plays it ahead (before,
by up to the tolerance).  RSI's sequence is its IPOC over the period:
clock and sequence are one there, nothing changes.

A controller whose clock does not run (every message stamped the same,
e.g. tm = 0, from its first two messages) is timed by its sequence
numbers alone.
"""

import math

MAX_JUMP = 5  # cycles a sequence number may skip (lost datagrams) without a fault
REORDER_WINDOW = 64  # how far back an old datagram is dropped quietly (not a fault)
# Messages in a row, numbered on from 0 or 1 behind the last seen, that are a restart, not reordered datagrams (a
# reordered datagram comes alone, or a few amid newer ones; a restarted controller sends nothing newer).  Three: two
# of them dropped unanswered, then the restart's fault (ramp to zero) as for a restart later in a session.
RESTART_RUN = 3
WRAP = 2**32  # sequence numbers and clocks are uint32 on every protocol here
# How far a controller's clock may run from its cycle's pace (a fraction) before their sum's drift is a fault.
# ASSUMPTION (no controller's manual at hand states how its time stamp is made): a stamp from another oscillator
# than the cycle's (two quartz crystals of +-50 ppm: 100 ppm apart) or from an OS clock slewed by NTP (Linux's
# adjtimex slews at most 500 ppm) is honest; twice the larger.  A clock at 4.004 ms a 4 ms message is the edge;
# the reference keeps the sequence's time whatever the clock's pace (below).
PACE_TOL = 1e-3
# The clock's drift and the time it is allowed against are sums that forget over this horizon (s): an honest clock's
# allowance (PACE_TOL of the time summed) stops growing at 10 ms, so a clock that runs away after an hour is the
# fault as soon as after a minute (before it, a sum since the start allowed 3.6 s after an hour: a clock at 4.5 ms
# a 4 ms message would have taken two minutes to be seen).
PACE_HORIZON_S = 10.0


def _signed(d):
    d %= WRAP
    return d - WRAP if d >= WRAP // 2 else d


class SessionClock:
    """``accept(seq, tm_ms)`` -> (verdict, dt_s): verdict "ok", "clock"
    (answer it, with a fault), "jump" (answer it, with a fault),
    "duplicate" or "old" (drop it); dt_s: how far the reference advances."""

    def __init__(self, period_s, clock_tol_ms=None):
        self.T = float(period_s)
        self.T_ms = self.T * 1e3
        # the clock may disagree with the sequence by half a period plus its
        # own resolution (1 ms) before it is a fault
        self.tol_ms = 0.5 * self.T_ms + 1.0 if clock_tol_ms is None else float(clock_tol_ms)
        self.seq = None
        self.tm = None
        self.clock_runs = None  # unknown until two messages have come
        self.counts = {"ok": 0, "clock": 0, "jump": 0, "duplicate": 0, "old": 0}
        # the run of messages behind the last one seen, each one after the one before: [first seq, seq, tm, count]
        self._behind = None
        self.restarted_from = None  # the first sequence number of the run taken as a restart (last "jump")
        # the time (ms) the sequence and the clock each allow the reference beyond where it stands: their steps
        # summed since the run's start (or its last jump or restart) minus the reference's; what one allows beyond
        # the other kept up to the tolerance (``_pace``)
        self.seq_ahead_ms = 0.0
        self.clock_ahead_ms = 0.0
        # the clock's own drift (ms): every step minus the sequence's (one beyond the tolerance up to it), summed
        # since the session's start or restart, forgetting over PACE_HORIZON_S (not clamped: a clock at another
        # pace runs away in it, and stays the fault)
        self.clock_drift_ms = 0.0
        # why the last "clock" verdict: ("step", the clock's step ms, the sequence's ms) or ("drift", the
        # clock's drift ms, periods summed, the drift allowed ms)
        self.clock_reason = None
        self._summed = 0
        self._paced_ms = 0.0  # the sequence's time the drift is summed over (ms), forgetting as it does
        self._running_away = False  # (the clock's drift a fault: it ends 1 ms, the clock's resolution, further in)

    @property
    def behind_run(self):
        """How many messages in a row came behind the last one seen, each the next after the one before (0: none)."""
        return self._behind[3] if self._behind is not None else 0

    def _run_behind(self, seq, tm):
        """Extend (or start) the run of messages behind the last one; True when it is a restart."""
        b = self._behind
        with_clock = b is not None and (not self.clock_runs or abs(_signed(tm - b[2]) - self.T_ms) <= self.tol_ms)
        if with_clock and _signed(seq - b[1]) == 1:
            b[1], b[2], b[3] = seq, tm, b[3] + 1
        else:
            # (its clock behind the last one seen too, or not running: a restart's clock starts again)
            b = self._behind = [seq, seq, tm, 1] if not self.clock_runs or _signed(tm - self.tm) <= 0 else None
        return b is not None and b[0] <= 1 and b[3] >= RESTART_RUN

    def accept(self, seq, tm_ms):
        if self.seq is None:
            self.seq, self.tm = int(seq), int(tm_ms)
            self.counts["ok"] += 1
            return "ok", 0.0
        ds = _signed(int(seq) - self.seq)
        if ds == 0:
            self.counts["duplicate"] += 1
            return "duplicate", 0.0
        if -REORDER_WINDOW <= ds < 0:
            if self._run_behind(int(seq), int(tm_ms)):
                prev_tm = self.tm
                self.restarted_from, self._behind = self._behind[0], None
                self.seq, self.tm = int(seq), int(tm_ms)
                # (a restart's clock starts again)
                self._restart_drift()
                self.counts["jump"] += 1
                return "jump", self._jump_step(_signed(int(tm_ms) - prev_tm))
            self.counts["old"] += 1
            return "old", 0.0
        self._behind = None
        self.restarted_from = None
        dtm = _signed(int(tm_ms) - self.tm)
        if self.clock_runs is None:
            self.clock_runs = dtm != 0
        self.seq, self.tm = int(seq), int(tm_ms)
        if ds < 0 or ds > MAX_JUMP:
            self.counts["jump"] += 1
            self._restart_drift()
            return "jump", self._jump_step(dtm)
        nominal_ms = ds * self.T_ms
        if not self.clock_runs:
            self.counts["ok"] += 1
            return "ok", nominal_ms * 1e-3
        if abs(dtm - nominal_ms) > self.tol_ms:
            self.counts["clock"] += 1
            self.clock_reason = ("step", dtm, nominal_ms)
            # (into the clock's drift as far as a step may go: one stamp late beyond the tolerance, the next
            # back, adds nothing; a clock set forward once, a tolerance at most; a clock that stalled or went
            # back, nothing: that is not a clock at another pace, and its steps counted would name a wrong
            # --period-ms for PACE_HORIZON_S after a stall that ended, the correction held at zero meanwhile)
            self._sum_drift(ds, 0.0 if dtm <= 0 else max(-self.tol_ms, min(self.tol_ms, dtm - nominal_ms)))
            # (for the reference, none where the clock went back or stalled (it holds); a step ahead counts, what
            # it allows beyond the sequence kept up to the tolerance (``_pace``): a clock that jumped ahead gives
            # the reference no more than the sequence, and a stamp late beyond the tolerance, the next one back,
            # costs no lag)
            return "clock", self._pace(nominal_ms, max(0.0, float(dtm)))
        self._sum_drift(ds, dtm - nominal_ms)
        allowed = self.tol_ms + PACE_TOL * self._paced_ms - (1.0 if self._running_away else 0.0)
        self._running_away = abs(self.clock_drift_ms) > allowed
        if self._running_away:
            # (each step within the tolerance, their sum not: the clock runs at another pace than the sequence, or
            # --period-ms is not the controller's cycle; the reference at the slower of the two)
            self.counts["clock"] += 1
            self.clock_reason = ("drift", self.clock_drift_ms, self._summed, allowed)
            return "clock", self._pace(nominal_ms, float(dtm))
        self.counts["ok"] += 1
        return "ok", self._pace(nominal_ms, float(dtm))

    def _pace(self, seq_step_ms, clock_step_ms):
        """How far the reference advances (s): what both the sequence's and
        the clock's time since the run's start allow beyond where it stands
        (never back).  Each is summed apart, so the 1 ms resolution of an
        honest clock's stamps (3, 5, 4, 4 ms) costs no lag that grows; what
        one allows beyond the other is kept up to the tolerance (a clock set
        a few ms ahead, or a sequence ahead of a slow clock, plays no burst
        later)."""
        a = self.seq_ahead_ms + seq_step_ms
        b = self.clock_ahead_ms + clock_step_ms
        step = max(0.0, min(a, b))
        self.seq_ahead_ms = min(a - step, self.tol_ms)
        self.clock_ahead_ms = min(b - step, self.tol_ms)
        return step * 1e-3

    def _jump_step(self, dtm):
        """A jump's or a restart's step (s): one period, or what the clock
        stepped if less (none where it went back); the run's time starts
        again from it."""
        if not self.clock_runs:
            return self.T
        return max(0.0, min(float(dtm), self.T_ms)) * 1e-3

    def _restart_drift(self):
        self.clock_drift_ms, self._summed, self._paced_ms, self._running_away = 0.0, 0, 0.0, False
        self.seq_ahead_ms = self.clock_ahead_ms = 0.0  # (the run's time starts again)

    def _sum_drift(self, ds, err_ms):
        """The clock's step ``err_ms`` off the sequence's ``ds`` periods into its drift (forgetting over
        PACE_HORIZON_S, as the time it is allowed against)."""
        keep = math.exp(-ds * self.T / PACE_HORIZON_S)
        self._summed += ds
        self._paced_ms = self._paced_ms * keep + ds * self.T_ms
        self.clock_drift_ms = self.clock_drift_ms * keep + err_ms

    def jump_text(self, seq, previous):
        return f"sequence number {seq} after {previous}"
