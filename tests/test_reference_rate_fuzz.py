"""Property test of the played reference's rate (cell/reference_rate.py) over random but legal-to-receive
controller message streams, through the loop's own methods (tests/test_reference_stop.py ``drive``: the real
send path's checks, the correction held at zero, so the commanded path is the played reference).

The streams (hypothesis, derandomized: the same examples every run): an honest clock with -1/0/+1 ms stamp
jitter, clocks up to 0.1 % fast or slow, stalls resuming on from the stalled stamp or taking the time back,
clocks set back, clocks jumping ahead, sequence gaps of 1-5 (lost datagrams), jumps of more than 5, controller
restarts numbered from 1 with the clock from 0, a clock at half or double pace for a while; then 2 s of an
honest clock.  Paths at constant joint speeds up to 0.9 of the axis speeds (each joint as fast as its working
range allows over the run: q2's 140 deg at 0.9 of 90 deg/s last 1.7 s).

Invariants, after every message:
* the played time never ahead of the sequence's time since the start (the accepted messages' sequence steps
  times the period, a jump or restart one period, as ``ReferenceRate.seq_step_s``);
* the played time never decreases;
* every commanded pose's second difference within the acceleration limit * T^2 on every joint, nothing
  refused nor unanswered;
* the played time ahead of the session's allowance (t_ref - t_session) by at most ``stop_bound_s``; behind it
  by no more than the rate counts as forgotten (``_lag_s``: what ramps up played behind the clock), that by at
  most v / (2 a) + a period per ramp (the docstring's "about v / (2 a) s behind" after a stop and a restart);
* after 2 s of an honest clock, the played step is one period again.
"""

import math

import numpy as np
import pytest
import test_reference_stop as trs
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from robstiff_drake.cell.reference_rate import CLOCK_SLACK_S
from robstiff_drake.cell.session import MAX_JUMP, WRAP, SessionClock

T = trs.T
TAIL = 500  # messages of an honest clock at the end: 2 s
FUZZ = settings(derandomize=True, max_examples=250, deadline=None, database=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])

KINDS = ("honest", "drift", "stall_on", "stall_back", "set_back", "jump_ahead", "gap", "seq_jump", "restart",
         "half", "double")
# (a lost datagram, "gap": one period of the path in the answer after it, as in every answer:
# test_a_lost_datagram_at_speed_is_answered_one_period_on below)
FUZZED = KINDS
segment = st.tuples(st.sampled_from(FUZZED), st.integers(1, 120), st.integers(0, 10**6))


def stream(segments, seed):
    """(seqs, stamps ms) of the segments, then TAIL messages of an honest, jittering clock."""
    rng = np.random.default_rng(seed)
    seq, c = 1, 500.0  # the next sequence number; the controller's true time (ms)
    seqs, stamps = [], []

    def emit(stamp=None):
        nonlocal seq
        seqs.append(seq)
        stamps.append(int(round(c)) + int(rng.integers(-1, 2)) if stamp is None else stamp)
        seq += 1

    emit(500)
    for kind, n, p in segments:
        if kind == "set_back":
            c -= 1 + p % 300
        elif kind == "jump_ahead":
            c += 5 + p % 500
        elif kind == "gap":
            lost = 1 + p % MAX_JUMP
            seq, c = seq + lost, c + 4.0 * lost
        elif kind == "seq_jump":
            lost = MAX_JUMP + 1 + p % 1000
            seq, c = seq + lost, c + 4.0 * lost
        elif kind == "restart":
            seq, c = 1, 0.0
        if kind in ("stall_on", "stall_back"):
            held = stamps[-1]
            for _ in range(n):
                c += 4.0
                emit(held)
            if kind == "stall_on":
                c = float(held)
            continue
        step = {"half": 2.0, "double": 8.0, "drift": 4.0 * (1.0 + ((p % 2001) - 1000) * 1e-6)}.get(kind, 4.0)
        for _ in range(n):
            c += step
            emit()
    for _ in range(TAIL):
        c += 4.0
        emit()
    return np.array(seqs) % WRAP, np.array(stamps) % WRAP


def seq_time(seqs, stamps, tol_ms):
    """The sequence's time since the start after every message (s): the accepted messages' steps (the session
    clock's own verdicts), a jump or restart one period; and the verdicts."""
    clock = SessionClock(T, tol_ms)
    out, verdicts, last, s = [], [], None, 0.0
    for q, tm in zip(seqs, stamps):
        v, _ = clock.accept(int(q), int(tm))
        verdicts.append(v)
        if v not in ("duplicate", "old"):
            if last is not None:
                ds = (int(q) - last) % WRAP
                s += ds * T if 0 < ds <= MAX_JUMP else T
            last = int(q)
        out.append(s)
    return np.array(out), verdicts


def speeds_for(robot, fraction, n):
    """Joint speeds (deg/s): ``fraction`` of the axis speeds, each joint as far as its range allows over n
    messages' path (the harness's path is straight through the ranges' middle)."""
    span = np.degrees(robot.q_upper_rad - robot.q_lower_rad)
    v = fraction * np.asarray(robot.speed_limit_deg_per_s, dtype=float)
    return np.minimum(v, 0.95 * span / ((n + 10) * T))


def accelerating_path(robot, speed_deg_per_s, duration_s, accel_fraction):
    """A straight joint path from rest at ``accel_fraction`` of the acceleration limits up to the constant
    ``speed_deg_per_s``, from near the ranges' lower ends, rows every T: (times s, q deg)."""
    lo, hi = np.degrees(robot.q_lower_rad), np.degrees(robot.q_upper_rad)
    v = np.asarray(speed_deg_per_s, dtype=float) * np.ones(6)
    a = accel_fraction * np.asarray(robot.acceleration_limit_deg_per_s2, dtype=float)
    t = np.arange(0.0, duration_s + 1e-9, T)[:, None]
    t1 = v / a  # (s: the end of the acceleration per joint)
    q = lo + 0.025 * (hi - lo) + np.where(t < t1, 0.5 * a * t**2, 0.5 * a * t1**2 + v * (t - t1))
    assert (q > lo).all() and (q < hi).all()
    return t[:, 0], q


def run(robot, fraction, seqs, stamps, accel_fraction=None):
    """``drive`` over the stream on a path long enough for it: constant speed, or from rest at
    ``accel_fraction`` of the acceleration limits."""
    n = len(seqs)
    orig = trs.path
    d = (n + 10) * T
    mine = ((lambda r, v: orig(r, v, duration_s=d)) if accel_fraction is None else
            (lambda r, v: accelerating_path(r, v, d, accel_fraction)))
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(trs, "path", mine)
        v = speeds_for(robot, fraction, n)
        return v, trs.drive(robot, v, seqs, stamps)


def check(robot, fraction, seqs, stamps, events=1):
    """The invariants (module docstring) over the stream; ``events``: the clock's changes in it (each may cost a
    slow-down and a ramp up)."""
    v, (loop, cmd, ts, tr, text) = run(robot, fraction, seqs, stamps)
    rate = loop.rate
    acc = np.asarray(robot.acceleration_limit_deg_per_s2, dtype=float)
    seq_s, verdicts = seq_time(seqs, stamps, loop.clock.tol_ms)
    assert verdicts.count("jump") == loop.n.jumps
    answered = sum(v not in ("duplicate", "old") for v in verdicts)
    assert loop.n.refused == 0 and loop.n.unanswered_refused == 0, text
    assert len(cmd) == answered
    # the played time: never ahead of the sequence's, never back
    assert (tr <= seq_s + 1e-9).all(), ("ahead of the sequence", int(np.argmax(tr - seq_s)), (tr - seq_s).max())
    assert (np.diff(tr) >= -1e-12).all(), ("played time back", np.diff(tr).min())
    # every commanded second difference within the acceleration limit * T^2
    if len(cmd) > 2:
        d2 = np.abs(np.diff(cmd, 2, axis=0)) / (acc * T**2)
        assert d2.max() <= 1.0 + 1e-6, ("acceleration", int(np.argmax(d2.max(axis=1))), d2.max())
    if rate is None:  # (a path at rest: the allowance played as it is)
        assert np.array_equal(tr, ts)
        return loop, tr, ts
    # the lead over the allowance, and the time behind it
    lead = tr - ts
    assert lead.max() <= rate.stop_bound_s + 1e-9, ("lead", lead.max(), rate.stop_bound_s)
    per_ramp = 0.5 * float((v / acc).max()) + T
    assert -lead.min() <= rate._lag_s + 1e-9, ("behind the allowance beyond what the rate counts",
                                               -lead.min(), rate._lag_s)
    # (one ramp spans several of the clock's changes when they come before it ends: half pace, then a stall,
    # then the clock's pace again rise twice; a bound per ramp begun was exceeded by 18 %: per change)
    # (and each lost datagram's period: the answer after a gap plays one period, the skipped ones behind)
    ds = np.diff(np.asarray(seqs, dtype=np.int64)) % WRAP
    skipped_s = float(np.sum(np.where((ds > 1) & (ds <= MAX_JUMP), ds - 1, 0))) * T
    assert rate._lag_s <= max(rate.ramps, events) * (per_ramp + CLOCK_SLACK_S) + skipped_s + 1e-9, (
        "behind", rate._lag_s, rate.ramps, per_ramp, skipped_s)
    # 2 s of an honest clock: the path at its own speed again
    assert np.allclose(np.diff(tr[-20:]), T, rtol=0, atol=1e-9), np.diff(tr[-20:])
    assert rate.following and rate.r == 1.0
    return loop, tr, ts


@FUZZ
@given(segments=st.lists(segment, min_size=1, max_size=5), seed=st.integers(0, 2**16),
       fraction=st.one_of(st.just(0.9), st.just(0.0), st.floats(0.0, 0.9)))
def test_random_legal_streams_keep_the_rates_invariants(robot, segments, seed, fraction):
    seqs, stamps = stream(segments, seed)
    check(robot, fraction, seqs, stamps, events=len(segments))


@pytest.mark.parametrize("case", ["rapid", "feed"])
def test_after_a_stall_an_honest_jittering_clock_lets_the_ramp_up_finish(robot, case):
    """The fuzz's minimized case: a stall (tests/test_reference_stop.py ``stalled``) and then an honest clock whose
    stamps jitter by -1, 0, +1 ms (fixed seed).  The ramp up ends as it does without the jitter: the path at its
    own speed within the run, the time played behind the clock about v / (2 a) (+ the slack, a period).  Before:
    under the ramp every 3 ms stamp pulled the rate down to it (the ramp tracked the allowance with no slack, and a
    lead of a fraction of a ms stopped the rise), so at a rapid the ramp up took 250 messages and more (still
    3.1 ms a 4 ms message at the end), 218 ms of the path behind the clock against 76 ms without the jitter."""
    n = 400
    seqs, stamps = trs.stalled(n)
    jitter = np.random.default_rng(5).integers(-1, 2, n)
    jitter[: trs.STALL[1]] = 0
    v = trs.speeds(robot, case)
    loop, _cmd, _ts, tr, text = trs.drive(robot, v, seqs, stamps + jitter)
    assert loop.n.refused == 0 and loop.n.unanswered_refused == 0, text
    assert np.allclose(np.diff(tr[-20:]), T, rtol=0, atol=1e-9), np.diff(tr[-20:])
    per_ramp = 0.5 * float((v / np.asarray(robot.acceleration_limit_deg_per_s2)).max()) + T
    assert loop.rate.summary()["behind_clock_ms"] <= (per_ramp + 2e-3) * 1e3, loop.rate.summary()


@pytest.mark.parametrize("fraction", [0.005, 0.1, 0.2, 0.6])
def test_a_lost_datagram_at_speed_is_answered_within_the_accelerations(robot, fraction):
    """One lost datagram (a sequence gap of 2) under an honest clock, the path at ``fraction`` of the axis
    speeds: the answer after it plays one period of the path and what of the skipped one the step's change within
    the acceleration limit and the axis speeds allows (the whole of it at a slow feed, a few per cent at a
    rapid), the rest counted behind the clock; nothing refused.  Before: the sequence's two periods in one
    answer, a step change of v T (0.24 deg on q1 at 0.6) where the acceleration supervision allows 10 a T^2
    (0.064 deg): refused, its fallback too, and every later message as well, the reference moving on from a pose
    the controller never got (at 0.2 and 0.6 of the axis speeds all 150 messages after the gap unanswered; at
    0.1, none).  Found by the fuzz above."""
    k = np.arange(300)
    seqs = 1 + k + (k >= 150)
    stamps = 500 + 4 * (seqs - 1)
    vmax = np.asarray(robot.speed_limit_deg_per_s, dtype=float)
    acc = np.asarray(robot.acceleration_limit_deg_per_s2, dtype=float)
    v = fraction * vmax
    loop, cmd, _ts, tr, text = trs.drive(robot, v, seqs, stamps)
    assert loop.n.refused == 0 and loop.n.unanswered_refused == 0 and len(cmd) == len(seqs), text
    assert (np.abs(np.diff(cmd, 2, axis=0)) / (acc * T**2)).max() <= 1.0 + 1e-6
    steps = np.diff(tr)
    extra = min(float((acc * T * T / v).min()), float(((vmax / v - 1.0) * T).min()))
    want = min(2 * T, T + extra)
    assert math.isclose(steps[149], want, abs_tol=1e-12), (steps[149], want)
    assert np.allclose(np.delete(steps, 149), T, rtol=0, atol=1e-12)
    assert math.isclose(loop.rate.summary()["behind_clock_ms"], (2 * T - want) * 1e3, abs_tol=1e-9)
    if fraction == 0.005:  # (a slow feed: the skipped period whole, the path on the controller's time)
        assert math.isclose(want, 2 * T)


@FUZZ
@given(segments=st.lists(segment, min_size=1, max_size=4), seed=st.integers(0, 2**16),
       fraction=st.floats(0.05, 0.9), accel_fraction=st.sampled_from([0.25, 0.5, 1.0]))
def test_a_path_from_rest_keeps_within_its_own_and_the_rates_accelerations(robot, segments, seed, fraction,
                                                                           accel_fraction):
    """The path accelerates from rest at a fraction of the limits: every commanded second difference within the
    path's own acceleration plus the rate's (the limit: ``ACCEL_FRACTION`` 1.0), times T^2; nothing refused; the
    played time never ahead of the sequence's, never back; the path at its own pace after 2 s of an honest clock."""
    seqs, stamps = stream(segments, seed)
    v, (loop, cmd, _ts, tr, text) = run(robot, fraction, seqs, stamps, accel_fraction)
    acc = np.asarray(robot.acceleration_limit_deg_per_s2, dtype=float)
    assert loop.n.refused == 0 and loop.n.unanswered_refused == 0, text
    d2 = np.abs(np.diff(cmd, 2, axis=0)) / ((1.0 + accel_fraction) * acc * T**2)
    assert d2.max() <= 1.0 + 1e-6, ("acceleration", int(np.argmax(d2.max(axis=1))), d2.max())
    seq_s, _ = seq_time(seqs, stamps, loop.clock.tol_ms)
    assert (tr <= seq_s + 1e-9).all() and (np.diff(tr) >= -1e-12).all()
    assert np.allclose(np.diff(tr[-20:]), T, rtol=0, atol=1e-9), np.diff(tr[-20:])
