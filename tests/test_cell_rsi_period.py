"""KUKA RSI's IPOC and compensate's --period-ms: the loop over a real RsiLink
(its one send path, the answers read back from a sink socket as a KRC reads
them), each datagram handed over by script with its arrival on a clock the
test sets (tests/test_cell_review_loop.py's way: no timing).

A KRC's IPOC is the millisecond time stamp of its interpolation cycle: it
steps by the cycle, 4 ms with RSI's IPO_FAST, 12 ms in IPO mode (ROS-
Industrial's kuka_rsi_simulator steps it by its cycle_time; KUKA's RSI
manual calls it the cycle's time stamp); the sequence the session check
reads is IPOC / --period-ms.

* --period-ms 4 against a 12 ms IPO: every message skipped two numbers,
  counted as two datagrams lost, no fault, nothing said (before); now one
  line names the cycle and the --period-ms to set, the lost count is
  honest (0) and the correction is held at zero (the loop was checked and
  tuned for 4 ms).
* --period-ms 12 against 4 ms: two messages in three fell on the last
  one's number and were dropped as "duplicates" (before), silently; now
  named likewise.
* an honest KRC whose IPOC is half a cycle off the --period-ms grid
  (1_000_002 + 4 k; 1_000_002 + 12 k at 12 ms): every other message was dropped as a duplicate (the
  rounding of IPOC / period, ties to even); now the grid is the session's
  own (its first IPOC's phase): none dropped.
* an IPOC that jitters by 0-2 ms (no KRC's: its IPOC counts whole cycles)
  still loses the messages that fall within the last one's cycle, but they
  are no longer called duplicates: one line says why, and a true duplicate
  (the same IPOC again) is still one.
"""

import io
import math
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(__file__))
import cell_helpers as h  # noqa: E402
from test_cell_review_loop import Q0, ScriptedLink, _ScriptedSensor, scripted_clock  # noqa: E402

from robstiff_drake.cell import rsi  # noqa: E402

WRONG = "--period-ms is not the controller's cycle"
BETWEEN = "within the last one's cycle"


class _ScriptedKrc(ScriptedLink):
    """An RsiLink whose receive hands over one scripted datagram (IPOC, or None: silent) at a time, each
    ``step_s`` after the last on the test's clock (ScriptedLink); ``aks``: the answers' AK read back."""

    def __init__(self, period_s, ipocs, clock, step_s):
        super().__init__(rsi.RsiLink(0, ("127.0.0.1", None), period_s), ipocs, clock, step_s)
        self.aks = self.answers

    def _message(self, ipoc):
        self.link.arrival_s = self.clock[0]
        return self.link.decode(rsi.encode_rob(ipoc, Q0, Q0))

    def first(self):
        self.link.arrival_s = self.clock[1]
        return self.link.decode(rsi.encode_rob(self.script.pop(0), Q0, Q0))

    def _answer(self, data):
        return rsi.decode_sen(data)[1]


def _run(robot, period_s, ipocs, step_s):
    """The loop at --period-ms ``period_s`` over the KRC's ``ipocs`` (one every ``step_s`` on the test's clock),
    holding Q0 with a push on the sensor (a correction of about 0.14 deg); returns (loop, its log text, the AKs)."""
    from robstiff_drake.cell.compensate import CompensatorLoop, LoopSettings, Reference

    w = (np.asarray(h.hold_wrench(robot, np.radians(Q0))(0.0)) + [3000.0, -2000.0, 0.0, 0.0, 0.0, 0.0]).tolist()
    clock = scripted_clock()
    krc = _ScriptedKrc(period_s, ipocs, clock, step_s)
    sensor = _ScriptedSensor(w, clock)
    ref = Reference(period_s=period_s)
    ref.hold(Q0)
    out = io.StringIO()
    loop = CompensatorLoop(h.hold_compensator(robot, w), krc.link, sensor, ref, robot,
                           LoopSettings(period_s=period_s, max_jump_Nm=350.0, max_correction_mm=math.inf,
                                        max_correction_deg=math.inf, start_tolerance_N=math.inf,
                                        sensor_rate_hz=1.0 / step_s), out=out)
    loop.pc_time = lambda: clock[0]
    clock[0] = clock[1]
    try:
        loop.run((krc.first(), clock[0]))
    finally:
        krc.close()
    return loop, out.getvalue(), np.array(krc.aks)


def test_rsi_4_ms_set_on_a_12_ms_ipo_is_named_with_the_period_to_set_and_nothing_counted_lost(robot):
    from robstiff_drake.cell.loop_stats import loop_stats

    n = 200
    loop, text, aks = _run(robot, 0.004, [1_000_000 + 12 * k for k in range(n)], 0.012)
    said = [ln for ln in text.splitlines() if WRONG in ln]
    assert len(said) == 1, text  # once a run (before: nothing said)
    assert "IPOC stepped 12 ms a message" in said[0] and "where --period-ms is 4;" in said[0], said[0]
    assert "start compensate again with --period-ms 12" in said[0], said[0]
    stats = loop_stats(loop)
    assert stats["lost_in_network"] == 0, stats  # (before: 398, two a message)
    assert stats["cycles"] == n and stats["health"]["verdict"] == "poor", stats
    assert "period" in loop.faults  # held for the run: the loop was checked and tuned for 4 ms
    assert np.abs(aks[:25]).max() > 0.01 and np.abs(aks[-1]).max() == 0.0  # ramped in, then to zero


def test_rsi_12_ms_set_on_a_4_ms_krc_is_named_and_its_messages_are_not_called_duplicates(robot):
    from robstiff_drake.cell.loop_stats import loop_stats

    loop, text, _ = _run(robot, 0.012, [1_000_000 + 4 * k for k in range(150)], 0.004)
    said = [ln for ln in text.splitlines() if WRONG in ln]
    assert len(said) == 1, text  # (before: 2 messages in 3 dropped as duplicates, nothing said)
    assert "IPOC stepped 4 ms a message" in said[0] and "start compensate again with --period-ms 4" in said[0]
    stats = loop_stats(loop)
    assert stats["duplicates_dropped"] == 0 and stats["between_cycles_dropped"] == 99, stats
    assert "period" in loop.faults


def test_an_honest_krc_half_a_cycle_off_the_grid_loses_nothing(robot):
    """IPOC 1_000_002 + 4 k at --period-ms 4 (and 1_000_002 + 12 k at 12, 6 ms off): before, round(IPOC /
    period) tied to even on every message and every other one was a 'duplicate', dropped unanswered (the KRC's
    late-packet limit then stops the robot)."""
    for period_ms, first in ((4, 1_000_002), (12, 1_000_002)):
        loop, text, aks = _run(robot, period_ms * 1e-3, [first + period_ms * k for k in range(100)],
                               period_ms * 1e-3)
        assert loop.n.duplicates == 0 and loop.n.between_cycles == 0, (period_ms, text)
        assert loop.n.answered == 100 and loop.n.lost == 0 and not loop.faults, (period_ms, text)


def test_an_ipoc_that_jitters_is_dropped_within_its_cycle_with_the_reason_and_a_true_duplicate_is_one(robot):
    rng = np.random.default_rng(0)
    ipocs = [1_000_000 + 4 * k + int(j) for k, j in enumerate(rng.integers(0, 3, 300))]
    ipocs[0] = 1_000_000  # (the session's grid from a message at the jitter's low end: 0-2 ms later ones then
    # round to the next cycle at 2 ms; from one in the middle, 1 ms, none would fall within a cycle)
    ipocs[150:150] = [ipocs[149]]  # the same datagram again: a true duplicate
    loop, text, _ = _run(robot, 0.004, ipocs, 0.004)
    said = [ln for ln in text.splitlines() if BETWEEN in ln]
    assert said and "a KRC's IPOC steps by whole cycles" in said[0], text
    assert loop.n.duplicates == 1, text  # (before: 52, every one within a cycle called a duplicate)
    assert loop.n.between_cycles > 20, loop.n.between_cycles
    assert loop.n.answered + loop.n.between_cycles + loop.n.duplicates == len(ipocs)
    assert WRONG not in text
