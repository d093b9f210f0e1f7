"""The controller's clock summed against its sequence (cell/session.py):
each step may pass the per-message tolerance (half a period + 1 ms) while
their sum runs away; the reference's time must stay with the sequence's.
(Before: a clock at 6 ms a 4 ms message passed every message and the
reference ran at 1.5 times the program's pace, the arm following it.)"""

import numpy as np
import pytest

from robstiff_drake.cell.session import SessionClock


def _run(period_ms, stamps_ms, seqs=None):
    """The verdicts and the reference's time (s) after each message."""
    c = SessionClock(period_ms * 1e-3)
    seqs = range(1, len(stamps_ms) + 1) if seqs is None else seqs
    verdicts, t, ts = [], 0.0, []
    for seq, tm in zip(seqs, stamps_ms):
        v, dt = c.accept(seq, int(tm) & 0xFFFFFFFF)
        verdicts.append(v)
        t += dt
        ts.append(t)
    return c, verdicts, np.array(ts)


@pytest.mark.parametrize("period_ms", [4, 8, 12])
def test_honest_clocks_with_their_resolution_and_jitter_pass(period_ms):
    """A controller's clock in whole ms, stamped up to 1 ms late at random
    (fixed seed), 10,000 messages, one in 50 lost (the sequence skips one),
    wrapping its 32-bit counter: no fault; the reference's time within 1 ms
    of the sequence's throughout."""
    rng = np.random.default_rng(7)
    seqs = np.cumsum(1 + (rng.random(10_000) < 0.02))
    t0 = 2**32 - 20_000  # (the counter wraps in the run)
    stamps = t0 + np.round((seqs - 1) * period_ms + rng.uniform(0.0, 1.0, seqs.size))
    c, verdicts, ts = _run(period_ms, stamps, seqs)
    assert set(verdicts) == {"ok"}
    assert np.abs(ts - (seqs - 1) * period_ms * 1e-3).max() <= 1.001e-3


@pytest.mark.parametrize("ms_per_message, faulted_from", [(6.0, 2), (2.0, 2), (4.5, 7), (3.6, 9)])
def test_a_clock_at_another_pace_is_a_fault_and_the_reference_keeps_the_sequences_time(ms_per_message,
                                                                                        faulted_from):
    """The clock at ``ms_per_message`` a 4 ms message (each step within the
    3 ms allowed): the clock's fault from the message where the sum first
    passes 3 ms, and never CLEAR_MESSAGES consistent messages in a row
    after it (the loop's fault never clears: a clock at 4.5 ms stamps 4 and
    5 ms in turn, and its sum, never clamped, keeps even its 4 ms steps the
    fault: tests/test_checks_attacked.py), and the reference's time the
    slower of the sequence's and the clock's, within 3 ms (at 6 ms: before,
    1.5 times the sequence's, 2 s ahead after 1000 messages; at 2 and 3.6
    ms it kept the sequence's, ahead of the clock's by 2 s and 0.4 s after
    1000 messages: tests/test_reference_pace.py)."""
    from robstiff_drake.cell.compensate import CLEAR_MESSAGES

    n = 1000
    stamps = np.round(np.arange(n) * ms_per_message)
    c, verdicts, ts = _run(4, stamps)
    first = verdicts.index("clock")
    runs = "".join("c" if v == "clock" else "o" for v in verdicts[first:]).split("c")
    assert first == faulted_from and max(len(r) for r in runs) < CLEAR_MESSAGES, verdicts[:12]
    slower = np.minimum(np.arange(n) * 4e-3, (stamps - stamps[0]) * 1e-3)
    assert (ts <= slower + 1e-12).all() and (ts >= slower - 3e-3 - 1e-12).all()
    assert c.clock_reason[0] == "drift"


def test_a_restart_starts_the_sum_again():
    """A clock 2 ms a message fast for 10 messages (faulted from the third),
    then a controller restart numbered from 1 with an honest clock: no
    fault after the restart's own."""
    stamps = list(np.arange(10) * 6) + list(np.arange(40) * 4)
    seqs = list(range(1000, 1010)) + list(range(1, 41))
    c, verdicts, _ = _run(4, stamps, seqs)
    assert "clock" in verdicts[:10]
    after = verdicts[10:]
    assert after[0] == "jump" and set(after[1:]) == {"ok"}, after[:6]
