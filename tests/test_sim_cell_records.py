"""The simulated cell's sensor records in time (cell/sim_cell.CellNetwork's
``spread_records``): a Net F/T streams each record as it samples it (every
1 ms at 1 kHz, in no phase with the controller), so that the compensator's
reader thread does not wake with its loop at every message, as it does when
a cycle's records come together just before the message (the default, which
lockstep needs).  Ordering only, no deadline: a late machine sends late, never
early nor out of order."""

import os
import sys
import threading

import numpy as np
import pytest

sys.path.insert(0, os.path.dirname(__file__))
import cell_helpers as h  # noqa: E402

from robstiff_drake.cell.sim_cell import CellNetwork  # noqa: E402
from robstiff_drake.cell.stand_in_arm import ServoArmStandIn  # noqa: E402

PERIOD_S = 0.004
SAMPLES = 4  # the stand-in's records a cycle (1 kHz at 4 ms)


def _cell(robot, spread):
    """(the stand-in arm at rest, its network: no compensator)."""
    station = ServoArmStandIn(robot=robot, joint_stiffness_Nm_per_rad=robot.joint_stiffness_Nm_per_rad,
                              calibration=h.calibration(robot), process_wrench=h.cutting_wrench(),
                              reference=lambda t: np.zeros(6), q_start_rad=np.zeros(6), seed=3,
                              sensor_samples=SAMPLES)
    return station, CellNetwork(station, egm_to=("127.0.0.1", h.free_udp_port()), netft_port=h.free_udp_port(),
                                period_s=PERIOD_S, spread_records=spread)


def _run(robot, spread, duration_s=0.2):
    """A cell (no compensator: the stand-in at rest) for ``duration_s``; its events in order: 'step' (the
    station stepped at a tick), 'row' (a record sent), 'msg' (the controller's message sent)."""
    station, net = _cell(robot, spread)
    events = []
    send_row, send_state, hold = net._send_row, net.egm.send_state, station.hold

    def row(r, t):
        events.append("row")
        send_row(r, t)

    def state(*a, **kw):
        events.append("msg")
        return send_state(*a, **kw)

    def held():
        events.append("step")
        return hold()

    net._send_row, net.egm.send_state, station.hold = row, state, held
    th = threading.Thread(target=net.run, args=(duration_s, np.zeros(6)), daemon=True)
    try:
        th.start()
        th.join(30.0)
    finally:
        net.stop = True
        net.close()
    return events


@pytest.fixture(scope="module")
def robot():
    return h.load_robot()


def _between_messages(events):
    """For each pair of messages: (records sent before the tick's step, records sent after it)."""
    out, before, after, stepped = [], 0, 0, False
    for e in events:
        if e == "msg":
            out.append((before, after))
            before, after, stepped = 0, 0, False
        elif e == "step":
            stepped = True
        elif stepped:
            after += 1
        else:
            before += 1
    return out[1:]  # (the first message's: the run's start)


def test_burst_sends_a_cycles_records_together_before_its_message(robot):
    pairs = _between_messages(_run(robot, spread=False))
    assert len(pairs) >= 10
    assert set(pairs) == {(0, SAMPLES)}  # all four after the tick's step, just before its message


def test_spread_sends_one_record_with_the_message_and_the_others_while_waiting(robot):
    pairs = _between_messages(_run(robot, spread=True))
    assert len(pairs) >= 10
    # the three later records of the cycle before, sent while waiting for this tick; this cycle's first with
    # its message
    assert set(pairs) == {(SAMPLES - 1, 1)}


def test_spread_records_are_never_sent_before_their_instant(robot, monkeypatch):
    """_wait_sending's rule on the clock it reads: a record queued for t is sent at t or later."""
    import time

    _, net = _cell(robot, spread=True)
    sent = []
    try:
        monkeypatch.setattr(net, "_send_row", lambda row, t: sent.append((time.monotonic(), row[0])))
        t0 = time.monotonic()
        net._send_wrench(np.arange(24.0).reshape(4, 6), 0.0, t0)
        assert [r for _, r in sent] == [0.0]  # the first at once
        net._wait_sending(t0 + PERIOD_S)
        assert [r for _, r in sent] == [0.0, 6.0, 12.0, 18.0]
        for i, (t, _) in enumerate(sent[1:], start=1):
            assert t >= t0 + i * PERIOD_S / 4
        assert not net._pending
    finally:
        net.close()
