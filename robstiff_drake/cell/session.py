"""The controller's sequence number and clock, checked message by message.

Nothing a datagram says about time is trusted alone: the sequence number
(EGM's header.seqno; RSI's IPOC and Stream Motion's sequence_no and time
stamp likewise) and the controller's clock (ms) must advance together.

* the same sequence number again: a duplicate, dropped (never answered);
* an older one (up to ``REORDER_WINDOW`` behind): a reordered datagram,
  dropped;
* a jump of more than ``MAX_JUMP`` cycles forward, or further back than
  the window: a fault (a controller restart looks like this); the session
  takes the new numbering as its own and the reference advances by one
  period;
* a clock that disagrees with the sequence (its step differs from the
  sequence's step times the period by more than ``CLOCK_TOL``): a fault;
  the reference advances by the sequence's step times the period (the
  clock's value is not used);
* a clock whose steps each pass but add up away from the sequence's
  (their sum since the session's start or restart more than the
  tolerance off the sequence's steps times the period: a clock running
  6 ms a 4 ms message, or a --period-ms the controller does not run): a
  fault on every message while it lasts, the reference advancing by the
  sequence's step (before, each step within the tolerance passed and the
  reference ran at the clock's pace: 1.5 times the program's feed at 6 ms
  a 4 ms message, the arm following it);
* otherwise the reference advances by the clock's step, which is then
  within ``MAX_JUMP`` periods (+ the tolerance): a bounded step per
  message, whatever the datagram says, and the reference's time within
  the tolerance of the sequence's.

* a run of older ones numbered on from 0 or 1 (``RESTART_RUN`` in a row,
  each one after the last, their clock with them, none newer between):
  a controller that restarted within the first ``REORDER_WINDOW``
  messages (its numbering and clock from the start again, behind the
  last seen): taken as a "jump" (its restart) on the run's last message,
  the ones before it dropped; a run numbered from elsewhere stays "old"
  (``behind_run`` counts it: the loop logs it).

A controller whose clock does not run (every message stamped the same,
e.g. tm = 0) is timed by its sequence numbers alone.
"""

MAX_JUMP = 5  # cycles a sequence number may skip (lost datagrams) without a fault
REORDER_WINDOW = 64  # how far back an old datagram is dropped quietly (not a fault)
# Messages in a row, numbered on from 0 or 1 behind the last seen, that are a restart, not reordered datagrams (a
# reordered datagram comes alone, or a few amid newer ones; a restarted controller sends nothing newer).  Three: two
# of them dropped unanswered, then the restart's fault (ramp to zero) as for a restart later in a session.
RESTART_RUN = 3
WRAP = 2**32  # sequence numbers and clocks are uint32 on every protocol here


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
        # the clock's steps taken (ms) minus the sequence's steps times the period, summed since the session's
        # start or restart: the reference's time ahead of the sequence's, kept within the tolerance
        self.drift_ms = 0.0
        # why the last "clock" verdict: ("step", the clock's step ms, the sequence's ms) or ("drift", the sum
        # it would reach ms, messages summed)
        self.clock_reason = None
        self._summed = 0

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
                self.restarted_from, self._behind = self._behind[0], None
                self.seq, self.tm = int(seq), int(tm_ms)
                self.drift_ms, self._summed = 0.0, 0  # (a restart's clock starts again)
                self.counts["jump"] += 1
                return "jump", self.T
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
            self.drift_ms, self._summed = 0.0, 0
            return "jump", self.T
        nominal_ms = ds * self.T_ms
        if not self.clock_runs:
            self.counts["ok"] += 1
            return "ok", nominal_ms * 1e-3
        if abs(dtm - nominal_ms) > self.tol_ms:
            self.counts["clock"] += 1
            self.clock_reason = ("step", dtm, nominal_ms)
            return "clock", nominal_ms * 1e-3
        drift = self.drift_ms + (dtm - nominal_ms)
        if abs(drift) > self.tol_ms:
            # (each step within the tolerance, their sum not: the clock runs at another pace than the sequence;
            # the step not taken, the reference stays within the tolerance of the sequence's time)
            self.counts["clock"] += 1
            self.clock_reason = ("drift", drift, self._summed + ds)
            return "clock", nominal_ms * 1e-3
        self.drift_ms = drift
        self._summed += ds
        self.counts["ok"] += 1
        return "ok", dtm * 1e-3

    def jump_text(self, seq, previous):
        return f"sequence number {seq} after {previous}"
