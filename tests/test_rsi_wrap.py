"""KUKA's IPOC as a 32-bit millisecond counter (cell/rsi.py IPOC_WRAPS_MS:
the assumption) wraps after 49.7 days of the controller's uptime.  A
scripted RSI session crossing the wrap mid-path: the same session goes on
(before: the small IPOC after the wrap was a new epoch, a restart: a start
learnt again from one datagram's setpoint).  A true restart (a new epoch)
is still one.  No timing: the datagrams' arrival stamps are data."""

import os
import sys

import pytest

sys.path.insert(0, os.path.dirname(__file__))
from rsi_session import T, drive  # noqa: E402

from robstiff_drake.cell.safety import clamp_deg  # noqa: E402


def _session(robot, *, wrap_ms=2**32, ipoc0_before=200, n=400, lost=0, epoch_ms=0, restart=False, late=False):
    """A KRC keeping its start along a 2 deg/s path on q1 (tests/rsi_session.py); its IPOC ``ipoc0_before``
    messages before ``wrap_ms`` at the first message, going round modulo ``wrap_ms``; at the wrap ``lost``
    datagrams lost, ``epoch_ms`` more (a new epoch), ``restart``: a new RSI_MOVECORR there.  ``late``: the
    datagram before the wrap comes again after it.  Every setpoint must pass the link's check.  Returns (link,
    largest |commanded - reference| deg, refusals, the session clock's verdicts)."""
    return drive(robot, speed_deg_per_s=2.0, first_ipoc=wrap_ms - 4 * ipoc0_before, event_at=ipoc0_before, n=n,
                 lost=lost, epoch_ms=epoch_ms, restart=restart, wrap_ms=wrap_ms, late=late, setpoints_checked=True)


@pytest.mark.parametrize("wrap_ms", [2**32, 2**31], ids=["32-bit", "31-bit"])
def test_an_ipoc_wrap_mid_path_is_the_same_session(robot, wrap_ms):
    """Before: the IPOC after the wrap (4 ms after 2**32 - 4) a backwards jump, a new session (the start learnt
    again from that datagram's setpoint, 0.8 deg along the path).  After: one session, every message consistent
    for the session check, every answer checked and within the clamp of the reference."""
    link, worst, refused, verdicts = _session(robot, wrap_ms=wrap_ms)
    assert link.session == 1 and link.wraps == 1, (link.session, link.wraps)
    assert not refused and worst <= float(clamp_deg(robot, 0.5).max()) + 2.0 * T + 1e-6, (worst, refused[:1])
    assert all(v == "ok" for _, v in verdicts), [x for x in verdicts if x[1] != "ok"][:3]


def test_a_late_datagram_of_before_the_wrap_is_old_not_a_restart(robot):
    link, _, refused, verdicts = _session(robot, late=True, n=260)
    assert link.session == 1 and not refused
    assert ("late", "old") in verdicts, verdicts[198:204]


def test_lost_datagrams_at_the_wrap_are_the_lost_datagram_case(robot):
    """Seven datagrams lost across the wrap: as lost datagrams without a wrap (tests/test_cell_review.py), the
    answer must be safe from the old start too, and on a 2 deg/s path it is not: refused."""
    link, _, refused, _ = _session(robot, lost=7, n=210)
    assert link.wraps == 1 and link.session == 2
    assert refused and "the old start" in refused[0], refused[:1]


def test_a_new_epoch_near_the_wrap_is_still_a_restart(robot):
    """A restart (a new RSI_MOVECORR, its IPOC 10^7 ms on: past the wrap, and far beyond the time passed here) is a
    new session as before, its answers within the bounds from the new start."""
    # (a restart silences the controller first: 8 periods here, as test_cell_review's; cell/rsi.py takes a new
    # epoch at the period's cadence for a time stamp that jumped, not a restart)
    link, worst, refused, _ = _session(robot, epoch_ms=10_000_000, restart=True, lost=7)
    assert link.session == 2 and link.wraps == 0
    assert not refused and worst <= float(clamp_deg(robot, 0.5).max()) + 2.0 * T + 1e-6, (worst, refused[:1])
