"""A controller (EGM, Stream Motion: numbered messages) that restarts within
the first REORDER_WINDOW (64) messages: its new numbering is behind the
last one seen, inside the reorder window.  Before: every new message
dropped as "old", silently, until its numbering passed the old one.  After:
numbered from 0/1 again, RESTART_RUN in a row, it is the restart it is (the
restart path of a later one: ramp to zero, 25 consistent messages, then
compensating again); a run behind numbered from elsewhere is logged once.
The loop over a real EgmLink driven by script (tests/test_cell_review_loop.py):
no timing."""

import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(__file__))
from test_cell_review_loop import Q0, _check_every_pose, _drive, _messages  # noqa: E402

from robstiff_drake.cell.session import RESTART_RUN, SessionClock  # noqa: E402

T = 0.004


def test_an_early_restart_numbered_from_one_again_is_taken_as_a_restart(robot):
    from robstiff_drake.cell.compensate import CLEAR_MESSAGES

    n_good, n_after = 40, 90
    loop, link = _drive(robot, _messages(n_good, Q0) + _messages(n_after, Q0))  # 1..40, then 1..90 (clock too)
    corr = _check_every_pose(robot, link)
    said = loop.out.getvalue()
    assert f"the controller restarted ({RESTART_RUN} messages in a row numbered from 1 again" in said, said
    assert loop.n.old == RESTART_RUN - 1 and loop.n.jumps == 1, (loop.n.old, loop.n.jumps)
    assert len(corr) == n_good + n_after - (RESTART_RUN - 1)  # (the run's first ones dropped, then all answered)
    size = np.abs(corr).max(axis=1)
    assert size[n_good - 1] > 0.05
    zero = n_good + int(np.argmax(size[n_good:] == 0.0))
    assert np.all(np.diff(size[n_good - 1:zero + 1]) <= 1e-12)  # ramped to zero
    back = zero + int(np.argmax(size[zero:] > 0.0))
    assert back >= n_good + CLEAR_MESSAGES, (zero, back)
    assert size[-1] > 0.05  # compensating again


def test_a_run_behind_not_numbered_from_the_start_is_logged_once_and_not_answered(robot):
    n_good = 40
    tail = _messages(60, Q0, seq0=11, tm=lambda seq: (seq - 11) * 4)  # 11..70: 30 behind or at the last, then past it
    loop, link = _drive(robot, _messages(n_good, Q0) + tail)
    _check_every_pose(robot, link)
    said = loop.out.getvalue()
    assert said.count("messages in a row with sequence numbers behind the last one") == 1, said
    assert "nothing is answered until its numbering passes 40" in said, said
    # (11..39 old, 40 a duplicate of the last one: dropped; 41..70 answered)
    assert (loop.n.old, loop.n.duplicates, len(link.commanded)) == (29, 1, n_good + 30)


def test_reordered_datagrams_amid_newer_ones_are_never_a_restart():
    """Old datagrams 1, 2, 3 ... delayed, each arriving between newer ones: each one "old", never a restart."""
    c = SessionClock(T)
    for s in range(1, 41):
        assert c.accept(s, (s - 1) * 4)[0] == "ok"
    got = []
    for k in range(1, 10):
        got.append(c.accept(k, (k - 1) * 4)[0])
        assert c.accept(40 + k, (39 + k) * 4)[0] == "ok"
    assert got == ["old"] * 9 and c.counts["jump"] == 0


def test_a_short_run_behind_is_old():
    c = SessionClock(T)
    for s in range(1, 41):
        c.accept(s, (s - 1) * 4)
    assert [c.accept(s, (s - 1) * 4)[0] for s in range(1, RESTART_RUN)] == ["old"] * (RESTART_RUN - 1)
    assert c.accept(41, 160)[0] == "ok" and c.behind_run == 0
