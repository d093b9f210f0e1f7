"""commands/compensate._realtime: with --rt-priority the loop's thread runs
under SCHED_FIFO at that priority and the threads started before it (the
sensor reader's) one below, so none of them is preempted by an ordinary
process while it holds Python's interpreter lock.  Run in a child process
(the scheduling class is left behind with it); skipped where the machine
does not allow real-time scheduling."""

import os
import subprocess
import sys

import pytest

CHILD = r"""
import os, sys, threading, time
from robstiff_drake.commands.compensate import _realtime
ready, done = threading.Event(), threading.Event()
tid = []
def reader():
    tid.append(threading.get_native_id())
    ready.set()
    done.wait(10)
t = threading.Thread(target=reader, daemon=True)
t.start()
ready.wait(10)
_realtime(int(sys.argv[1]))
me = os.sched_getscheduler(0), os.sched_getparam(0).sched_priority
other = os.sched_getscheduler(tid[0]), os.sched_getparam(tid[0]).sched_priority
done.set()
print(me[0] == os.SCHED_FIFO, me[1], other[0] == os.SCHED_FIFO, other[1])
"""


def _fifo_allowed():
    try:
        out = subprocess.run([sys.executable, "-c", "import os; os.sched_setscheduler(0, os.SCHED_FIFO, "
                              "os.sched_param(1))"], capture_output=True, timeout=30)
        return out.returncode == 0
    except (OSError, subprocess.TimeoutExpired):
        return False


@pytest.mark.skipif(not hasattr(os, "sched_setscheduler") or not _fifo_allowed(),
                    reason="real-time scheduling (SCHED_FIFO) not permitted on this machine")
def test_the_loop_and_the_threads_before_it_run_real_time():
    out = subprocess.run([sys.executable, "-c", CHILD, "20"], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["True", "20", "True", "19"], out.stdout
