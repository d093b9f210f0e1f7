"""The reference's time `robstiff compensate` plays against the controller's
clock and sequence (cell/session.py ``SessionClock._pace``), over the loop's
own methods with scripted messages (tests/test_reference_pace.py's ``_drive``:
no socket, no timing).  Per case: the reference's time, the clock's elapsed
and the sequence's time (s) after the given messages, and over the run the
most the reference was ahead of the slower of the two and behind it (ms).

    python benchmarks/reference_pace.py

The figures in docs/real_cell.md ("Sequence and clock") and in
cell/session.py's docstring come from this script (before: the same script
over the code before the change).

Then a path moving at a rapid's joint speeds (0.6 of the axis speeds) and at
a cutting feed (2 deg/s) while the controller's clock stalls for 50 messages
and through a controller restart, under an honest clock whose stamps
jitter by a millisecond and with one datagram lost (tests/test_reference_stop.py's ``drive``:
the real send path's checks, the
correction held at zero), with the played reference's rate
(cell/reference_rate.py) and without it (before): the largest commanded
second difference over the acceleration limit * T^2 and over the
supervision's bound (10 times it), the targets refused and the messages
unanswered, the stop's time (from the stall's first message to the first
commanded step of zero), the most the played time led the clock and how far
behind it it ends."""

import os
import sys

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "tests"))

from test_reference_pace import _drive  # noqa: E402

from robstiff_drake.cell.egm import EgmLink  # noqa: E402
from robstiff_drake.cell.stream_motion import StreamMotionLink  # noqa: E402


def cases():
    k = np.arange(300)
    yield "EGM 4 ms, --period-ms 8", 8, 1 + k, 7_000 + 4 * k, EgmLink
    yield "Stream Motion 4 ms (250 Hz), --period-ms 8", 8, 1 + k, 7_000 + 4 * k, StreamMotionLink
    yield "EGM 4 ms, --period-ms 12", 12, 1 + k, 7_000 + 4 * k, EgmLink
    jitter = np.random.default_rng(5).integers(-1, 2, 1000)
    jitter[0] = 0
    yield "EGM 4 ms, stamps -1/0/+1 ms (honest), 1000 messages", 4, 1 + np.arange(1000), \
        1_000 + 4 * np.arange(1000) + jitter, EgmLink
    yield "a clock at 3 ms a 4 ms message", 4, 1 + k, 500 + 3 * k, EgmLink
    yield "the sequence steps two a message, the clock 4 ms", 4, 1 + 2 * k, 500 + 4 * k, EgmLink
    yield "a clock that stalls for messages 100-149", 4, 1 + k, \
        500 + np.where(k < 100, 4 * k, np.where(k < 150, 400, 400 + 4 * (k - 150))), EgmLink
    yield "a clock 3 ms ahead at message 100 (no fault)", 4, 1 + k, np.where(k < 100, 4 * k, 403 + 4 * (k - 100)), \
        EgmLink
    yield "a clock 1 s ahead at message 100, then 3 ms a message", 4, 1 + k, \
        np.where(k < 100, 4 * k, 1400 + 3 * (k - 100)), EgmLink


def main():
    from robstiff_drake.model.robot import load_robot

    robot = load_robot()
    for name, period_ms, seqs, stamps, kind in cases():
        _, ts, _, _ = _drive(robot, period_ms, seqs, stamps, kind)
        seq_s = (np.asarray(seqs) - seqs[0]) * period_ms * 1e-3
        clock_s = (np.asarray(stamps, dtype=float) - stamps[0]) * 1e-3
        if "ahead at message 100" in name:  # (the jump's step counted as the sequence's: what may be followed)
            clock_s = np.where(np.arange(len(ts)) < 100, clock_s, clock_s - (clock_s[100] - seq_s[100]))
        slower = np.minimum(seq_s, clock_s)
        at = [i for i in (25, 100, 199, 999) if i < len(ts)]
        rows = "; ".join(f"after {i}: reference {ts[i]:.3f}, clock {clock_s[i]:.3f}, sequence {seq_s[i]:.3f}"
                         for i in at)
        print(f"[{name}] {rows}; ahead of the slower by at most {(ts - slower).max() * 1e3:.1f} ms, behind it by "
              f"at most {(slower - ts).max() * 1e3:.1f} ms", flush=True)


def honest(n=400):
    """tests/test_reference_stop.py's honest clock: seqs and stamps (ms) jittering by -1, 0 or +1 ms (seed 5)."""
    k = np.arange(n)
    jitter = np.random.default_rng(5).integers(-1, 2, n)
    jitter[0] = 0
    return 1 + k, 1_000 + 4 * k + jitter


def lost(n=300, at=150):
    """Seqs and stamps (ms) of an honest 4 ms clock with one datagram lost (a sequence gap of 2) at ``at``."""
    k = np.arange(n)
    seqs = 1 + k + (k >= at)
    return seqs, 500 + 4 * (seqs - 1)


def stops():
    from test_reference_stop import STALL, T, drive, speeds, stalled

    from robstiff_drake.cell.safety import SUPERVISION_ACCEL
    from robstiff_drake.model.robot import load_robot

    robot = load_robot()
    acc_T2 = np.asarray(robot.acceleration_limit_deg_per_s2) * T**2
    k = np.arange(200)
    scenarios = [("a stall of 50 messages, the clock on from its stalled stamp", stalled(resume="on")),
                 ("a stall of 50 messages, the stalled time back in one step", stalled(resume="back")),
                 ("a controller restart after 200 messages", (np.r_[1 + k, 1 + k], np.r_[500 + 4 * k, 4 * k])),
                 ("an honest clock, stamps -1/0/+1 ms, 400 messages", honest()),
                 ("one lost datagram at message 150 of 300", lost())]
    for case in ("rapid", "feed"):
        for name, (seqs, stamps) in scenarios:
            for ramp in (False, True):
                loop, cmd, ts, tr, _ = drive(robot, speeds(robot, case), seqs, stamps, ramp=ramp)
                worst = (np.asarray(loop.link.tried_d2) / acc_T2).max()  # (of every target checked: refused too)
                still = np.flatnonzero((np.abs(np.diff(cmd, axis=0)) < 1e-12).all(axis=1))
                first = still[still >= STALL[0] - 1]
                stop = ""
                if "stall" in name and len(cmd) == len(seqs):
                    stop = f"; stop in {(first[0] - (STALL[0] - 1)) * T:.3f} s" if len(first) else "; no stop"
                v = speeds(robot, case)
                print(f"[{name}, {case} (q1 {v[0]:g} deg/s), {'with the rate' if ramp else 'before'}] largest "
                      f"second difference {worst:.2f} x the acceleration limit * T^2 ({worst / SUPERVISION_ACCEL:.3f} "
                      f"x the supervision's bound); {loop.n.refused} refused, {loop.n.unanswered_refused} "
                      f"unanswered{stop}; lead over the clock at most {(tr - ts).max() * 1e3:.1f} ms; behind it at "
                      f"the end {(ts[-1] - tr[-1]) * 1e3:.1f} ms", flush=True)


if __name__ == "__main__":
    main()
    stops()
