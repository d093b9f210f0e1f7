"""The compensator's loop over scripted messages that carry their own
arrival times (several in one read: this PC stalled) and a wrist sensor
whose records arrive at their own times (each stamped with its arrival,
NaN where the script marks it invalid): the sensor's checks judged on
arrival times as a real reader stamps them, not rounded to the messages'.
The test's clock (tests/test_cell_review_loop.py's) is the loop's PC
clock: no timing.  Used by tests/test_checks_attacked.py and
benchmarks/checks_attacked.py."""

import io
import math
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(__file__))
import cell_helpers as h  # noqa: E402
from test_cell_review_loop import Q0, T, _ScriptedEgm, scripted_clock  # noqa: E402

PUSH = [300.0, -200.0, 0.0, 0.0, 0.0, 0.0]  # a cut's push on the sensor (N, N*m): a correction of 0.017 deg


class TimedSensor:
    """Per drain: the records whose arrival (s after the run's first message) has come on the test's clock."""

    def __init__(self, w, clock, times_s, invalid=None):
        self.w, self.clock, self.times = list(w), clock, np.asarray(times_s, float)
        self.invalid = np.zeros(self.times.size, bool) if invalid is None else np.asarray(invalid, bool)
        self.i = 0

    def drain(self):
        j = int(np.searchsorted(self.times, self.clock[0] - self.clock[1] + 1e-12, side="right"))
        nan = [math.nan] * 6
        got = [(nan if bad else list(self.w), self.clock[1] + t, 0, False)
               for t, bad in zip(self.times[self.i:j], self.invalid[self.i:j])]
        self.i = j
        return got


def plain(n, period_s=T, arrive=None):
    """``n`` reads of one message each: sequence k + 1, clock k periods (ms), arrival ``arrive(k)`` (s; default
    k periods)."""
    return [[(k + 1, round(k * period_s * 1e3), arrive(k) if arrive else k * period_s)] for k in range(n)]


def jittered(rate_hz, periods, duration_s, seed):
    """A stream at ``rate_hz`` whose records each arrive up to ``periods`` record periods early or late (uniform,
    fixed seed), in order; from 50 ms before the first message."""
    rng = np.random.default_rng(seed)
    k = np.arange(-5, int((duration_s + 0.1) * rate_hz))
    return np.sort((k + rng.uniform(-periods, periods, k.size)) / rate_hz)


def drive(robot, reads, rec_times, *, invalid=None, **settings):
    """The loop holding Q0 over ``reads`` (each a list of (sequence, clock ms, arrival s); [] a silent read), the
    sensor reading the hold pose's wrench plus PUSH at ``rec_times`` (s; ``invalid``: those NaN), LoopSettings
    ``settings`` (no start check unless given).  Returns (loop, the corrections answered, deg)."""
    from robstiff_drake.cell.compensate import CompensatorLoop, LoopSettings, Reference
    from robstiff_drake.cell.link import Message

    air = np.asarray(h.hold_wrench(robot, np.radians(Q0))(0.0))
    clock = scripted_clock()
    script = [[(Message(s, int(tm) & 0xFFFFFFFF, list(Q0)), a) for s, tm, a in r] for r in reads]
    first, rest = script[0][0], script[1:]
    link = _ScriptedEgm([], clock)

    def receive(timeout_s):
        link._collect()
        if not rest:
            raise KeyboardInterrupt  # the script's end
        got = rest.pop(0)
        if not got:
            clock[0] += settings.get("period_s", T)
            return []
        clock[0] = clock[1] + got[-1][1]
        return [(m, clock[1] + a) for m, a in got]

    link.link.receive = receive
    sensor = TimedSensor(air + PUSH, clock, rec_times, invalid)
    ref = Reference(period_s=settings.get("period_s", T))
    ref.hold(Q0)
    loop = CompensatorLoop(h.hold_compensator(robot, air.tolist()), link.link, sensor, ref, robot,
                           LoopSettings(**{"max_jump_Nm": 350.0, "start_tolerance_N": math.inf, **settings}),
                           out=io.StringIO())
    loop.pc_time = lambda: clock[0]
    clock[0] = clock[1] + first[1]
    try:
        loop.run((first[0], clock[0]))
    finally:
        link.close()
    return loop, np.array(link.commanded) - np.asarray(Q0)


def summary(loop, corr, label):
    """One line: the faults, the rate check's figures, the corrections."""
    dev = np.abs(corr).max(axis=1) if len(corr) else np.zeros(1)
    rc = loop.rate_check
    at = loop.faults.get("sensor rate")
    on = np.flatnonzero(dev > 1e-9)
    spread = f"{rc['least_hz']:.0f}-{rc['most_hz']:.0f} Hz" if rc["least_hz"] is not None else "-"
    return (f"[{label}] rate fault at message {None if at is None else round(at / loop.s.period_s)}; "
            f"sensor faults {loop.n.sensor_faults}; most silences in a row {rc['silences_in_a_row']}; windows "
            f"{rc['windows_judged']} ({spread}); {int((dev > 1e-9).sum())} of {len(dev)} answers corrected, the last "
            f"{int(on[-1]) if on.size else None}; faults at the end {sorted(loop.faults) or 'none'}")
