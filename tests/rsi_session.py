"""A scripted KUKA RSI session for the link's tests (tests/test_cell_review.py,
tests/test_rsi_wrap.py): a KRC keeping its start S (every pose it commands
is S + the AK it read) along a path moving q1, answered by an RsiLink as
the loop answers (target = the reference, the envelope of
cell/compensate.py).  No timing: the datagrams' arrival stamps are data
(4 ms a message on the PC's clock)."""

import socket

import numpy as np

from robstiff_drake.cell import rsi
from robstiff_drake.cell.safety import Envelope, UnsafeTarget, clamp_deg, supervision_tolerances
from robstiff_drake.cell.session import SessionClock

T = 0.004
Q0 = [0.0, 7.008, 29.517, 0.0, 53.476, 0.0]


def drive(robot, *, speed_deg_per_s, first_ipoc, event_at, n, lost=0, epoch_ms=0, restart=False, wrap_ms=None,
          late=False, setpoints_checked=False):
    """Messages 0..n-1, the first with IPOC ``first_ipoc``, each 4 ms on
    (modulo ``wrap_ms`` when given); at message ``event_at`` ``lost``
    datagrams were lost on the way (the IPOC skips them), ``epoch_ms`` more
    (a new epoch), ``restart``: a new RSI_MOVECORR there (its start the pose
    it stands at); ``late``: the datagram before ``event_at`` comes again
    after it; ``setpoints_checked``: every message's setpoint must pass the
    link's check (``answer_problem``).  Returns (the link (closed), the
    largest |commanded - reference| (deg), the link's refusals, the session
    clock's verdicts)."""
    lo, hi = tuple(np.degrees(robot.q_lower_rad)), tuple(np.degrees(robot.q_upper_rad))
    clamp = clamp_deg(robot, 0.5)
    sink = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sink.bind(("127.0.0.1", 0))
    link = rsi.RsiLink(0, ("127.0.0.1", None), T)
    link.reply_to = sink.getsockname()
    clock = SessionClock(T)
    q0 = np.asarray(Q0)
    start, pose, t_pc, worst, refused, verdicts = q0.copy(), q0.copy(), 0.0, 0.0, [], []
    ipoc = before = first_ipoc
    late_ipoc = None  # (the IPOC of the message before the event)
    try:
        for i in range(n):
            at_event = i == event_at
            skipped = lost if at_event else 0
            if restart and at_event:
                start = pose.copy()
            if i:
                before = ipoc
                ipoc = ipoc + 4 * (1 + skipped) + (epoch_ms if at_event else 0)
                if wrap_ms is not None:
                    ipoc %= wrap_ms
            t_pc += T * (1 + skipped)
            link.arrival_s = 1000.0 + t_pc
            if late and i == event_at + 1:  # the last datagram of before the event, again: late
                old = link.decode(rsi.encode_rob(late_ipoc, pose, pose))
                verdicts.append(("late", clock.accept(old.seq, old.tm_ms)[0]))
            if at_event:
                late_ipoc = before
            msg = link.decode(rsi.encode_rob(ipoc, pose, pose))
            verdicts.append((i, clock.accept(msg.seq, msg.tm_ms)[0]))
            ref = q0 + [speed_deg_per_s * t_pc, 0, 0, 0, 0, 0]
            env = Envelope(lo, hi, tuple(ref), tuple(clamp + speed_deg_per_s * T), tuple(pose),
                           tuple(clamp + speed_deg_per_s * (T + 0.1)), *supervision_tolerances(robot, T))
            if setpoints_checked:
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
