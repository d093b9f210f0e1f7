"""`--controller 127.0.0.1` without a port (EGM's and RSI's controllers
send from a port of their own; cell/link.py learns the first message's port)
attacked through the real `compensate` process by a second sender on the
controller's address from another port: interleaved every cycle with the
real controller (a pose 30 deg away, sequence numbers and clocks that look
like the continuation), sending first, taking over after a silence of the
controller far beyond ``port_switch_silence_s`` (0.1 s), the controller
restarting from a new port, malformed datagrams from the learnt port while
another port sends valid ones, and a stalled compensator that reads the
controller's last message and the new port's first in one batch (those
three in tests/test_controller_port_attacks_sessions.py).

Every target received by anyone is finite, inside the working ranges and
within the correction's clamp (+ the reference's motion over a period) of
the reference at its cycle; no answer reaches a port that is not the
controller's while the controller speaks; summary.json's counts are what
was sent.  Lockstep (one message, then its answer) and silences of 0.6 s
(6x the threshold) where a port must be taken up; where a silence must NOT
pass, the senders send without any pause (no timing assumption on a loaded
machine); every wait is bounded by the hang guard (HANG_GUARD_S)."""

import os
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

from robstiff_drake.cell.safety import clamp_deg  # noqa: E402


# ------------------------------------------------------------------------------------------------ EGM


def test_egm_stranger_port_interleaved_every_cycle_is_never_heard(robot, cell):
    """Attack 1 (EGM): right after each of the controller's 300 messages
    another port on 127.0.0.1 sends the next sequence number and clock (what
    would look like the continuation) with a pose 30 deg away: it is dropped and
    counted every time, never answered; the controller gets every answer,
    within the clamp of the reference."""
    model, payload, ref, ref_deg, sensor, log = cell
    chk = Checker(robot, ref_deg)
    port = h.free_udp_port()
    proc = h.start_compensate(model, payload, sensor, port, reference=ref, log=log, extra=CTRL)
    ctrl, stranger = h.ScriptedController(port), h.ScriptedController(port)
    n = 300
    try:
        assert ctrl.exchange(1, 0.0, ref_deg(0.0)) is not None  # the controller first: its port is learnt
        for k in range(1, n):
            # the stranger right after the controller's message (two sends back to back: the controller never
            # silent in between, whatever this machine's load), the next sequence number and clock
            ctrl.send(k + 1, k * T_MS, ref_deg(k * T))
            stranger.send(k + 2, (k + 1) * T_MS, ref_deg((k + 1) * T) + FAR_DEG)
            got = (ctrl.answers(h.HANG_GUARD_S) or [None])[-1]
            assert got is not None, f"the controller got no answer at {k}"
            chk.check(got, k, "controller")
    finally:
        code, err, heard, extra = finish_with_stranger(proc, ctrl, stranger)  # (after the run's end: all it was ever sent)
    assert code == 0, err[-2000:]
    assert heard == [] and extra == []
    s = _summary(log)
    assert s["strangers_dropped"] == n - 1 and s["controller_port_switches"] == 0
    assert s["answered"] == n and s["targets_refused"] == 0
    _report("egm interleaved", strangers=s["strangers_dropped"], answers_to_stranger=len(heard),
            answers_to_controller=s["answered"], worst_deg=round(chk.worst_deg, 4))


def test_egm_stranger_first_with_a_reference_the_start_is_refused(robot, cell):
    """Attack 2 (EGM, with --reference): the stranger port speaks first, 30
    deg from the reference's start, then the real controller too: the
    stranger's port is learnt (the link cannot tell it from the
    controller's), and the start tolerance refuses the run at its first
    message: one line, exit 2, nothing sent to anyone."""
    model, payload, ref, ref_deg, sensor, log = cell
    port = h.free_udp_port()
    proc = h.start_compensate(model, payload, sensor, port, reference=ref, log=log, extra=CTRL)
    ctrl, stranger = h.ScriptedController(port), h.ScriptedController(port)
    try:
        for k in range(50):
            stranger.send(k + 1, k * T_MS, ref_deg(k * T) + FAR_DEG)
            if k >= 10:
                ctrl.send(k + 1, k * T_MS, ref_deg(k * T))
    finally:
        code, err = h.finish(proc, end=False)
        heard, got = stranger.answers(), ctrl.answers()
        ctrl.close()
        stranger.close()
    assert code == 2, err[-2000:]
    assert "30.000 deg from the reference's start on joint 1" in err, err[-2000:]
    assert "Traceback" not in err
    assert heard == [] and got == []
    _report("egm stranger first, reference", exit=code, answers_to_stranger=len(heard), answers_to_controller=len(got))


def test_egm_stranger_first_without_a_reference_never_moves_the_real_one(robot, cell):
    """Attack 2 (EGM, no --reference: the hold pose is the first message's):
    the stranger port speaks first, 30 deg from the arm: its port and its
    pose are learnt (it is answered its own pose: as far as the link can
    tell, it is the controller); the real controller meanwhile is a
    stranger, never answered.  After the stranger fell silent (0.6 s) the
    real controller is taken up (a port switch), but the hold pose is 30 deg
    from its feedback: every target is refused, nothing is sent to it: the
    real arm is never moved."""
    model, payload, ref, ref_deg, sensor, log = cell
    q0 = ref_deg(0.0)
    far = q0 + FAR_DEG
    clamp = clamp_deg(robot, 0.5)
    port = h.free_udp_port()
    proc = h.start_compensate(model, payload, sensor, port, log=log, extra=CTRL)
    ctrl, stranger = h.ScriptedController(port), h.ScriptedController(port)
    try:
        to_stranger = []
        for k in range(50):  # the stranger first (answered: it holds the port), then the controller too (dropped)
            stranger.send(k + 1, k * T_MS, far)
            if k >= 10:  # (right after the stranger's: it never fell silent in between)
                ctrl.send(k + 1, k * T_MS, q0)
            got = stranger.answers(h.HANG_GUARD_S)
            assert got
            to_stranger += got
        time.sleep(TAKE_UP_SILENCE_S)
        for k in range(50, 150):
            ctrl.send(k + 1, k * T_MS, q0)
            time.sleep(0.002)
    finally:
        code, err = h.finish(proc)
        to_stranger += stranger.answers()
        to_ctrl = ctrl.answers()
        ctrl.close()
        stranger.close()
    assert code == 0, err[-2000:]
    lo, hi = np.degrees(robot.q_lower_rad), np.degrees(robot.q_upper_rad)
    for t in to_stranger:  # its own pose (zero correction: the start's gate), inside the working ranges
        assert np.all(np.isfinite(t)) and np.all(np.asarray(t) >= lo) and np.all(np.asarray(t) <= hi)
        assert np.abs(np.asarray(t) - far).max() <= clamp.max() + 1e-6
    assert to_ctrl == [], "the real controller was sent the stranger's pose"
    s = _summary(log)
    assert s["controller_port_switches"] == 1
    assert s["strangers_dropped"] == 40  # the real controller's messages while the stranger spoke
    assert s["answered"] == len(to_stranger) == 50
    assert s["targets_refused"] >= 100  # every one of the real controller's messages after the switch
    assert "from the arm's feedback" in err
    _report("egm stranger first, hold pose", strangers=s["strangers_dropped"], answers_to_stranger=len(to_stranger),
            answers_to_controller=len(to_ctrl), refused=s["targets_refused"])


@pytest.mark.parametrize("stranger_pose", ["far", "truthful"])
def test_egm_stranger_takes_over_after_the_controllers_silence(robot, cell, stranger_pose):
    """Attack 3 (EGM): 100 cycles of the controller with the stranger
    interleaved (dropped); then the controller falls silent while the
    stranger keeps sending with the continuation's sequence and clock.  A
    silence of no length (the stranger's datagrams between the controller's
    last and its own next, sent back to back) keeps the controller's port;
    one of 0.6 s gives the stranger the port (a new session): with a pose
    30 deg away every target is refused (nothing sent to it); with the
    arm's true pose it is answered, within the clamp of the reference.
    Then the real controller comes back on its old port: now the stranger,
    never answered while the new one speaks."""
    model, payload, ref, ref_deg, sensor, log = cell
    chk = Checker(robot, ref_deg)
    offset = FAR_DEG if stranger_pose == "far" else np.zeros(6)
    port = h.free_udp_port()
    proc = h.start_compensate(model, payload, sensor, port, reference=ref, log=log, extra=CTRL)
    ctrl, stranger = h.ScriptedController(port), h.ScriptedController(port)
    to_stranger = []
    try:
        for k in range(100):
            ctrl.send(k + 1, k * T_MS, ref_deg(k * T))
            if k:  # (right after the controller's: no silence in between, whatever this machine's load)
                stranger.send(k + 2, (k + 1) * T_MS, ref_deg((k + 1) * T) + offset)
            got = (ctrl.answers(h.HANG_GUARD_S) or [None])[-1]
            assert got is not None
            chk.check(got, k, "controller")
        assert stranger.answers() == []
        time.sleep(TAKE_UP_SILENCE_S)  # the controller silent; the stranger goes on where it left off
        for k in range(100, 200):
            stranger.send(k + 1, k * T_MS, ref_deg(k * T) + offset)
            got = stranger.answers(timeout_s=h.HANG_GUARD_S if stranger_pose == "truthful" else 0.05)
            to_stranger += [(k, g) for g in got]
        for k in range(200, 230):  # the real controller back on its old port, the new one still speaking
            stranger.send(k + 1, k * T_MS, ref_deg(k * T) + offset)
            ctrl.send(k + 1, k * T_MS, ref_deg(k * T))  # (right after the new one's: it never fell silent)
            got = stranger.answers(timeout_s=h.HANG_GUARD_S if stranger_pose == "truthful" else 0.05)
            to_stranger += [(k, g) for g in got]
    finally:
        code, err = h.finish(proc)
        to_stranger += [(None, g) for g in stranger.answers()]
        back = ctrl.answers()
        ctrl.close()
        stranger.close()
    assert code == 0, err[-2000:]
    for k, got in to_stranger:
        assert k is not None and k >= 100, "an answer reached the stranger while the controller spoke"
        chk.check(got, k, "stranger")
    assert back == [], "the old controller's port was answered after the new session took it"
    s = _summary(log)
    assert s["controller_port_switches"] == 1
    assert s["strangers_dropped"] == 99 + 30  # interleaved before the silence; the old port after it
    if stranger_pose == "far":
        assert to_stranger == [] and s["targets_refused"] >= 1
    else:
        assert len(to_stranger) == 130 and s["answered"] == 100 + 130
    _report(f"egm takeover ({stranger_pose})", strangers=s["strangers_dropped"],
            answers_to_stranger_after_silence=len(to_stranger), answers_to_old_port_after=len(back),
            refused=s["targets_refused"], worst_deg=round(chk.worst_deg, 4))


def test_egm_short_silence_then_the_stranger_leaves_and_the_controller_returns(robot, cell):
    """Attack 3's two silences (EGM).  0.05 s (below the 0.1 s) while the
    stranger sends from another port 30 deg away: on an idle machine the
    port stays the controller's; a loaded one may stretch it past 0.1 s,
    so only what holds either way is asserted: the stranger is sent
    nothing (its pose is refused), every target is within the checks.
    Then the controller is silent 0.6 s while the stranger streams (it
    takes the port: refused every time), the stranger stops, and after 0.6
    s more the controller comes back on its own port (its numbering where
    the stranger's left off): taken up again.  The stranger's 100 messages
    advanced the reference's time by 0.4 s (0.4 deg on q2 here) although
    none was answered, so the controller's new targets are a step beyond
    the axis speeds from the last one sent: refused; it is answered the
    last target sent before the silence (held) while that stays within the
    clamp of the reference, then nothing: the stranger cost the run its
    compensation (a denial of service), never a target beyond the checks."""
    held = []
    model, payload, ref, ref_deg, sensor, log = cell
    chk = Checker(robot, ref_deg)
    port = h.free_udp_port()
    proc = h.start_compensate(model, payload, sensor, port, reference=ref, log=log, extra=CTRL)
    ctrl, stranger = h.ScriptedController(port), h.ScriptedController(port)
    try:
        for k in range(100):
            got = ctrl.exchange(k + 1, k * T_MS, ref_deg(k * T))
            assert got is not None
            chk.check(got, k, "controller")
            held = got
        for i in range(3):  # 0.05 s: the stranger's three messages, the controller silent
            stranger.send(101 + i, (100 + i) * T_MS, ref_deg((100 + i) * T) + FAR_DEG)
            time.sleep(0.017)
        for k in range(100, 150):  # the controller again (answered unless a loaded machine made that 0.1 s)
            for got in ctrl.answers(0.0) + [ctrl.exchange(k + 1, k * T_MS, ref_deg(k * T), timeout_s=2.0)]:
                if got is not None:
                    chk.check(got, k, "controller")
                    held = got
        time.sleep(TAKE_UP_SILENCE_S)
        for k in range(150, 250):  # the stranger alone: it takes the port
            stranger.send(k + 1, k * T_MS, ref_deg(k * T) + FAR_DEG)
            time.sleep(0.002)
        time.sleep(TAKE_UP_SILENCE_S)
        back = exchange_while_answered(ctrl, range(250, 400), ref_deg)  # the controller back on its own port
    finally:
        code, err, heard, late = finish_with_stranger(proc, ctrl, stranger)
    assert code == 0, err[-2000:]
    assert heard == []
    s = _summary(log)
    for k, got in back:  # (the reference's time went on with the stranger's messages)
        chk.check(got, k, "controller")
        assert got == pytest.approx(held, abs=1e-9), "after its return the controller is held where it was"
    assert late == []
    assert len(back) < 150 and s["targets_refused"] >= 100 + len(back)
    assert s["controller_port_switches"] in (2, 4)  # (4: the 0.05 s stretched past 0.1 s by this machine's load)
    _report("egm 0.05 s silence, stranger's takeover, controller's return", strangers=s["strangers_dropped"],
            switches=s["controller_port_switches"], answers_to_stranger=len(heard), refused=s["targets_refused"],
            answers_to_controller_after_return=len(back), worst_deg=round(chk.worst_deg, 4))
