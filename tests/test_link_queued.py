"""How long a controller's datagram waited at this PC before the loop read
it (cell/link.py's ``queued_s``, from the kernel's receive time stamp):
parsed from the ancillary data, counted into the response (the datagram's
arrival -> the answer: the computation plus that wait) and logged; and
the simulated controller's record of each cycle it had no answer for
(cell/sim_cell.py: the time the compensator had, the controller's own
lateness).  Logic only: no timing is asserted."""

import math
import socket
import sys
import time

import numpy as np
import pytest

import cell_helpers as h
from robstiff_drake.cell import link as link_module
from robstiff_drake.cell.compensate import CompensatorLoop, LoopSettings, Reference
from robstiff_drake.cell.egm import EgmLink
from robstiff_drake.cell.link import Message, queued_s, stamp_s
from robstiff_drake.cell.run_log import FILES, StreamLog
from robstiff_drake.cell.sim_cell import CellNetwork
from robstiff_drake.model.robot import load_robot

Q0 = [0.0, 7.008, 29.517, 0.0, 53.476, 0.0]


def test_the_kernels_stamp_is_read_from_the_ancillary_data():
    if link_module.SO_TIMESTAMPNS is None:
        pytest.skip("no SO_TIMESTAMPNS on this system")
    data = link_module._TIMESPEC.pack(1_700_000_000, 250_000_000)
    assert stamp_s([(socket.SOL_SOCKET, link_module.SO_TIMESTAMPNS, data)]) == 1_700_000_000.25
    assert stamp_s([]) is None
    assert stamp_s([(socket.SOL_SOCKET, link_module.SO_TIMESTAMPNS + 1, data)]) is None  # another kind
    assert stamp_s([(socket.SOL_SOCKET, link_module.SO_TIMESTAMPNS, data[:4])]) is None  # cut short


def test_the_wait_is_unknown_without_a_stamp_or_when_the_clock_stepped_back():
    assert queued_s(100.0, 100.003) == pytest.approx(0.003)
    assert math.isnan(queued_s(None, 100.0))
    assert math.isnan(queued_s(100.0, 99.0))  # (the wall clock stepped back between the two)
    assert math.isnan(queued_s(100.0, 100.0 + 7200.0))  # (or forward by hours)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="SO_TIMESTAMPNS is Linux's")
def test_a_datagram_over_loopback_carries_its_wait():
    sender = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sender.bind(("127.0.0.1", 0))
    link = EgmLink(0, ("127.0.0.1", None))
    try:
        from robstiff_drake.cell.egm import ControllerLink

        ctrl = ControllerLink("127.0.0.1", link.port)
        ctrl.send(ctrl.robot_message(Q0, Q0, tm_ms=4))
        got = link.receive(5.0)
        ctrl.close()
    finally:
        link.close()
        sender.close()
    assert len(got) == 1
    msg, _ = got[0]
    assert math.isfinite(msg.queued_s) and msg.queued_s >= 0.0


class _Link:
    name, option, port = "EGM", "--egm-port", 0
    strangers = malformed = 0

    def send_targets(self, msg, target, env):
        pass


class _Sensor:
    def drain(self):
        return []


def test_the_response_is_the_computation_plus_the_wait_and_is_logged(tmp_path):
    robot = load_robot()
    w = h.hold_wrench(robot, np.radians(Q0))(0.0).tolist()
    ref = Reference(period_s=0.004)
    ref.hold(Q0)
    log = StreamLog(tmp_path / "log", "compensator: {}\n", "test")
    loop = CompensatorLoop(h.hold_compensator(robot, w), _Link(), _Sensor(), ref, robot,
                           LoopSettings(max_jump_Nm=350.0), log=log, out=open("/dev/null", "w"))

    loop.run_start(Message(1, 0, Q0, echo=1), time.monotonic())  # (no stamp: not in the response)
    waits = {2: 0.5, 3: float("nan"), 4: 0.5, 5: 0.25}
    for k, q in waits.items():
        msg = Message(k, (k - 1) * 4, Q0, echo=k, queued_s=q)
        ok, dt = loop._session(msg)
        loop.cycle(msg, time.monotonic(), dt)
    n = loop.n
    assert n.response_ms.n == 3 and n.compute_ms.n == 5
    # each response is its computation plus its wait: the largest is at least the largest wait, and no more than
    # the largest computation plus it
    assert 500.0 <= n.response_ms.max <= n.compute_ms.max + 500.0 + 1e-9
    stats = loop.stats()
    assert stats["response_ms"]["stamped"] == 3 and stats["response_ms"]["over_period"] == 3  # (each waited over a period)
    rows = [r.rstrip("\n").split(",") for r in log.chunks["cycles.csv"]]
    col = FILES["cycles.csv"].index("queued_ms")
    assert [r[col] for r in rows] == ["", "500", "", "500", "250"]
    loop.finish_start()
    log.close({})


class _NoAnswerFor:
    """A controller link for CellNetwork whose compensator answers every
    message at once but ``skip``'s (never)."""

    def __init__(self, skip, q_deg):
        self.skip_k, self.q_deg, self.pending = skip, q_deg, []

    def send_state(self, k, joints, planned, tm_ms, bad_type=False):
        if k != self.skip_k:
            self.pending.append(k)

    def answers(self):
        out, self.pending = [(k, list(self.q_deg)) for k in self.pending], []
        return out

    def wait(self, timeout_s):
        pass

    def skip(self):
        pass

    def close(self):
        pass


class _Station:
    def __init__(self, q):
        self.q = np.asarray(q, dtype=float)

    def step(self, q_cmd):
        return self.q, np.zeros(6)


def test_the_simulated_controller_records_each_cycle_it_had_no_answer_for():
    q = np.radians(Q0)
    net = CellNetwork(_Station(q), egm_to=None, netft_port=0, link=_NoAnswerFor(10, Q0), transport_delay_cycles=1)
    try:
        st = net.run(0.2, q)  # (50 ticks of 4 ms)
    finally:
        net.close()
    assert st.unanswered == 1 and st.trailing_unanswered == 0
    assert len(st.unanswered_detail) == 1
    k, had_ms, late_ms = st.unanswered_detail[0]
    assert k == 12  # (message 10's answer was due at tick 10 + 1 + the transport delay of one cycle)
    assert math.isfinite(had_ms) and had_ms > 0.0 and math.isfinite(late_ms)
