"""KUKA's IPOC as a 32-bit millisecond counter (cell/rsi.py IPOC_WRAPS_MS:
the assumption) wraps after 49.7 days of the controller's uptime.  A
scripted RSI session crossing the wrap mid-path: the same session goes on
(before: the small IPOC after the wrap was a new epoch, a restart: a start
learnt again from one datagram's setpoint).  A true restart (a new epoch)
is still one.  No timing: the datagrams' arrival stamps are data."""

import socket

import numpy as np
import pytest

from robstiff_drake.cell import rsi
from robstiff_drake.cell.safety import Envelope, UnsafeTarget, clamp_deg, supervision_tolerances
from robstiff_drake.cell.session import SessionClock

T = 0.004
Q0 = [0.0, 7.008, 29.517, 0.0, 53.476, 0.0]


def _session(robot, *, wrap_ms=2**32, ipoc0_before=200, n=400, lost=0, epoch_ms=0, restart=False, late=False):
    """A KRC keeping its start S (every pose it commands: S + the AK it read) along a 2 deg/s path on q1; its IPOC
    ``ipoc0_before`` messages before ``wrap_ms`` at the first message, going round modulo ``wrap_ms``; at the wrap
    ``lost`` datagrams lost, ``epoch_ms`` more (a new epoch), ``restart``: a new RSI_MOVECORR there.  ``late``: the
    datagram before the wrap comes again after it.  Returns (link, largest |commanded - reference| deg, refusals,
    the session clock's verdicts)."""
    speed = 2.0
    lo, hi = tuple(np.degrees(robot.q_lower_rad)), tuple(np.degrees(robot.q_upper_rad))
    clamp = clamp_deg(robot, 0.5)
    sink = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sink.bind(("127.0.0.1", 0))
    link = rsi.RsiLink(0, ("127.0.0.1", None), T)
    link.reply_to = sink.getsockname()
    clock = SessionClock(T)
    q0 = np.asarray(Q0)
    start, pose, t_pc, worst, refused, verdicts = q0.copy(), q0.copy(), 0.0, 0.0, [], []
    ipoc = wrap_ms - 4 * ipoc0_before
    try:
        for i in range(n):
            at_wrap = i == ipoc0_before
            skipped = lost if at_wrap else 0
            if restart and at_wrap:
                start = pose.copy()
            if i:
                ipoc = (ipoc + 4 * (1 + skipped) + (epoch_ms if at_wrap else 0)) % wrap_ms
            t_pc += T * (1 + skipped)
            link.arrival_s = 1000.0 + t_pc
            if late and i == ipoc0_before + 1:  # the last datagram of before the wrap, again: late
                old = link.decode(rsi.encode_rob(wrap_ms - 4, pose, pose))
                verdicts.append(("late", clock.accept(old.seq, old.tm_ms)[0]))
            msg = link.decode(rsi.encode_rob(ipoc, pose, pose))
            verdicts.append((i, clock.accept(msg.seq, msg.tm_ms)[0]))
            ref = q0 + [speed * t_pc, 0, 0, 0, 0, 0]
            env = Envelope(lo, hi, tuple(ref), tuple(clamp + speed * T), tuple(pose),
                           tuple(clamp + speed * (T + 0.1)), *supervision_tolerances(robot, T))
            problem = link.answer_problem(msg, env)
            assert problem is None, (i, problem)
            try:
                link.send_targets(msg, ref.tolist(), env)
            except UnsafeTarget as e:
                refused.append(str(e))
                continue
            pose = start + rsi.decode_sen(sink.recv(65536))[1]
            worst = max(worst, float(np.abs(pose - ref).max()))
    finally:
        link.close()
        sink.close()
    return link, worst, refused, verdicts


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
    link, worst, refused, _ = _session(robot, epoch_ms=10_000_000, restart=True)
    assert link.session == 2 and link.wraps == 0
    assert not refused and worst <= float(clamp_deg(robot, 0.5).max()) + 2.0 * T + 1e-6, (worst, refused[:1])
