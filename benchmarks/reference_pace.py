"""The reference's time `robstiff compensate` plays against the controller's
clock and sequence (cell/session.py ``SessionClock._pace``), over the loop's
own methods with scripted messages (tests/test_reference_pace.py's ``_drive``:
no socket, no timing).  Per case: the reference's time, the clock's elapsed
and the sequence's time (s) after the given messages, and over the run the
most the reference was ahead of the slower of the two and behind it (ms).

    python benchmarks/reference_pace.py

The figures in docs/real_cell.md ("Sequence and clock") and in
cell/session.py's docstring come from this script (before: the same script
over the code before the change)."""

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


if __name__ == "__main__":
    main()
