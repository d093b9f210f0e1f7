"""The compensator's loop keeps Python's garbage collector off the way to
its answers: with cell/realtime_thread.quiet_gc's token the automatic
collector is off and the loop collects at its safe points only, after an
answer has left (never between a message's arrival and its answer), and
the collections are counted; restore_gc gives the collector back.
cell/realtime_thread.pin_to_cpu keeps the loop's thread on one CPU, or
says why not and leaves the run going."""

import gc
import os
import subprocess
import sys

import numpy as np
import pytest

import cell_helpers as h
from robstiff_drake.cell.compensate import CompensatorLoop, LoopSettings, Reference
from robstiff_drake.cell.link import Message
from robstiff_drake.cell.realtime_thread import collect_if_due, pin_to_cpu, quiet_gc, restore_gc
from robstiff_drake.model.robot import load_robot

Q0 = [0.0, 7.008, 29.517, 0.0, 53.476, 0.0]


class Link:
    """A controller that sends N messages (garbage made on the way: the
    decoding's cycles) and then Ctrl-C; the calls recorded in order."""

    name, option, port, strangers, malformed = "EGM", "--egm-port", 0, 0, 0

    def __init__(self, calls, n):
        self.calls, self.k, self.n = calls, 1, n

    def receive(self, timeout_s):
        self.k += 1
        if self.k > self.n:
            raise KeyboardInterrupt
        for _ in range(40):  # (reference cycles: only a collection frees them)
            a = []
            a.append(a)
        self.calls.append("arrival")
        return [(Message(self.k, (self.k - 1) * 4, Q0, echo=self.k), 0.004 * self.k)]

    def send_targets(self, msg, target, env):
        self.calls.append("answer")


class Sensor:
    def drain(self):
        return []


def _loop(calls, n):
    robot = load_robot()
    w = h.hold_wrench(robot, np.radians(Q0))(0.0).tolist()
    ref = Reference(period_s=0.004)
    ref.hold(Q0)
    loop = CompensatorLoop(h.hold_compensator(robot, w), Link(calls, n), Sensor(), ref, robot,
                           LoopSettings(max_jump_Nm=350.0), out=open(os.devnull, "w"))
    return loop


def _collections_between(calls):
    """(collections between an arrival and its answer, collections elsewhere)."""
    inside = outside = 0
    waiting = False
    for c in calls:
        if c == "arrival":
            waiting = True
        elif c == "answer":
            waiting = False
        elif c == "gc":
            inside += waiting
            outside += not waiting
    return inside, outside


def _run(n, token_thresholds):
    calls = []
    loop = _loop(calls, n)

    def seen(phase, info):
        if phase == "start":
            calls.append("gc")

    token = quiet_gc()
    try:
        if token_thresholds is None:
            gc.set_threshold(50, 10, 10)
            gc.enable()  # (the automatic collector: what the loop ran with before)
        else:
            loop.gc_token = (token_thresholds, token[1])
        gc.callbacks.append(seen)
        first = loop.link.receive(0.1)[0]
        loop.run(first)
    finally:
        gc.callbacks.remove(seen)
        gc.set_threshold(*token[0])
        restore_gc(token)
    return calls, loop


def test_the_loop_collects_only_after_its_answers():
    calls, loop = _run(300, (50, 10, 10))
    inside, outside = _collections_between(calls)
    assert inside == 0, calls[:60]
    assert outside >= 10  # (it does collect: the reference cycles are freed)
    assert loop.n.gc_ms.n == outside
    assert loop.stats()["gc_ms"]["collections"] == outside
    assert gc.isenabled()  # (given back at the end)


def test_with_the_automatic_collector_collections_come_on_the_way_to_answers():
    """The measurement's own check: the same loop with the collector left on
    collects between arrivals and answers (what the safe point removes)."""
    calls, loop = _run(300, None)
    inside, _ = _collections_between(calls)
    assert inside > 0
    assert loop.n.gc_ms.n == 0


def test_collect_if_due_follows_the_thresholds_and_leaves_an_enabled_collector_alone():
    token = quiet_gc()
    try:
        t = ((100, 10, 10), token[1])
        gc.collect()
        assert collect_if_due(t) == -1  # (nothing new yet)
        junk = [[i] for i in range(500)]  # noqa: F841 (tracked objects: the count rises)
        assert collect_if_due(t) == 0
        assert gc.get_count()[0] < 100
        assert collect_if_due(None) == -1
    finally:
        restore_gc(token)
    assert gc.isenabled()
    assert collect_if_due(((1, 1, 1), True)) == -1  # (the collector on: nothing done here)


@pytest.mark.skipif(not hasattr(os, "sched_setaffinity"), reason="no CPU affinity on this OS")
def test_pin_to_cpu_pins_the_loops_thread_and_gives_later_threads_every_cpu():
    child = r"""
import os, threading
from robstiff_drake.cell.realtime_thread import pin_to_cpu, unpin_this_thread
allowed = sorted(os.sched_getaffinity(0))
cpu = allowed[-1]
print(pin_to_cpu(cpu))
print(sorted(os.sched_getaffinity(0)) == [cpu])
got = []
def later():
    unpin_this_thread()
    got.append(sorted(os.sched_getaffinity(0)) == allowed)
t = threading.Thread(target=later)
t.start(); t.join()
print(got[0])
print(pin_to_cpu(4095) is not None, sorted(os.sched_getaffinity(0)) == [cpu])
"""
    out = subprocess.run([sys.executable, "-c", child], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["None", "True", "True", "True", "True"], out.stdout


def test_pin_to_cpu_none_does_nothing():
    before = os.sched_getaffinity(0) if hasattr(os, "sched_getaffinity") else None
    assert pin_to_cpu(None) is None
    if before is not None:
        assert os.sched_getaffinity(0) == before
