"""`--controller HOST` without a port (EGM's controller sends from a port of
its own): the port of the first message decoded is the controller's, and
another port on that address is a stranger while the controller speaks
(before: every port on the address was heard, and the answer went to the
newest sender).  A new port is taken up only after the controller fell
silent for ``port_switch_silence_s`` (a new EGM session).  Logic only: the
silence is set far above any scheduling delay where the test needs it
not to pass, and the test sleeps well beyond it where it must."""

import time

import pytest

pytest.importorskip("abb_robot_client", reason="the EGM link needs abb-robot-client (pip install '.[test]')")

from robstiff_drake.cell.egm import ControllerLink, EgmLink  # noqa: E402

Q0 = [0.0, 7.008, 29.517, 0.0, 53.476, 0.0]
FAR = [30.0, 17.0, 39.5, 45.0, 73.5, 90.0]


def _all(link, n, timeout_s=10.0):
    """The first ``n`` messages the link hears (or what came within ``timeout_s``)."""
    got, t_end = [], time.monotonic() + timeout_s
    while len(got) < n and time.monotonic() < t_end:
        got += link.receive(0.5)
    return got


@pytest.fixture()
def link():
    lk = EgmLink(0, ("127.0.0.1", None))
    yield lk
    lk.close()


def test_another_port_on_the_controllers_address_is_a_stranger_while_it_speaks(link):
    link.port_switch_silence_s = 60.0  # (no scheduling delay reaches it)
    ctrl, other = ControllerLink("127.0.0.1", link.port), ControllerLink("127.0.0.1", link.port)
    try:
        ctrl.send(ctrl.robot_message(Q0, Q0, tm_ms=4))
        first = _all(link, 1)
        for k in range(2, 12):
            other.send(other.robot_message(FAR, FAR, tm_ms=4 * k))
            ctrl.send(ctrl.robot_message(Q0, Q0, tm_ms=4 * k))
        rest = _all(link, 10)
        time.sleep(0.2)
        rest += link.receive(0.0)  # (anything still queued)
        ctrl_port = ctrl.sock.getsockname()[1]
    finally:
        ctrl.close()
        other.close()
    heard = [list(m.joints_deg) for m, _ in first + rest]
    assert len(heard) == 11
    assert all(h == pytest.approx(Q0) for h in heard)  # never the other port's pose
    assert link.strangers == 10
    assert link.reply_to == ("127.0.0.1", ctrl_port)  # the answer goes to the controller's port only
    assert link.port_switches == 0


def test_a_new_port_is_taken_up_after_the_controller_fell_silent(link):
    link.port_switch_silence_s = 0.05
    ctrl = ControllerLink("127.0.0.1", link.port)
    try:
        ctrl.send(ctrl.robot_message(Q0, Q0, tm_ms=4))
        assert len(_all(link, 1)) == 1
    finally:
        ctrl.close()
    time.sleep(0.5)  # (10x the silence: a stopped and restarted EGM session)
    again = ControllerLink("127.0.0.1", link.port)
    try:
        again.send(again.robot_message(FAR, FAR, tm_ms=4))
        got = _all(link, 1)
        port = again.sock.getsockname()[1]
    finally:
        again.close()
    assert [list(m.joints_deg) for m, _ in got] == [pytest.approx(FAR)]
    assert link.reply_to == ("127.0.0.1", port)
    assert link.port_switches == 1 and link.strangers == 0


def test_a_given_port_is_the_only_one_heard():
    lk = EgmLink(0, ("127.0.0.1", 1))  # (port 1: no controller sends from it)
    ctrl = ControllerLink("127.0.0.1", lk.port)
    try:
        ctrl.send(ctrl.robot_message(Q0, Q0, tm_ms=4))
        time.sleep(0.2)
        got = lk.receive(0.0)
    finally:
        ctrl.close()
        lk.close()
    assert got == [] and lk.strangers == 1


def test_garbled_datagrams_from_the_learnt_port_keep_it(link):
    """The learnt port speaking garbage is not silent: another port's valid
    message right after a garbled one stays a stranger's (before: only a
    decoded message kept the port, and a silence of decoded ones, 1.5 s
    here, handed it on)."""
    link.port_switch_silence_s = 0.5  # (far above the pause between the two sends below, whatever the load)
    ctrl, other = ControllerLink("127.0.0.1", link.port), ControllerLink("127.0.0.1", link.port)
    try:
        ctrl.send(ctrl.robot_message(Q0, Q0, tm_ms=4))
        assert len(_all(link, 1)) == 1
        time.sleep(1.5)  # (3x the silence, in decoded messages)
        ctrl.send(b"\x08\x01garbled")
        other.send(other.robot_message(FAR, FAR, tm_ms=8))
        time.sleep(0.2)
        got = link.receive(0.0)
        ctrl_port = ctrl.sock.getsockname()[1]
    finally:
        ctrl.close()
        other.close()
    assert got == []
    assert link.malformed == 1 and link.strangers == 1 and link.port_switches == 0
    assert link.reply_to == ("127.0.0.1", ctrl_port)


def test_the_old_sessions_messages_read_with_the_new_ports_are_not_returned(link):
    """One read holds the old port's last message and, after a silence
    beyond the threshold, a new port's first: only the new one is returned
    (an answer to the old one would go to the new port), the old counted as
    a stranger's (before: both returned, the answers going to the new port)."""
    link.port_switch_silence_s = 0.05
    ctrl, again = ControllerLink("127.0.0.1", link.port), ControllerLink("127.0.0.1", link.port)
    try:
        ctrl.send(ctrl.robot_message(Q0, Q0, tm_ms=4))
        assert len(_all(link, 1)) == 1
        ctrl.send(ctrl.robot_message(Q0, Q0, tm_ms=8))  # (not read before the new port's)
        time.sleep(0.3)
        again.send(again.robot_message(FAR, FAR, tm_ms=4))
        time.sleep(0.2)
        got = link.receive(0.0)
        port = again.sock.getsockname()[1]
    finally:
        ctrl.close()
        again.close()
    assert [list(m.joints_deg) for m, _ in got] == [pytest.approx(FAR)]
    assert link.reply_to == ("127.0.0.1", port)
    assert link.port_switches == 1 and link.strangers == 1
