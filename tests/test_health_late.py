"""cell/compensate's late answers as the controller counts them: an
answer that left more than the controller's cycle after its message
arrived at this PC (the kernel's receive stamp) missed the controller's
next cycle even when the next message had not been read yet (it came
late to this PC; the controller's cycle runs on its own clock: EGM holds
the last target, RSI counts a late packet).  Before, only an answer sent
after the next message had arrived counted late, so a run whose answers
all left 12 ms after their 4 ms messages was "good".  Scripted batches,
the stamps fed as data (``Message.queued_s``): no timing."""

import time

import numpy as np

import cell_helpers as h
from robstiff_drake.cell.compensate import CompensatorLoop, LoopSettings, Reference
from robstiff_drake.cell.health import verdict
from robstiff_drake.cell.link import Message
from robstiff_drake.cell.run_log import FILES, StreamLog
from robstiff_drake.model.robot import load_robot

Q0 = [0.0, 7.008, 29.517, 0.0, 53.476, 0.0]
NAN = float("nan")


def _run(waits, log=None):
    """The loop over messages 2.. read one at a time, message k having
    waited ``waits[k - 2]`` s at this PC before its read (NaN: no stamp)."""
    robot = load_robot()
    w = h.hold_wrench(robot, np.radians(Q0))(0.0).tolist()
    ref = Reference(period_s=0.004)
    ref.hold(Q0)
    batches = [[Message(k, (k - 1) * 4, Q0, echo=k, queued_s=q)] for k, q in enumerate(waits, start=2)]
    loop = CompensatorLoop(h.hold_compensator(robot, w), h.ScriptedLink(batches), h.HeldSensor(w), ref, robot,
                           LoopSettings(max_jump_Nm=350.0), log=log, out=open("/dev/null", "w"))
    loop.run((Message(1, 0, Q0, echo=1), time.monotonic()))
    return loop


def test_an_answer_over_the_cycle_is_late_though_the_next_message_had_not_come(tmp_path):
    # 40 messages read one at a time; three of them had waited 12 ms (three 4 ms cycles) at this PC before
    # their read, the rest carry no stamp (their response unknown: never counted)
    waits = [NAN] * 40
    for i in (5, 17, 30):
        waits[i] = 0.012
    log = StreamLog(tmp_path / "log", "compensator: {}\n", "test")
    loop = _run(waits, log)
    s = loop.stats()
    hv = s["health"]
    # (before: late 0 and the verdict GOOD)
    assert hv["verdict"] == "degraded", hv  # 3 of 41 cycles late: over GOOD_LATE's 5 %
    assert s["answered"] == 41 and s["late"] == 3 and s["missed_cycles"] == 3, s
    assert s["late_over_deadline"] == 3 and s["late_next_waiting"] == 0, s
    assert s["answer_deadline_ms"] == 4.0
    assert s["response_ms"]["over_period"] == 3
    assert "3 late; 3 of them more than 4 ms after their message arrived" in hv["line"], hv["line"]
    # the log's cycles.csv says which answers were late
    loop.finish_start()
    log.close(s)
    lines = [x for x in (tmp_path / "log" / "cycles.csv").read_text().splitlines() if not x.startswith("#")]
    assert lines[0].split(",") == FILES["cycles.csv"]
    col = FILES["cycles.csv"].index("late")
    rows = [x.split(",") for x in lines[1:]]
    assert len(rows) == 41 and [i for i, r in enumerate(rows) if r[col] == "1"] == [6, 18, 31], rows  # (row 0: the start)


def test_the_first_answer_is_not_judged():
    # the first message waited 50 ms (the loop's start): the controller holds its own pose until the first
    # target reaches it, and counts from there (as the start's backlog is not late)
    robot = load_robot()
    w = h.hold_wrench(robot, np.radians(Q0))(0.0).tolist()
    ref = Reference(period_s=0.004)
    ref.hold(Q0)
    loop = CompensatorLoop(h.hold_compensator(robot, w), h.ScriptedLink([]), h.HeldSensor(w), ref, robot,
                           LoopSettings(max_jump_Nm=350.0), log=None, out=open("/dev/null", "w"))
    loop.run((Message(1, 0, Q0, echo=1, queued_s=0.05), time.monotonic()))
    s = loop.stats()
    assert s["late"] == 0 and s["late_over_deadline"] == 0 and s["health"]["verdict"] == "good", s


def test_the_verdict_counts_answers_over_the_deadline_with_the_late():
    word, reasons, line = verdict(cycles=100, answered=100, late=8, unanswered=0, faults=0, lost_fraction=0.0,
                                  over_deadline=6, deadline_ms=4.0)
    assert word == "degraded"
    assert reasons == ["8 of 100 cycles without a fresh answer (8 late; 6 of them more than 4 ms after their "
                       "message arrived, 0 unanswered)"], reasons
    word, reasons, _ = verdict(cycles=100, answered=100, late=2, unanswered=0, faults=0, lost_fraction=0.0)
    assert word == "good" and reasons == ["2 of 100 cycles without a fresh answer (2 late, 0 unanswered)"]
