"""cell/compensate's lateness on the same cycles as the controller's:
the messages a controller sent before this side's first answer reached
it (it holds its own pose meanwhile), waiting here in one batch, are the
start's backlog, not late answers; a batch after this side first caught
up is late.  Scripted batches, no timing: in lockstep on a loaded PC the
compensator counted such a backlog as 78 of 829 cycles late (DEGRADED)
while the simulated controller, counting from its first target, saw none
(GOOD)."""

import time

import numpy as np

import cell_helpers as h
from robstiff_drake.cell.compensate import CompensatorLoop, LoopSettings, Reference
from robstiff_drake.cell.link import Message
from robstiff_drake.model.robot import load_robot

Q0 = [0.0, 7.008, 29.517, 0.0, 53.476, 0.0]


def _msg(k):
    return Message(k, (k - 1) * 4, Q0, echo=k)


def test_the_start_backlog_is_not_late_and_a_later_batch_is():
    robot = load_robot()
    w = h.hold_wrench(robot, np.radians(Q0))(0.0).tolist()
    ref = Reference(period_s=0.004)
    ref.hold(Q0)
    # the first message alone (answered), then the five the controller sent before that answer reached it,
    # then one at a time (caught up), then a batch of three: this side fell behind, all three answered late
    batches = [[_msg(k) for k in range(2, 7)]] + [[_msg(k)] for k in range(7, 12)] + [[_msg(12), _msg(13),
                                                                                        _msg(14)]]
    loop = CompensatorLoop(h.hold_compensator(robot, w), h.ScriptedLink(batches), h.HeldSensor(w), ref, robot,
                           LoopSettings(max_jump_Nm=350.0), log=None, out=open("/dev/null", "w"))
    loop.run((_msg(1), time.monotonic()))
    s = loop.stats()
    assert s["answered"] == 14, s
    # (before: the backlog counted late too, 8)
    assert s["start_backlog"] == 4 and s["late"] == 3, (s["start_backlog"], s["late"])
