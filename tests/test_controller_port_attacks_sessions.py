"""The learnt controller port's hostile test, its sessions' part (the
attacks on one session: tests/test_controller_port_attacks.py, whose
docstring says what every run asserts): a controller restarting from a NEW
port after a silence of 0.6 s (EGM and RSI), garbled datagrams from the
learnt port while another port sends valid ones, and a stalled compensator
(SIGSTOP) that reads the controller's last message and a new port's first
in one batch.  Through the real `compensate` process, lockstep; every wait
bounded by the hang guard."""

import os
import select
import signal
import socket
import sys
import time

import numpy as np
import pytest

pytest.importorskip("pynetft", reason="the cell tests need pynetft (pip install '.[test]')")
pytest.importorskip("abb_robot_client", reason="the cell tests need abb-robot-client (pip install '.[test]')")

sys.path.insert(0, os.path.dirname(__file__))
import cell_helpers as h  # noqa: E402
from port_attacks import CTRL, FAR_DEG, T, T_MS, TAKE_UP_SILENCE_S, Checker, _report, _summary  # noqa: E402
from port_attacks import exchange_while_answered, finish_with_stranger  # noqa: E402
from port_attacks import cell, robot  # noqa: E402,F401 (the fixtures)

from robstiff_drake.cell import rsi  # noqa: E402
from robstiff_drake.cell.safety import clamp_deg  # noqa: E402


def test_egm_controller_restarting_from_a_new_port_is_taken_up_safely(robot, cell):
    """Attack 4 (EGM): the controller streams 100 cycles, stops, and after
    0.6 s a new session starts from a NEW port, its numbering and clock
    from 1 and 0 again: taken up (one port switch), answered within the
    clamp of the reference (the reference's time goes on by one period at
    the restart's fault); the old port is sent nothing after the switch."""
    model, payload, ref, ref_deg, sensor, log = cell
    chk = Checker(robot, ref_deg)
    port = h.free_udp_port()
    proc = h.start_compensate(model, payload, sensor, port, reference=ref, log=log, extra=CTRL)
    ctrl = h.ScriptedController(port)
    again = None
    answered_new = 0
    try:
        for k in range(100):
            got = ctrl.exchange(k + 1, k * T_MS, ref_deg(k * T))
            assert got is not None
            chk.check(got, k, "controller")
        time.sleep(TAKE_UP_SILENCE_S)
        again = h.ScriptedController(port)
        assert again.port != ctrl.port
        for i in range(150):  # (its session time: the reference's at 100 + i periods at most, one step per message)
            k = 100 + i
            again.send(i + 1, i * T_MS, ref_deg(k * T))
            for got in again.answers(timeout_s=10.0):
                answered_new += 1
                chk.check(got, k, "new session")
    finally:
        code, err = h.finish(proc)
        late_new = again.answers() if again is not None else []
        old = ctrl.answers()
        ctrl.close()
        if again is not None:
            again.close()
    assert code == 0, err[-2000:]
    for got in late_new:
        chk.check(got, 249, "new session")
    assert old == []
    s = _summary(log)
    assert s["controller_port_switches"] == 1 and s["strangers_dropped"] == 0
    assert answered_new + len(late_new) >= 150 - 3  # (the restart's first messages may be dropped as "old")
    assert s["answered"] == 100 + answered_new + len(late_new)
    _report("egm restart from a new port", switches=s["controller_port_switches"],
            answers_to_new_port=answered_new + len(late_new), answers_to_old_port=len(old),
            worst_deg=round(chk.worst_deg, 4))


def test_egm_malformed_from_the_learnt_port_does_not_hand_it_to_another(robot, cell):
    """Attack 5 (EGM): the learnt port sends only malformed datagrams for
    about a second (the controller speaks, garbled) while another port sends
    valid messages with the arm's true pose, each right after a garbled one:
    the other port is never taken up, never answered; the garbled ones are
    counted as malformed, the other's as strangers; then the controller's
    valid messages are answered again.  Before: only a DECODED message kept
    the port, so 0.1 s of garbage handed it to the other sender (answered,
    the controller's own messages dropped as a stranger's)."""
    model, payload, ref, ref_deg, sensor, log = cell
    chk = Checker(robot, ref_deg)
    port = h.free_udp_port()
    proc = h.start_compensate(model, payload, sensor, port, reference=ref, log=log, extra=CTRL)
    ctrl, stranger = h.ScriptedController(port), h.ScriptedController(port)
    n_bad = 100
    try:
        for k in range(50):
            got = ctrl.exchange(k + 1, k * T_MS, ref_deg(k * T))
            assert got is not None
            chk.check(got, k, "controller")
        for i in range(n_bad):  # ~1 s: each of the other port's valid messages right after a garbled one
            k = 50 + i
            ctrl.sock.sendto(b"\x08\x01garbled" + bytes([i % 256]), ctrl.addr)
            stranger.send(k + 1, k * T_MS, ref_deg(k * T))
            time.sleep(0.01)
        k0 = 50 + n_bad
        back = exchange_while_answered(ctrl, range(k0, k0 + 50), ref_deg)
    finally:
        code, err, heard, extra = finish_with_stranger(proc, ctrl, stranger)
    assert code == 0, err[-2000:]
    s = _summary(log)
    for k, got in back:  # (its sequence jumped by n_bad: a fault, the reference's time one period on)
        chk.check(got, k - n_bad, "controller")
    assert heard == [], f"the other port was answered {len(heard)} times; summary {s['controller_port_switches']} " \
                        f"switches, {s['strangers_dropped']} strangers"
    assert len(back) == 50 and extra == []
    assert s["controller_port_switches"] == 0
    assert s["strangers_dropped"] == n_bad and s["malformed"] == n_bad
    _report("egm malformed + valid other port", strangers=s["strangers_dropped"], malformed=s["malformed"],
            answers_to_stranger=len(heard), worst_deg=round(chk.worst_deg, 4))


def test_egm_a_stalled_loop_never_answers_the_old_sessions_message_to_the_new_port(robot, cell):
    """Attack 3's race (EGM): the compensator is stalled (SIGSTOP: a loaded
    PC) while the controller's last message arrives and, 0.6 s later, a new
    port's first (its arm 1 deg from the reference): one read holds both,
    and the new port is taken up.  The old session's message must not be
    answered: the answer would go to the new port, checked against the OLD
    arm's feedback (before: it went there, 1 deg from the new arm's
    feedback, beyond the clamp the check allows).  The new port's own
    message is refused (1 deg from the reference)."""
    model, payload, ref, ref_deg, sensor, log = cell
    port = h.free_udp_port()
    proc = h.start_compensate(model, payload, sensor, port, reference=ref, log=log, extra=CTRL)
    ctrl, other = h.ScriptedController(port), h.ScriptedController(port)
    off = np.array([1.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    try:
        for k in range(50):
            assert ctrl.exchange(k + 1, k * T_MS, ref_deg(k * T)) is not None
        os.kill(proc.pid, signal.SIGSTOP)
        try:
            ctrl.send(51, 50 * T_MS, ref_deg(50 * T))
            time.sleep(TAKE_UP_SILENCE_S)
            other.send(52, 51 * T_MS, ref_deg(51 * T) + off)
        finally:
            os.kill(proc.pid, signal.SIGCONT)
        got_other = other.answers(timeout_s=2.0)  # (what it is sent, if anything: a bound, not a verdict)
    finally:
        code, err = h.finish(proc)
        got_other += other.answers()
        got_ctrl = ctrl.answers()
        ctrl.close()
        other.close()
    assert code == 0, err[-2000:]
    clamp = clamp_deg(robot, 0.5)
    for t in got_other:  # anything the new port was sent: within the clamp of ITS arm's feedback
        assert np.all(np.abs(np.asarray(t) - (ref_deg(51 * T) + off)) <= clamp + 1e-5), (t, err[-2000:])
    assert got_other == [] and got_ctrl == []
    s = _summary(log)
    assert s["controller_port_switches"] == 1
    assert s["strangers_dropped"] == 1  # the old session's message, read after the new port's was taken up
    _report("egm stalled loop, batch across a switch", answers_to_new_port=len(got_other),
            answers_to_old_port=len(got_ctrl), strangers=s["strangers_dropped"])


# ------------------------------------------------------------------------------------------------ RSI


def _krc_cycle(krc, stranger=None, far_deg=None):
    """One <Rob> of ``krc`` (test_rsi_restart.ScriptedKrc's cycle) and, right
    after it, the stranger's with the next IPOC and ``far_deg`` as its
    feedback and setpoint; the pose the KRC commands (deg), or None."""
    ipoc = krc.ipoc0 + int(round(krc.i * T * 1e3))
    krc.i += 1
    krc.sock.sendto(rsi.encode_rob(ipoc, krc.commanded, krc.commanded), krc.pc)
    if stranger is not None:
        stranger.sendto(rsi.encode_rob(ipoc + int(T_MS), list(far_deg), list(far_deg)), krc.pc)
    if not select.select([krc.sock], [], [], h.HANG_GUARD_S)[0]:
        return None
    got_ipoc, ak = rsi.decode_sen(krc.sock.recvfrom(65536)[0])
    if got_ipoc != ipoc:
        return None
    krc.commanded = [s + a for s, a in zip(krc.start, ak)]
    return list(krc.commanded)


def _queued(sock):
    out = []
    while select.select([sock], [], [], 0.0)[0]:
        out.append(sock.recvfrom(65536)[0])
    return out


def test_rsi_stranger_port_interleaved_then_a_restart_from_a_new_port(robot, cell):
    """Attacks 1 and 4 (RSI): right after each of the KRC's 200 <Rob> another
    port on 127.0.0.1 sends the next IPOC with a pose 30 deg away: dropped,
    counted, never answered; every pose the KRC commands (its start + AK)
    is within the clamp of the reference.  Then the KRC falls silent 0.6 s
    and starts RSI again from a NEW port (a new IPOC epoch, its start the
    pose it stands at): taken up (one port switch, "RSI: a new session"),
    its poses within the clamp of the reference; the old port is sent
    nothing after the switch."""
    from test_rsi_restart import ScriptedKrc

    model, payload, ref, ref_deg, sensor, log = cell
    chk = Checker(robot, ref_deg)
    port = h.free_udp_port()
    proc = h.start_compensate(model, payload, sensor, port, reference=ref, log=log,
                              extra=CTRL + ["--controller-protocol", "rsi"])
    krc = ScriptedKrc(port, ref_deg(0.0))
    stranger = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    stranger.bind(("127.0.0.1", 0))
    again = None
    poses = []
    try:
        for i in range(200):
            got = _krc_cycle(krc, stranger if i else None, ref_deg((i + 1) * T) + FAR_DEG)
            assert got is not None, f"the KRC got no answer at {i}"
            poses.append(got)
        time.sleep(TAKE_UP_SILENCE_S)
        again = ScriptedKrc(port, krc.commanded, ipoc0=70_000_000)  # RSI_ON again, from a new port
        assert again.sock.getsockname()[1] != krc.sock.getsockname()[1]
        for i in range(200, 350):
            got = _krc_cycle(again)
            assert got is not None, f"the restarted KRC got no answer at {i}"
            poses.append(got)
    finally:
        code, err = h.finish(proc)
        heard = _queued(stranger)
        old = _queued(krc.sock)
        stranger.close()
        krc.sock.close()
        if again is not None:
            again.sock.close()
    assert code == 0, err[-2000:]
    for i, p in enumerate(poses):  # (the reference advances one period per message, the restart's too)
        chk.check(p, i, "KRC")
    assert heard == [] and old == []
    assert "RSI: a new session" in err, err[-2000:]
    s = _summary(log)
    assert s["strangers_dropped"] == 199 and s["controller_port_switches"] == 1
    assert s["answered"] == 350
    _report("rsi interleaved + restart from a new port", strangers=s["strangers_dropped"],
            switches=s["controller_port_switches"], answers_to_stranger=len(heard), answers_to_old_port=len(old),
            worst_deg=round(chk.worst_deg, 4))
