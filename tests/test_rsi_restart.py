"""A KUKA controller that restarts RSI in the middle of a path (a new
RSI_MOVECORR: a new IPOC epoch, its axis corrections counted from a new
start pose): the compensator re-learns the start, and every pose the
controller commands (its start + AK) stays within the correction's clamp of
the reference and within the axis speed of the last one.

Two controllers: a scripted one (lockstep: one <Rob>, then its <Sen>; no
timing on a loaded machine) and the project's simulated KRC
(cell/sim_cell.py with cell/rsi.RsiControllerLink) in lockstep."""

import math
import os
import select
import socket
import sys
import time

import numpy as np
import pytest

pytest.importorskip("pynetft", reason="the cell tests need pynetft (pip install '.[test]')")
pytest.importorskip("abb_robot_client", reason="the cell tests need abb-robot-client (pip install '.[test]')")

sys.path.insert(0, os.path.dirname(__file__))
import cell_helpers as h  # noqa: E402

from robstiff_drake.cell import rsi  # noqa: E402
from robstiff_drake.cell.safety import clamp_deg  # noqa: E402
from robstiff_drake.model.robot import load_robot  # noqa: E402

T = 0.004


def _moving_reference(folder, q0_deg, amplitude_deg=30.0, duration_s=2.0):
    """A joint reference (CSV) whose q1 and q2 move by a cosine profile
    (q1 by ``amplitude_deg``, q2 by a third of it) over ``duration_s``: a
    path fast enough that the old start and a new one differ by degrees."""
    ts = np.arange(0.0, duration_s + 1e-9, T)
    s = 0.5 - 0.5 * np.cos(np.pi * ts / duration_s)
    q = np.tile(np.asarray(q0_deg, dtype=float), (len(ts), 1))
    q[:, 0] += amplitude_deg * s
    q[:, 1] += amplitude_deg / 3.0 * s
    path = os.path.join(folder, "moving.csv")
    with open(path, "w") as f:
        f.write("# test joint reference: q1 and q2 by a cosine profile\n")
        f.write("t_s," + ",".join(f"q{j}_deg" for j in range(1, 7)) + "\n")
        for t, row in zip(ts, q):
            f.write(f"{t:.4f}," + ",".join(f"{v:.9f}" for v in row) + "\n")
    return path, lambda t: np.array([np.interp(t, ts, q[:, j]) for j in range(6)])


class ScriptedKrc:
    """A KRC that sends <Rob> (AIPos = ASPos = the pose it commands) and
    waits for each <Sen>; it commands its start + AK, and ``restart``
    starts a new RSI session: another IPOC epoch, the start the pose it
    stands at."""

    def __init__(self, pc_port, start_deg, ipoc0=1_000_000):
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.pc = ("127.0.0.1", pc_port)
        self.start = list(start_deg)
        self.commanded = list(start_deg)
        self.ipoc0, self.i = ipoc0, 0

    def restart(self, ipoc0, silence_s=0.1):
        """RSI_OFF, then RSI_ON/RSI_MOVECORR: ``silence_s`` without a
        datagram (a restart is no time stamp that jumps at the period's
        cadence: cell/rsi.RESTART_SILENCE_PERIODS), then the new epoch."""
        time.sleep(silence_s)
        self.ipoc0, self.i = ipoc0, 0
        self.start = list(self.commanded)

    def cycle(self, timeout_s=10.0):
        """One <Rob>, its <Sen>: the pose commanded (deg), or None."""
        ipoc = self.ipoc0 + int(round(self.i * T * 1e3))
        self.i += 1
        self.sock.sendto(rsi.encode_rob(ipoc, self.commanded, self.commanded), self.pc)
        r, _, _ = select.select([self.sock], [], [], timeout_s)
        if not r:
            return None
        got_ipoc, ak = rsi.decode_sen(self.sock.recvfrom(65536)[0])
        if got_ipoc != ipoc:
            return None
        self.commanded = [s + a for s, a in zip(self.start, ak)]
        return list(self.commanded)


@pytest.mark.parametrize("amplitude_deg", [10.0, 30.0], ids=["slow", "fast"])
def test_rsi_restart_with_a_new_start_pose_and_ipoc_epoch(tmp_path, amplitude_deg):
    """A restart 0.8 s into the path (3.5 or 10 deg from the first start).
    Slow path: every message answered, the controller's poses (its new
    start + AK) within the clamp of the reference.  Fast path (23 deg/s at
    the restart): an arm at rest cannot take the path up again within its
    acceleration, so the compensator stops answering (nothing beyond the
    bounds is ever commanded) and says why."""
    robot = load_robot()
    model, payload, _, ref_fn = h.write_inputs(str(tmp_path), robot, duration_s=0.1)
    q0 = np.degrees(ref_fn(0.0))
    path, ref = _moving_reference(str(tmp_path), q0, amplitude_deg)
    sensor = h.FakeSensor(h.hold_wrench(robot, ref_fn(0.0)))
    port = h.free_udp_port()
    proc = h.start_compensate(model, payload, sensor, port, reference=path,
                              extra=["--controller-protocol", "rsi"])
    krc = ScriptedKrc(port, q0)
    poses = []
    try:
        for i in range(350):
            if i == 200:
                krc.restart(ipoc0=70_000_000)  # a new RSI_MOVECORR: the arm stands 3.5 (10) deg from its start
            got = krc.cycle()
            poses.append(got)
            if got is None:
                break
    finally:
        rc, err = h.finish(proc)
        sensor.close()
        krc.sock.close()
    answered = [p for p in poses if p is not None]
    assert len(answered) > 200 and abs(answered[200][0] - q0[0]) > 3.0, "the restart comes 3 deg from the start"
    clamp = clamp_deg(robot, 0.5)
    step = np.asarray(robot.speed_limit_deg_per_s) * T
    for i, p in enumerate(answered):
        r = ref(i * T)  # the reference advances one period per message, the restart's too
        motion = np.abs(ref((i + 1) * T) - ref((i - 1) * T))
        off = np.abs(np.asarray(p) - r)
        assert np.all(off <= clamp + motion + 1e-5), (i, (off - clamp).max(), err[-2000:])
        if i:
            d = np.abs(np.asarray(p) - np.asarray(answered[i - 1]))
            assert np.all(d <= step + 1e-6), (i, d.max(), err[-2000:])
    assert "RSI: a new session" in err, err[-2000:]
    if amplitude_deg < 20.0:
        assert len(answered) == len(poses) == 350, f"the compensator stopped answering at message {len(answered)}:\n{err}"
        after = err[err.index("RSI: a new session"):]
        assert "compensating again" in after, err[-2000:]  # ramped to zero, then up again from zero
    else:
        assert len(answered) < 210 and "acceleration supervision allows" in err, err[-2000:]


def test_simulated_krc_restarting_mid_path(tmp_path):
    """The project's simulated KRC (lockstep, its motion supervision on)
    restarts RSI half-way through a moving path: it never refuses a target,
    and the path runs to its end from the restart's new start.  (Before, the
    simulated restart was silent on the controller's clock only: compensate
    took it for a time stamp that jumped and refused to answer, the cell
    stopped after its 60 s answer timeout, and the test passed on the
    targets before the restart.)"""
    from robstiff_drake.cell.sim_cell import Faults

    robot = load_robot()
    model, payload, _, ref_fn = h.write_inputs(str(tmp_path), robot, duration_s=0.1)
    q0 = np.degrees(ref_fn(0.0))
    # (10 deg in 2 s: at most 7.9 deg/s, from which a restarted arm at rest may take up the path again within
    # the controller's acceleration supervision)
    path, ref = _moving_reference(str(tmp_path), q0, amplitude_deg=10.0)
    port, netft = h.free_udp_port(), h.free_udp_port()
    link = rsi.RsiControllerLink("127.0.0.1", port, T)
    # the path (2 s), the restart at 1 s and its pause: 3 s of the controller's clock (cut_s), whatever this
    # machine's pace; the compensator ended by the test once the cell is done (before: the cell ran 40 s of wall
    # clock and compensate ended on a 1 s silence, which a controller stalled that long met mid-path too)
    th, net = h.start_cell(robot, lambda t: np.radians(ref(t)), egm_port=port, netft_port=netft, duration_s=600.0,
                           link=link, lockstep=True, faults=Faults(restart_at=1.0, restart_pause_s=0.1), cut_s=3.0,
                           answer_timeout_s=60.0)
    cmd = h.compensate_cmd(model, payload, path, egm_port=port, netft_port=netft, idle_exit_s=h.HANG_GUARD_S,
                           extra=["--controller-protocol", "rsi"])
    cp = h.run_compensate_against_thread_cell(cmd, th, net)
    assert net.stats.refused == 0, (net.stats.stop_reason, cp.stderr[-2000:])
    assert not net.stats.stop_reason, (net.stats.stop_reason, cp.stderr[-2000:])  # (the cut's 3 s ran out)
    assert "RSI: a new session" in cp.stderr, cp.stderr[-2000:]
    assert "target refused" not in cp.stderr, cp.stderr[-2000:]  # (the new session answered from its start)
    q = np.degrees(np.array(net.stats.q_cmd))
    # the cut's 3 s of the controller's clock less the restart's pause, each period commanded
    assert len(q) >= (3.0 - 0.1) / T - 5 and math.isfinite(q.max()), len(q)
    steps = np.abs(np.diff(q, axis=0)).max(axis=0)
    assert np.all(steps <= np.asarray(robot.speed_limit_deg_per_s) * T + 1e-6), steps


def _link(protocol, port):
    from robstiff_drake.cell.egm import EgmLink
    from robstiff_drake.cell.stream_motion import StreamMotionLink

    ctrl = ("127.0.0.1", None)
    return {"egm": lambda: EgmLink(0, ctrl), "rsi": lambda: rsi.RsiLink(0, ctrl, T),
            "stream-motion": lambda: StreamMotionLink(0, ("127.0.0.1", port))}[protocol]()


@pytest.mark.parametrize("protocol", ["egm", "rsi", "stream-motion"])
def test_every_protocol_checks_the_step_of_the_pose_it_will_command(protocol):
    """Each protocol's one send path refuses a pose further from the last
    one the controller was told than its axis speed allows in a period, or
    one that changes the step beyond its acceleration supervision."""
    from robstiff_drake.cell.link import Message
    from robstiff_drake.cell.safety import Envelope, UnsafeTarget, supervision_tolerances

    robot = load_robot()
    sink = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sink.bind(("127.0.0.1", 0))
    link = _link(protocol, sink.getsockname()[1])
    link.reply_to = sink.getsockname()
    q0 = [0.0, 7.008, 29.517, 0.0, 53.476, 0.0]
    if protocol == "rsi":
        link.decode(rsi.encode_rob(1_000_000, q0, q0))  # the session's start: its setpoint
    lo, hi = tuple(np.degrees(robot.q_lower_rad)), tuple(np.degrees(robot.q_upper_rad))

    def env(ref):
        return Envelope(lo, hi, tuple(ref), (2.0,) * 6, tuple(ref), (2.0,) * 6,
                        *supervision_tolerances(robot, T))

    def msg(i, pose):
        if protocol == "rsi":
            return link.decode(rsi.encode_rob(1_000_000 + 4 * i, pose, pose))
        return Message(i, 4 * i, list(pose), echo=i)

    q = list(q0)
    assert link.send_targets(msg(1, q), q, env(q))
    q1 = [q[0] + 0.03] + q[1:]  # 7.5 deg/s: within 100 deg/s, and from rest within 10 x 400 deg/s^2
    assert link.send_targets(msg(2, q), q1, env(q1))
    far = [q1[0] + 1.0] + q1[1:]  # 1 deg in 4 ms: 250 deg/s
    with pytest.raises(UnsafeTarget, match="axis speed"):
        link.send_targets(msg(3, q1), far, env(far))
    jerk = [q1[0] - 0.1] + q1[1:]  # from +0.03 to -0.1 deg per period
    with pytest.raises(UnsafeTarget, match="acceleration"):
        link.send_targets(msg(3, q1), jerk, env(jerk))
    assert link.sent == 2
    link.close()
    sink.close()


@pytest.mark.parametrize("ipoc", ["9" * 309, "-5", "\u0661\u0662\u0663", "+5", " ", "1e3", "1" * 20])
def test_a_malformed_ipoc_is_a_malformed_message(ipoc):
    """An IPOC that is no time stamp (309 digits: OverflowError before; a
    sign; Arabic-Indic digits that int() takes) is a MessageError: the link
    drops the datagram and counts it, the loop goes on."""
    from robstiff_drake.cell.link import MessageError

    data = rsi.encode_rob(5, [0.0] * 6, [0.0] * 6).replace(b"<IPOC>5</IPOC>", f"<IPOC>{ipoc}</IPOC>".encode())
    with pytest.raises(MessageError, match="IPOC"):
        rsi.decode_rob(data)
    link = rsi.RsiLink(0, ("127.0.0.1", None), T)
    try:
        link.sock.sendto(data, ("127.0.0.1", link.port))
        link.sock.sendto(rsi.encode_rob(1000, [0.0] * 6, [0.0] * 6), ("127.0.0.1", link.port))
        got = link.receive(5.0)
        assert link.malformed == 1 and [m.tm_ms for m, _ in got] == [1000]
    finally:
        link.close()
