"""The pace the joint reference is played at: a stop and a restart within
the robot's acceleration when the controller's clock stalls.

The session's clock (cell/session.py ``SessionClock._pace``) allows the
reference a step each message, ``dt_allowed_s``: the slower of the
sequence's and the controller's clock's time since the run's start; 0
while the clock stalls or went back.  Played as it is, a stall stops the
streamed path within one cycle at whatever speed it had, and the clock
running again takes the path to its full speed within one cycle: at a
rapid's speed a step change the controller's motion supervision refuses
(cell/safety.py ``SUPERVISION_ACCEL``), at a cutting feed a jerk it lets
through.  ``ReferenceRate.step`` turns that allowance into the step
actually played, ``dt_played_s``, through a rate ``r`` in [0, 1]
(reference seconds per sequence second) whose change per message is
bounded so that every joint's acceleration from the time-scaling,
|qdot_ref_j(tau)| * |dr/dt|, stays within ``ACCEL_FRACTION`` of the robot
file's ``acceleration_limit_deg_per_s2[j]`` (qdot_ref: the reference's own
joint speed around the played time, ``Reference.speed_at``; dt: the
sequence's step, the controller's time per message).

Rules:

* Following (r = 1) the step is the sequence's own while the played
  time stays within ``CLOCK_SLACK_S`` (2 ms) of the allowed time: an
  honest clock's whole-ms stamps (steps of 3, 5, 4 ms; -1, 0, +1 ms of
  jitter a stamp) play the path at its own speed, one step a message.
  Before, the allowance was played as it came: the played step followed
  the stamps' jitter, a step change of a quarter of a period's motion,
  which at 0.6 of the axis speeds the controller's supervision refused,
  and the path never got back within its step tolerance (397 of 400
  messages unanswered, tests/test_reference_stop.py).
* One answer plays one period of the path at the full rate, and after a
  lost datagram (a gap of up to ``MAX_JUMP``) what of the skipped time
  the step's change within the accelerations and the axis speeds allows
  (``_catch_up_s``: at a 2 deg/s feed 0.72 of a period, at a rapid 3 %),
  the rest counted behind the clock.  Before, the answer
  after a gap played them all: a step change of v T, which the
  supervision refused beyond 0.16 of the axis speeds, its fallback too,
  and every later message as well (150 of 150 unanswered after one lost
  datagram at 0.2 of the axis speeds; tests/test_reference_rate_fuzz.py).
* Otherwise the step is the one that puts the played time within
  ``CLOCK_SLACK_S`` ahead of the allowed time, within [r - dr, r + dr]
  times a period and never more than the sequence's own step
  (the sequence is the other witness of time: the played time is never
  ahead of the sequence's).  Before, the ramp put it on the allowed time
  and rose only with no lead at all: after a stall, an honest clock's
  3 ms stamps pulled the rate down at every one, and at a rapid the ramp
  up had not ended a second later (3.1 ms a 4 ms message; 218 ms of the
  path behind the clock against 76 ms without the jitter:
  tests/test_reference_rate_fuzz.py).
* Decelerating, the played time runs ahead of the clock's: that lead is
  kept, and r does not rise while more than the slack is left: it stays
  (0 after a full stop) until the clock's time has caught up, then ramps
  up, never above 1 (following again at 1 within the slack).  What the
  ramp up plays behind the clock is forgotten (as the time a stalled
  clock held the reference is): after a stop from full speed v
  and a restart the played reference is about v / (2 a) s behind where it
  would have been.
* A jump or a restart of the session (SessionClock's "jump" verdicts:
  their step is at most one period) is one more message through the same
  rule, the rate and the lead carried across: the played path's speed
  never steps there either (a restarted controller that stands still
  meanwhile is its own supervision's matter, as before).

The lead.  A stop from full speed takes at most ``stop_bound_s`` =
max_j v_j / (ACCEL_FRACTION a_j) of the sequence's time (v_j: the robot
file's axis speeds, which a reference is checked against; about v / a for
the joint that sets the pace) and plays at most that much reference time
ahead of a clock that stalled at its start, about v / (2 a) s (v^2 / (2 a)
of path) at a constant speed; a clock that runs again meanwhile shortens
it.  ``max_lead_s`` is the most seen (the run log: cycles.csv's t_ref_s
against its t_s; summary.json's ``reference_rate``).

Without acceleration limits in the robot file, or on a held (constant)
reference, ``of`` returns None: the loop plays the allowance as before.

Per message: two comparisons while following (0.44 us); a few float
operations and one ``speed_at`` (two or three rows of the reference)
under a ramp (5.3 us), two after a lost datagram.
"""

import math

from robstiff_drake.cell.session import MAX_JUMP, WRAP

# ASSUMPTION: the time-scaling may use the robot file's whole acceleration limit (1.0 of it), on top of the
# reference's own acceleration: the limit is what the file says the arm's planner ramps with (models/*.yaml: full
# axis speed in 0.25 s, no maker publishes it), the controller's supervision lets ten times it through
# (cell/safety.py SUPERVISION_ACCEL), and a smaller fraction lengthens the stop and the lead in proportion (a stop
# from 100 deg/s at 400 deg/s^2 takes 0.25 s and plays 0.125 s of the path ahead of the stalled clock; at 0.5 of
# it, 0.5 s and 0.25 s).
ACCEL_FRACTION = 1.0
# How far the played time may run ahead of the allowed time while following: the controllers' clock stamps are
# whole milliseconds (EGM, Stream Motion, RSI's IPOC), so the time elapsed between two of them is up to 1 ms off the
# time that passed, and a stamp that jitters by a millisecond (the tests' honest clock: -1, 0, +1 ms a stamp) up to
# 2 ms.  ASSUMPTION: 2 ms covers an honest controller's stamps (no maker states its stamps' jitter); a clock that
# falls further behind than that starts the ramp (bounded by the accelerations, so a jitterier clock costs a small
# slow-down, never a refused step), and the lead is 2 ms of the path at most, never a faster path.
CLOCK_SLACK_S = 2e-3


def _said(ramp):
    """Whether ramp number ``ramp`` (1, 2, ...) has its start and end said in the events: the first five and
    every hundredth, as the loop says the correction's saturation onsets (a clock 0.1 % slow, still honest by
    the session's checks, with whole-ms stamps starts a small ramp every second or so: a line each would fill
    events.csv; summary.json's ``reference_rate`` counts them all)."""
    return ramp <= 5 or ramp % 100 == 0


class ReferenceRate:
    """``step(dt_allowed_s, seq, reference, t_ref_s)`` -> the step to
    play (s); ``r`` the rate, ``lead_s`` the played time ahead of the
    allowed one (s)."""

    def __init__(self, period_s, accel_deg_per_s2, speed_deg_per_s=None, fraction=ACCEL_FRACTION, say=None):
        self.T = float(period_s)
        self.seq = None  # the last message's sequence number
        self.fraction = float(fraction)
        self.acc = [self.fraction * float(a) for a in accel_deg_per_s2]
        v = speed_deg_per_s
        self.vmax = None if v is None else [float(x) for x in v]
        # (a stop from full speed: at most this long on the sequence's time; None without the axis speeds)
        self.stop_bound_s = None if v is None else max(float(s) / a for s, a in zip(v, self.acc))
        self.say = say  # (a line at a ramp's start and at its end; None: silent)
        self.r = 1.0
        self.lead_s = 0.0
        self.following = True
        self.messages = 0  # messages played under a ramp
        self.ramps = 0  # ramps begun
        self.max_lead_s = 0.0
        self.min_rate = 1.0
        self._lag_s = 0.0  # the time the ramps up played behind the clock, forgotten (s)
        self._ramp_messages = self._ramp_lead_s = 0

    @classmethod
    def of(cls, period_s, robot, reference, say=None):
        """The rate for ``robot``'s limits, or None (the allowance played as it is): no acceleration limits in
        the robot file, or a held reference."""
        a = getattr(robot, "acceleration_limit_deg_per_s2", None)
        if a is None or getattr(reference, "t", None) is None or len(reference.t) < 2:
            return None
        return cls(period_s, list(a), getattr(robot, "speed_limit_deg_per_s", None), say=say)

    def seq_step_s(self, seq):
        """The sequence's step to message ``seq`` (s: the controller's time
        this message; one period for a jump or a restart, 0 for the first)."""
        last, self.seq = self.seq, seq
        if last is None:
            return 0.0
        ds = (seq - last) % WRAP
        return ds * self.T if 0 < ds <= MAX_JUMP else self.T

    def step(self, dt_allowed_s, seq, reference, t_ref_s):
        """The step to play this message (s): ``dt_allowed_s`` the session
        clock's allowance, ``seq`` the message's sequence number,
        ``reference.speed_at(t_ref_s)`` the reference's joint speeds (deg/s)
        around the played time."""
        dt_seq_s = self.seq_step_s(seq)
        # (what one answer plays at the full rate: one period, whatever the sequence skipped: after a lost
        # datagram the controller's next target is one period of the path from the last one it got, as every
        # other answer, the skipped period counted behind the clock; two periods in one answer were a step
        # change of v T, refused at more than 0.16 of the axis speeds, and the run locked out after it)
        step_s = min(dt_seq_s, self.T)
        if self.following and dt_seq_s > self.T:
            # (the speeds over the longer step: at its start and at its end, a path that accelerates included)
            speeds = [max(a, b) for a, b in zip(reference.speed_at(t_ref_s), reference.speed_at(t_ref_s + dt_seq_s))]
            step_s = min(dt_seq_s, self.T + self._catch_up_s(speeds))
        if self.following:
            lead = self.lead_s + step_s - dt_allowed_s
            if lead <= CLOCK_SLACK_S:
                # (the sequence's step: the stamps' jitter not played; the allowance beyond the played time, which
                # pays back this lead, never played beyond the sequence's)
                if lead < 0.0:  # (the allowance beyond the played time not played: counted behind the clock)
                    self._lag_s -= lead
                self.lead_s = max(lead, 0.0)
                self.max_lead_s = max(self.max_lead_s, self.lead_s)
                return step_s
            self.following = False
            self.ramps += 1
            self._ramp_messages, self._ramp_lead_s = 0, 0.0
            if self.say is not None and _said(self.ramps):
                bound = ("" if self.stop_bound_s is None else
                         f" (a stop from full speed in at most {self.stop_bound_s:.3f} s)")
                self.say(f"reference: the controller's clock allows {dt_allowed_s * 1e3:.1f} ms of a "
                         f"{dt_seq_s * 1e3:.1f} ms message: the played reference slows within the robot's "
                         f"acceleration limits{bound}")
        if step_s <= 0.0:
            played = 0.0
        else:
            # the rate's change this message: |qdot_j| * dr/dt <= acc_j on every joint
            k = math.inf
            for a, v in zip(self.acc, reference.speed_at(t_ref_s)):
                if v * k > a:
                    k = a / v
            dr = k * step_s
            r, lead = self.r, self.lead_s
            # (no rise while ahead of the clock by more than the slack; the played time put within the slack of
            # the allowed one, as while following: a 3 ms stamp of an honest clock does not pull the rate down)
            hi = (min(1.0, r + dr) if lead <= CLOCK_SLACK_S else r) * step_s
            lo = max(0.0, r - dr) * step_s
            played = min(max(dt_allowed_s - lead + CLOCK_SLACK_S, lo), hi)
            self.r = played / step_s
        lead = self.lead_s + played - dt_allowed_s
        if lead < 0.0:
            self._lag_s -= lead
            lead = 0.0
        self.lead_s = lead
        self.messages += 1
        self._ramp_messages += 1
        self.max_lead_s = max(self.max_lead_s, lead)
        self._ramp_lead_s = max(self._ramp_lead_s, lead)
        self.min_rate = min(self.min_rate, self.r)
        if self.r >= 1.0 and lead <= CLOCK_SLACK_S:
            self.r, self.following = 1.0, True
            if self.say is not None and _said(self.ramps):
                self.say(f"reference: played at the clock's pace again after {self._ramp_messages} messages under "
                         f"the ramp (at most {self._ramp_lead_s * 1e3:.1f} ms of the path played ahead of the "
                         f"clock; {self._lag_s * 1e3:.1f} ms behind it in all now)")
        return played

    def _catch_up_s(self, speeds_deg_per_s):
        """How much more than a period one answer may play after a lost
        datagram (s): the step's change within the acceleration limit
        (|qdot_j| dstep <= a_j T) and the step within the axis speeds
        ((T + dstep) |qdot_j| <= v_j T): at a cutting feed the skipped
        time whole, as before (2 deg/s: up to 0.8 of a period), at a
        rapid a few per cent of it."""
        extra = math.inf
        T = self.T
        for j, (a, q) in enumerate(zip(self.acc, speeds_deg_per_s)):
            if q > 0.0:
                extra = min(extra, a * T * T / q)
                if self.vmax is not None:
                    extra = min(extra, max(0.0, self.vmax[j] / q - 1.0) * T)
        return extra

    def summary(self):
        return {"messages_under_ramp": self.messages, "ramps": self.ramps, "max_lead_ms": self.max_lead_s * 1e3,
                "lowest_rate": self.min_rate, "behind_clock_ms": self._lag_s * 1e3,
                "stop_bound_s": self.stop_bound_s, "accel_fraction": self.fraction}
