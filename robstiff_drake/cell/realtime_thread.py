"""The compensator process's scheduling: its loop's thread under
SCHED_FIFO (``--rt-priority``) with the threads it started before, and the
garbage collector kept out of the loop's way.  The start's own work runs
below the loop (cell/start_gate.below_the_loop)."""

import sys

def realtime(priority):
    """Run the loop's thread under SCHED_FIFO at ``priority`` (1-99), as a
    real-time PC would; 0: leave the scheduling alone.  Not permitted (no
    privilege): a warning, and the loop runs anyway.

    The process's threads started before it (the sensor reader's) go to
    SCHED_FIFO one below the loop: they take Python's interpreter lock to
    hand over each record, and one of them preempted by another process
    while it holds the lock would hold up the loop for that process's time
    slice (the loop's own priority does not help it then).  Threads started
    later (the log's writer) inherit the loop's scheduling."""
    if not priority:
        return
    import os
    import threading

    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(int(priority)))
    except (AttributeError, PermissionError, OSError) as e:
        print(f"robstiff: warning: --rt-priority {priority}: cannot switch to real-time scheduling ({e}); running "
              "without it", file=sys.stderr)
        return
    me = threading.get_native_id()
    try:
        tids = [int(t) for t in os.listdir("/proc/self/task")]
    except OSError:
        return  # (not Linux: the loop's thread only)
    for tid in tids:
        if tid != me:
            try:
                os.sched_setscheduler(tid, os.SCHED_FIFO, os.sched_param(max(int(priority) - 1, 1)))
            except OSError:
                pass  # (a thread that ended meanwhile)


def quiet_gc():
    """Freeze the objects made so far out of the garbage collector's reach
    (fewer and shorter collection pauses in the loop)."""
    import gc

    gc.collect()
    gc.freeze()
    return True


def restore_gc(frozen):
    import gc

    if frozen:
        gc.unfreeze()
