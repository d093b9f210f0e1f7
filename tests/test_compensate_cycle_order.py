"""cell/compensate's cycle keeps the log's work after the answer: the
sensor records' rows are formatted once the target has been sent, with
the same times and values as the records the chain took (in order)."""

import numpy as np

import cell_helpers as h
from robstiff_drake.cell.compensate import CompensatorLoop, LoopSettings, Reference
from robstiff_drake.cell.link import Message
from robstiff_drake.model.robot import load_robot

Q0 = [0.0, 7.008, 29.517, 0.0, 53.476, 0.0]


class Link:
    name, option, port = "EGM", "--egm-port", 0

    def __init__(self, calls):
        self.calls = calls

    def send_targets(self, msg, target, env):
        self.calls.append(("send", msg.seq))


class Log:
    def __init__(self, calls):
        self.calls = calls

    def bind(self, loop):
        pass

    def open(self):  # (the log folder's start: off the loop's thread, cell/start_gate.py)
        pass

    def wrench(self, t, w):
        self.calls.append(("wrench", t, tuple(w)))

    def cycle(self, loop, msg, *a):
        self.calls.append(("cycle", msg.seq))

    def event(self, *a):
        pass


class Sensor:
    def __init__(self, records):
        self.records = records

    def drain(self):
        out, self.records[:] = list(self.records), []
        return out


def test_the_records_rows_are_written_after_the_answer_in_order():
    robot = load_robot()
    w = h.hold_wrench(robot, np.radians(Q0))(0.0).tolist()
    comp = h.hold_compensator(robot, w)
    ref = Reference(period_s=0.004)
    ref.hold(Q0)
    calls, records = [], []
    loop = CompensatorLoop(comp, Link(calls), Sensor(records), ref, robot, LoopSettings(max_jump_Nm=350.0),
                           log=Log(calls), out=open("/dev/null", "w"))
    loop.run_start(Message(1, 0, Q0, echo=1), 0.0)
    expected = []
    for k in range(2, 6):
        batch = [([v + 0.1 * i + k for v in w], 0.004 * k, 0, False) for i in range(4)]
        if k == 4:
            batch[1] = (batch[1][0], batch[1][1], 0, True)  # a clipped record: logged as NaN
        records.extend(batch)
        expected.append([tuple(r[0]) if not r[3] else (float("nan"),) * 6 for r in batch])
        del calls[:]
        msg = Message(k, (k - 1) * 4, Q0, echo=k)
        ok, dt = loop._session(msg)
        loop.cycle(msg, 0.004 * k, dt)
        kinds = [c[0] for c in calls]
        assert kinds == ["send", "wrench", "wrench", "wrench", "wrench", "cycle"], kinds
        rows = [c[2] for c in calls if c[0] == "wrench"]
        np.testing.assert_array_equal(np.array(rows), np.array(expected[-1]))
        times = [c[1] for c in calls if c[0] == "wrench"]
        assert all(b > a for a, b in zip(times, times[1:]))
    assert loop._wrench_rows == []
