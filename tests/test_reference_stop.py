"""A controller clock that stalls while its messages keep coming: the
played reference stops and starts again within the robot's accelerations
(cell/reference_rate.py), not within one cycle.  The loop's own methods
(``_session``, ``cycle``) over scripted messages and a send path that makes
the real one's checks (cell/safety.py ``unsafe_reason``, ``motion_reason``
with the supervision's step and acceleration tolerances): no socket, no
timing.  The correction is held at zero (``correction_off``): the commanded
path is the played reference.

Before: the reference held within one cycle of the stall and took up its
speed within one cycle when the clock ran again.  At a rapid's joint speeds
(0.6 of the robot file's axis speeds) the stop's target was refused by the
supervision (a step change of 0.24 deg on q1 where it allows 0.064), its
fallback too, and the message went unanswered; at a cutting feed (2 deg/s)
the stop went through at 1.25 times the acceleration limit * T^2 (within
the supervision's 10 times: a jerk on a real arm)."""

import io
import math

import cell_helpers as h
import numpy as np
import pytest
from test_reference_pace import _Sensor  # (one record of the hold's wrench per read, on the test's clock)

from robstiff_drake.cell.compensate import CompensatorLoop, LoopSettings, Reference
from robstiff_drake.cell.link import Message
from robstiff_drake.cell.safety import UnsafeTarget, motion_reason, unsafe_reason

T = 0.004
RAPID = 0.6  # a rapid: this fraction of the robot file's axis speeds on every joint
FEED_DEG_PER_S = 2.0  # a cutting feed's joint speeds (about 50 mm/s at the tool of a 2.5 m arm)
STALL = (100, 150)  # the messages whose clock stamp is the one before (the clock stalled)


class _CheckedLink:
    """A send path with the real one's checks (cell/link.PCLink.send_targets): the commanded poses kept, and
    the largest second difference (deg, per joint) of every target checked, sent or refused."""

    name, option, port, cycles_ms = "EGM", "--egm-port", 0, (4.0,)
    strangers = malformed = 0

    def __init__(self):
        self.commanded = []
        self.tried_d2 = [0.0] * 6

    def send_targets(self, msg, target, env):
        if len(self.commanded) >= 2:
            p2, p1 = self.commanded[-2:]
            self.tried_d2 = [max(m, abs(x - 2.0 * b + a)) for m, x, b, a in zip(self.tried_d2, target, p1, p2)]
        reason = unsafe_reason(target, env) or motion_reason(target, env, self.commanded[-2:])
        if reason is not None:
            raise UnsafeTarget(reason)
        self.commanded.append(list(target))


def path(robot, speed_deg_per_s, duration_s=2.0):
    """A straight joint path at constant joint speeds (deg/s), rows every T, through the working ranges' middle
    at half its duration: (times s, q deg)."""
    lo, hi = np.degrees(robot.q_lower_rad), np.degrees(robot.q_upper_rad)
    v = np.asarray(speed_deg_per_s, dtype=float) * np.ones(6)
    t = np.arange(0.0, duration_s + 1e-9, T)
    q = 0.5 * (lo + hi) + v * (t[:, None] - 0.5 * duration_s)
    assert (q > lo).all() and (q < hi).all()
    return t, q


def drive(robot, speed_deg_per_s, seqs, stamps_ms, ramp=True):
    """The loop over messages (``seqs``, ``stamps_ms``), the arm at the last pose commanded; returns (loop, the
    poses commanded (one per answered message, deg), t_session after each message, the played reference's time
    after each message (t_session where there is none: before), the loop's text).  ``ramp`` False: the loop's
    rate taken away, the session's allowance played as it is (the loop before cell/reference_rate.py)."""
    t_ref, q_ref = path(robot, speed_deg_per_s)
    ref = Reference(t_ref, q_ref, period_s=T)
    clock = [1000.0]
    w = h.hold_wrench(robot, np.radians(q_ref[0]))(0.0)
    out = io.StringIO()
    link = _CheckedLink()
    loop = CompensatorLoop(h.hold_compensator(robot, list(w)), link, _Sensor(list(w), clock), ref, robot,
                           LoopSettings(period_s=T, max_jump_Nm=350.0, max_correction_mm=math.inf,
                                        max_correction_deg=math.inf, start_tolerance_N=math.inf,
                                        sensor_rate_hz=250.0, correction_off="held at zero in the test"), out=out)
    loop.pc_time = lambda: clock[0]
    if not ramp:
        loop.rate = None
    ts, tr = [], []
    for i, (seq, tm) in enumerate(zip(seqs, stamps_ms)):
        arm = link.commanded[-1] if link.commanded else q_ref[0].tolist()
        msg = Message(int(seq) % 2**32, int(tm) % 2**32, list(arm), echo=int(seq))
        if i == 0:
            loop.run_start(msg, clock[0])
        else:
            clock[0] += T
            ok, dt = loop._session(msg)
            if ok:
                loop.cycle(msg, clock[0], dt)
        ts.append(loop.t_session)
        tr.append(getattr(loop, "t_ref", loop.t_session))
    return loop, np.array(link.commanded), np.array(ts), np.array(tr), out.getvalue()


def stalled(n=400, resume="on"):
    """Seqs and stamps (ms): 4 ms a message, the stamp stuck for the messages in STALL; then on from the stalled
    stamp ("on") or from where it would have been ("back": the stalled time in one step)."""
    k = np.arange(n)
    a, b = STALL
    after = 4 * (a - 1) + 4 * (k - b + 1) if resume == "on" else 4 * k
    return 1 + k, 500 + np.where(k < a, 4 * k, np.where(k < b, 4 * (a - 1), after))


def speeds(robot, case):
    return RAPID * robot.speed_limit_deg_per_s if case == "rapid" else FEED_DEG_PER_S * np.ones(6)


@pytest.mark.parametrize("resume", ["on", "back"])
@pytest.mark.parametrize("case", ["rapid", "feed"])
def test_a_stalled_clock_stops_and_restarts_the_path_within_the_robots_accelerations(robot, case, resume):
    """Every commanded step changes by at most the acceleration limit * T^2 per joint (the reference's own speed
    is constant), nothing refused or unanswered, the played time never ahead of the sequence's, and its lead over
    the stalled clock within v / (2 a) (+ a period).  Before: at a rapid, 0.24 deg where the supervision allows
    0.064 (refused, unanswered); at a feed 1.25 times the limit."""
    seqs, stamps = stalled(resume=resume)
    loop, cmd, ts, tr, text = drive(robot, speeds(robot, case), seqs, stamps)
    acc_T2 = np.asarray(robot.acceleration_limit_deg_per_s2) * T**2
    d2 = np.abs(np.diff(cmd, 2, axis=0))
    assert loop.n.refused == 0 and loop.n.unanswered_refused == 0, text
    assert len(cmd) == len(seqs)
    worst = (d2 / acc_T2).max()
    assert worst <= 1.0 + 1e-6, worst
    seq_s = (seqs - seqs[0]) * T
    assert (tr <= seq_s + 1e-12).all(), (tr - seq_s).max()
    v_over_a = float((speeds(robot, case) / np.asarray(robot.acceleration_limit_deg_per_s2)).max())
    lead = (tr - ts).max()
    assert lead <= 0.5 * v_over_a + T + 1e-9, (lead, v_over_a)
    assert lead <= loop.rate.stop_bound_s
    # the path stopped within the stall and moves at its speed again at the end
    _a, b = STALL
    assert cmd[b - 1].tolist() == cmd[b - 2].tolist()
    assert np.allclose(cmd[-1] - cmd[-2], speeds(robot, case) * T)
    # said once at the stop's start and once at its end, and counted
    assert text.count("the played reference slows") == 1 and text.count("at the clock's pace again") == 1, text
    assert loop.stats()["reference_rate"]["messages_under_ramp"] == loop.rate.messages > 50
    # the loop without the rate (before): the stop within one cycle
    loop, cmd, _, _, _ = drive(robot, speeds(robot, case), seqs, stamps, ramp=False)
    if case == "rapid":
        assert loop.n.refused > 0 and loop.n.unanswered_refused > 0
    else:
        assert loop.n.refused == 0 and (np.abs(np.diff(cmd, 2, axis=0)) / acc_T2).max() > 1.2


@pytest.mark.parametrize("case", ["rapid", "feed"])
def test_a_controller_restart_mid_path_keeps_the_paths_speed_within_the_accelerations(robot, case):
    """The controller restarts after 200 messages (numbered from 1 again, its clock from 0): the session's
    "jump", whose step is 0 there (its clock went back), goes through the rate like any message, the rate and
    its lead carried across.  Before: a stop within one cycle, at a rapid 37.5 times the acceleration limit *
    T^2: refused, unanswered."""
    k = np.arange(200)
    seqs, stamps = np.r_[1 + k, 1 + k], np.r_[500 + 4 * k, 4 * k]
    acc_T2 = np.asarray(robot.acceleration_limit_deg_per_s2) * T**2
    for ramp in (True, False):
        loop, cmd, ts, tr, text = drive(robot, speeds(robot, case), seqs, stamps, ramp=ramp)
        assert loop.n.jumps == 1, text
        worst = (np.asarray(loop.link.tried_d2) / acc_T2).max()
        if ramp:
            assert loop.n.refused == 0 and loop.n.unanswered_refused == 0 and len(cmd) == len(seqs), text
            assert worst <= 1.0 + 1e-6, worst
            assert (tr - ts).max() <= T + 1e-9 and np.allclose(cmd[-1] - cmd[-2], speeds(robot, case) * T)
        elif case == "rapid":
            assert loop.n.unanswered_refused > 0 and worst > 10.0
        else:
            assert worst > 1.2


@pytest.mark.parametrize("fraction", [0.1, RAPID])
def test_an_honest_clock_plays_the_path_at_its_own_speed_one_step_a_message(robot, fraction):
    """A path at ``fraction`` of the axis speeds under an honest clock whose stamps jitter by -1, 0 or +1 ms
    (whole ms, fixed seed): the played time steps by the sequence's period at every message, within 2 ms of the
    session's (CLOCK_SLACK_S) and never ahead of the sequence's, every commanded step the same, no ramp, nothing
    refused.  Before: the played step followed the stamps (3, 5, 4 ms): at 0.6 of the axis speeds a step change
    the supervision refused, and the path never got back within the step tolerance (most messages unanswered)."""
    n = 400
    k = np.arange(n)
    jitter = np.random.default_rng(5).integers(-1, 2, n)
    jitter[0] = 0
    seqs, stamps = 1 + k, 1_000 + 4 * k + jitter
    v = fraction * robot.speed_limit_deg_per_s
    loop, cmd, ts, tr, text = drive(robot, v, seqs, stamps)
    assert loop.n.refused == 0 and loop.n.unanswered_refused == 0 and len(cmd) == n, text
    assert np.allclose(np.diff(tr), T, rtol=0, atol=1e-12)
    assert (tr - ts).max() <= 2e-3 + 1e-12 and (tr <= (seqs - seqs[0]) * T + 1e-12).all()
    assert loop.rate.messages == 0 and "slows" not in text
    assert np.allclose(np.diff(cmd, axis=0), v * T, rtol=0, atol=1e-9)
    # the allowance played as it comes (before): the stamps' jitter in the path
    before, _cmd_b, _, tr_b, _ = drive(robot, v, seqs, stamps, ramp=False)
    assert np.abs(np.diff(tr_b) - T).max() >= 1e-3 - 1e-12
    if fraction == RAPID:
        assert before.n.unanswered_refused > n // 2


def test_without_acceleration_limits_or_on_a_held_reference_the_allowance_is_played_as_it_is(robot):
    """No acceleration limits in the robot file: the played time is the session's through the stall, as before
    (the held reference's loop: tests/test_reference_pace.py's, unchanged)."""
    from dataclasses import replace

    loop, _cmd, ts, tr, _ = drive(replace(robot, acceleration_limit_deg_per_s2=None), FEED_DEG_PER_S, *stalled())
    assert loop.rate is None and np.array_equal(tr, ts)
    from robstiff_drake.cell.reference_rate import ReferenceRate

    ref = Reference(period_s=T)
    ref.hold([0.0] * 6)
    assert ReferenceRate.of(T, robot, ref) is None


def test_a_stall_that_ended_is_not_named_a_wrong_period_nor_keeps_the_correction_off(robot):
    """The clock stalls for 50 messages and runs on from its stalled stamp at the sequence's pace: its fault ends
    with the stall.  Before: each stalled step went into the clock's drift (up to the tolerance, -3 ms each),
    the drift stayed beyond its allowance for seconds after the stall, the loop said "--period-ms is not the
    controller's cycle" and the clock's fault (the correction at zero) lasted past the end of the run."""
    seqs, stamps = stalled(n=600, resume="on")
    loop, _cmd, _ts, _tr, text = drive(robot, FEED_DEG_PER_S, seqs, stamps)
    assert "is not the controller's cycle" not in text, text
    assert abs(loop.clock.clock_drift_ms) < 1.0, loop.clock.clock_drift_ms
    assert "clock" not in loop.faults and "period" not in loop.faults, loop.faults
    # the stall itself was the clock's fault, every stalled message
    assert loop.clock.counts["clock"] >= STALL[1] - STALL[0] - 1


@pytest.mark.parametrize("case", ["rapid", "feed"])
def test_a_clock_at_half_the_pace_slows_the_path_to_it_within_the_accelerations(robot, case):
    """From message 100 on the clock steps 2 ms a 4 ms message (a controller whose cycle is half --period-ms,
    or a slow clock): the played path slows to the clock's pace (one step of 2 ms a message at the end) within
    the acceleration limit, nothing refused, never ahead of the sequence's time, its lead over the clock within
    a stop's (v / (2 a) + a period).  Before: the played step fell from 4 to 2 ms within one message."""
    n = 400
    k = np.arange(n)
    seqs, stamps = 1 + k, 500 + np.where(k < 100, 4 * k, 400 + 2 * (k - 100))
    v = speeds(robot, case)
    acc_T2 = np.asarray(robot.acceleration_limit_deg_per_s2) * T**2
    loop, cmd, ts, tr, text = drive(robot, v, seqs, stamps)
    assert loop.n.refused == 0 and loop.n.unanswered_refused == 0 and len(cmd) == n, text
    assert (np.abs(np.diff(cmd, 2, axis=0)) / acc_T2).max() <= 1.0 + 1e-6
    assert (tr <= (seqs - seqs[0]) * T + 1e-12).all()
    v_over_a = float((v / np.asarray(robot.acceleration_limit_deg_per_s2)).max())
    assert (tr - ts).max() <= 0.5 * v_over_a + T + 1e-9
    assert np.allclose(np.diff(tr[-20:]), 0.002, rtol=0, atol=1e-9)
    _, _, _, tr_b, _ = drive(robot, v, seqs, stamps, ramp=False)
    steps = np.diff(tr_b)
    i = int(np.argmax(steps < 0.004 - 1e-9))
    assert i > 50 and np.isclose(steps[i - 1], 0.004) and steps[i] <= 0.002 + 1e-9  # (4 -> 2 ms in one message)


def test_a_clock_slightly_slow_makes_small_ramps_said_five_times_not_each_time(robot):
    """A clock 0.1 % slow (whole-ms stamps, floored: honest by the session's checks) under a path at 0.1 of the
    axis speeds for 7.6 s: the played time falls more than 2 ms behind the sequence's now and then, and each time
    a small ramp (a step of at most a few tenths of a period less) pays it back within the accelerations; the
    events say the first five ramps' start and end, summary.json counts them all.  Before: a line at each."""
    import test_reference_stop as trs

    orig = trs.path
    try:
        trs.path = lambda robot, v, duration_s=2.0: orig(robot, v, duration_s=8.0)
        k = np.arange(1900)
        v = 0.1 * robot.speed_limit_deg_per_s
        loop, cmd, ts, tr, text = drive(robot, v, 1 + k, 500 + np.floor(4 * k * 0.999).astype(int))
    finally:
        trs.path = orig
    acc_T2 = np.asarray(robot.acceleration_limit_deg_per_s2) * T**2
    assert loop.n.refused == 0 and loop.n.unanswered_refused == 0
    assert (np.abs(np.diff(cmd, 2, axis=0)) / acc_T2).max() <= 1.0 + 1e-6
    assert loop.rate.ramps > 5
    assert text.count("the played reference slows") == 5 and text.count("at the clock's pace again") == 5
    assert loop.stats()["reference_rate"]["ramps"] == loop.rate.ramps
    assert (tr - ts).max() <= 3e-3 and np.diff(tr).min() >= 0.5 * T
