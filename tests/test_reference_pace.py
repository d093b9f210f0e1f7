"""The reference `robstiff compensate` plays against the controller's own
clock (cell/session.py ``SessionClock._pace``): its time since the run's
start is at most the sequence's steps times --period-ms and at most the
controller's clock elapsed, from the first message, whatever the verdicts;
an honest clock's 1 ms resolution costs no lag that grows.  The loop's own
methods (``_session``, ``cycle``) over scripted messages: no socket, no
timing.

Before: the reference advanced by the clock's step only while it stayed
within the tolerance of the sequence's time, and by the sequence's on every
fault: --period-ms 8 on a 4 ms controller (EGM, Stream Motion at 250 Hz)
played 8 ms a 4 ms message, twice the program's feed, until the clock's
drift was the fault and 25 messages more named the period; a slow or
stalled clock had the reference at the sequence's pace; a clock set a few
ms ahead had it ahead by as much."""

import io
import math

import numpy as np
import pytest

import cell_helpers as h
from robstiff_drake.cell.compensate import CompensatorLoop, LoopSettings, Reference
from robstiff_drake.cell.egm import EgmLink
from robstiff_drake.cell.link import Message
from robstiff_drake.cell.session import SessionClock
from robstiff_drake.cell.stream_motion import StreamMotionLink

Q0 = [0.0, 7.008, 29.517, 0.0, 53.476, 0.0]
PUSH_N = [3000.0, -2000.0, 0.0, 0.0, 0.0, 0.0]  # (a correction of about 0.14 deg: tests/test_cell_review_loop.py)
WRONG = "--period-ms is not the controller's cycle"


class _Link:
    """A protocol's name and cycles (its link's class attributes) and a send path that keeps the targets."""

    option, port = "--port", 0

    def __init__(self, kind):
        self.name, self.cycles_ms = kind.name, kind.cycles_ms
        self.sent = []

    def send_targets(self, msg, target, env):
        self.sent.append(list(target))


class _Sensor:
    """One record of ``w`` per read, stamped on the test's clock."""

    def __init__(self, w, clock):
        self.w, self.clock = w, clock

    def drain(self):
        return [(list(self.w), self.clock[0], 0, False)]


def _drive(robot, period_ms, seqs, stamps_ms, kind=EgmLink, push=False):
    """The loop at --period-ms ``period_ms`` over messages (``seqs``, ``stamps_ms``: the controller's clock, ms,
    wrapped to 32 bits), one every 4 ms on the test's clock, holding Q0; returns (loop, the reference's time after
    each message s, the corrections after each message deg, the loop's text)."""
    w = np.asarray(h.hold_wrench(robot, np.radians(Q0))(0.0)) + (PUSH_N if push else 0.0)
    clock = [1000.0]
    ref = Reference(period_s=period_ms * 1e-3)
    ref.hold(Q0)
    out = io.StringIO()
    link = _Link(kind)
    loop = CompensatorLoop(h.hold_compensator(robot, w.tolist()), link, _Sensor(w.tolist(), clock), ref, robot,
                           LoopSettings(period_s=period_ms * 1e-3, max_jump_Nm=350.0, max_correction_mm=math.inf,
                                        max_correction_deg=math.inf, start_tolerance_N=math.inf,
                                        sensor_rate_hz=250.0), out=out)
    loop.pc_time = lambda: clock[0]
    ts, corr = [], []
    for i, (seq, tm) in enumerate(zip(seqs, stamps_ms)):
        msg = Message(int(seq) % 2**32, int(tm) % 2**32, list(Q0), echo=int(seq))
        if i == 0:
            loop.run_start(msg, clock[0])
        else:
            clock[0] += 0.004
            ok, dt = loop._session(msg)
            if ok:
                loop.cycle(msg, clock[0], dt)
        ts.append(loop.t_session)
        corr.append(max(abs(c) for c in loop.comp.correction))
    return loop, np.array(ts), np.degrees(corr), out.getvalue()


def _elapsed_s(x, unit_s):
    x = np.asarray(x, dtype=float)
    return (x - x[0]) * unit_s


# ------------------------------------------------------------------------------------ (a) a wrong, longer --period-ms

@pytest.mark.parametrize("kind, period_ms, late", [(EgmLink, 8, False), (EgmLink, 8, True),
                                                   (StreamMotionLink, 8, False), (StreamMotionLink, 8, True),
                                                   (EgmLink, 12, False)])
def test_a_period_longer_than_the_controllers_4_ms_never_plays_faster_than_its_clock(robot, kind, period_ms, late):
    """--period-ms 8 (12) against a controller whose clock steps 4 ms a message (stamped up to 1 ms late, fixed
    seed): after every message, from the first, the reference's time is at most the clock's elapsed + 1 ms, and
    the wrong period is still named once.  Before: 8 ms a message until the drift's fault and 25 more messages
    (0.55 s after 100 messages where the clock showed 0.4 s; at 12 ms, 1.2 s): twice (three times) the program's
    feed, the arm following it."""
    n = 200
    k = np.arange(n)
    stamps = 7_000 + 4 * k + (np.random.default_rng(3).integers(0, 2, n) if late else 0)
    loop, ts, _, text = _drive(robot, period_ms, 1 + k, stamps, kind)
    clock_s = _elapsed_s(stamps, 1e-3)
    assert (ts <= clock_s + 1e-3 + 1e-9).all(), (ts - clock_s).max()
    assert ts[-1] >= clock_s[-1] - 1e-3 - 1e-9  # (not held either: the clock's pace)
    said = [ln for ln in text.splitlines() if WRONG in ln]
    assert len(said) == 1 and "plays at 1.00 times" in said[0], text
    assert loop.n.refused == 0


# ------------------------------------------------------------------------------- (b) an honest clock's resolution

def test_an_honest_clocks_jitter_costs_no_lag_that_grows_and_never_plays_ahead(robot):
    """An honest 4 ms controller whose stamps jitter by -1, 0 or +1 ms (whole ms, fixed seed; its first on time):
    after each of 1000 messages the reference's time is within 1 ms of the sequence's, never ahead of the
    sequence's nor of the clock's, and no fault.  (A rule taking the smaller step per message would lag 0.45 s
    here.  Before: it followed the clock's stamps, 1 ms ahead of the sequence's on a third of the messages.)"""
    n = 1000
    k = np.arange(n)
    jitter = np.random.default_rng(5).integers(-1, 2, n)
    jitter[0] = 0
    stamps = 1_000 + 4 * k + jitter
    assert set(np.diff(stamps)) == {2, 3, 4, 5, 6}
    loop, ts, _, text = _drive(robot, 4, 1 + k, stamps)
    seq_s, clock_s = k * 4e-3, _elapsed_s(stamps, 1e-3)
    assert (ts <= np.minimum(seq_s, clock_s) + 1e-9).all(), (ts - np.minimum(seq_s, clock_s)).max()
    assert np.abs(ts - seq_s).max() <= 1e-3 + 1e-9 and abs(ts[-1] - seq_s[-1]) <= 1e-3 + 1e-9
    assert loop.n.clock_faults == 0 and not loop.faults, text
    per_step_min = np.r_[0.0, np.cumsum(np.minimum(np.diff(stamps), 4))] * 1e-3
    assert seq_s[-1] - per_step_min[-1] > 0.4  # (0.445 s: what the naive rule would lag, the test can tell)


# ------------------------------------------------------------------------------- (c) a clock slower than the sequence

def _slow_cases():
    k = np.arange(300)
    yield "3 ms a 4 ms message", 1 + k, 500 + 3 * k
    yield "2 ms a 4 ms message", 1 + k, 500 + 2 * k
    yield "the sequence steps two a message, the clock 4 ms", 1 + 2 * k, 500 + 4 * k
    stall = np.where(k < 100, 4 * k, np.where(k < 150, 400, 400 + 4 * (k - 150)))
    yield "a clock that stalls for 50 messages", 1 + k, 500 + stall


@pytest.mark.parametrize("case, seqs, stamps", list(_slow_cases()), ids=[c[0] for c in _slow_cases()])
def test_a_clock_slower_than_the_sequence_sets_the_reference_pace(robot, case, seqs, stamps):
    """A slow or lying clock (or a controller whose cycle is shorter than the sequence says): the reference's
    time follows the clock's elapsed (never ahead of it, within 3 ms behind), the clock's fault said; a clock that
    stalls holds the reference and the correction still ramps to zero meanwhile.  Before: the reference at the
    sequence's pace, 0.3 to 1.2 s ahead of the clock after 300 messages, and through the stall."""
    loop, ts, corr, text = _drive(robot, 4, seqs, stamps, push=True)
    clock_s = _elapsed_s(stamps, 1e-3)
    assert (ts <= clock_s + 1e-9).all(), (ts - clock_s).max()
    assert (ts >= clock_s - 3e-3 - 1e-9).all(), (clock_s - ts).max()
    assert loop.n.clock_faults > 0 and "the reference advances by the slower of the clock and the sequence" in text
    if "stalls" in case:
        assert ts[100] == ts[149]  # held through the stall
        assert corr[95] > 0.05 and corr[149] == 0.0  # (ramped to zero while held, not frozen)


# ------------------------------------------------------------------------------------------ (d) a clock set ahead

@pytest.mark.parametrize("jump_ms, after_ms", [(3, 4), (1000, 4), (1000, 3)])
def test_a_clock_that_jumps_ahead_gives_the_reference_no_more_than_the_sequence(robot, jump_ms, after_ms):
    """The clock jumps ``jump_ms`` ahead at message 100 (3 ms: within the tolerance, no fault; 1000: the step's
    fault), then steps ``after_ms`` a message: the reference follows the sequence, never ahead of it, and a clock
    that runs slow after its jump still sets the pace (the jump is no credit beyond the tolerance, 3 ms).
    Before: 3 ms ahead of the sequence for the rest of the run; after the jump and 3 ms steps, the sequence's
    pace (0.2 s ahead of the clock's steps after 200 messages)."""
    n = 300
    k = np.arange(n)
    stamps = np.where(k < 100, 4 * k, 400 + jump_ms + after_ms * (k - 100))
    loop, ts, _, _ = _drive(robot, 4, 1 + k, stamps)
    seq_s = k * 4e-3
    # the clock's elapsed counting the jump's step as the sequence's: what the reference may follow
    clock_s = np.where(k < 100, k * 4e-3, 0.4 + (k - 100) * after_ms * 1e-3)
    slower = np.minimum(seq_s, clock_s)
    assert (ts <= seq_s + 1e-9).all() and (ts <= slower + 3e-3 + 1e-9).all(), (ts - slower).max()
    assert (ts >= slower - 1e-3 - 1e-9).all(), (slower - ts).max()


# ---------------------------------------------------------------------------------------- what starts a run again

def test_after_a_wrap_a_jump_a_restart_or_a_clock_set_back_the_reference_is_no_faster_than_the_clock(robot):
    """A run whose clock wraps at 2**32, then segments each started by a reset, each followed by 60 messages of
    a clock at 2 ms a 4 ms message: a sequence jump of 100 (the clock 400 ms on), a controller restart (numbered
    from 1, its clock from 0), a clock set back by 500 ms.  Within each segment the reference advances at most
    the clock's elapsed since the reset plus one period (the reset's own step, none where the clock went back).
    Before: at the sequence's pace after each (0.12 s ahead of the clock in each segment)."""
    seqs, stamps, starts = [], [], []
    tm = 2**32 - 200  # (the clock wraps in the first segment)
    for k in range(100):
        seqs.append(1 + k)
        stamps.append(tm + 4 * k)
    for reset in ("jump", "restart", "set back"):
        last_seq, last_tm = seqs[-1], stamps[-1]
        if reset == "jump":
            seq0, tm0 = last_seq + 100, last_tm + 400
        elif reset == "restart":
            seq0, tm0 = 1, 0
        else:
            seq0, tm0 = last_seq + 1, last_tm - 500
        starts.append(len(seqs))
        for k in range(60):
            seqs.append(seq0 + k)
            stamps.append(tm0 + 2 * k)
    loop, ts, _, text = _drive(robot, 4, seqs, [s % 2**32 for s in stamps])
    first = np.array(ts[:100])
    assert np.abs(first - np.arange(100) * 4e-3).max() <= 1e-9  # (an honest clock across its wrap)
    for s in starts:
        before = ts[s - 1]
        clock_s = np.arange(60) * 2e-3
        played = ts[s:s + 60] - before
        own = played[0]
        assert own <= 4e-3 + 1e-9
        assert (played <= own + clock_s + 1e-9).all(), (played - own - clock_s).max()
    assert loop.n.jumps == 2 and loop.n.clock_faults > 0, text


# --------------------------------------------------------------------------------------- (e) RSI: nothing changes

@pytest.mark.parametrize("period_ms, first, step_ms", [(4, 1_000_003, 4), (12, 1_000_003, 12), (4, 1_000_000, 12),
                                                       (4, 1_000_002, 4), (12, 1_000_002, 12)])
def test_rsis_reference_is_its_ipocs_time_as_before(period_ms, first, step_ms):
    """RSI's sequence is its IPOC over --period-ms (cell/rsi.py), so its clock and its sequence are one: the
    reference's time is the IPOC's elapsed exactly, as before, an odd start, a 12 ms IPO read at --period-ms 4
    and an IPOC half a cycle off the grid among them; and after a restart (a new IPOC epoch after 200 ms
    silent) it goes on by one period, as before."""
    from robstiff_drake.cell.rsi import RsiLink
    from robstiff_drake.cell.rsi_codec import encode_rob

    link, c, q = RsiLink(0, ("127.0.0.1", None), period_ms * 1e-3), SessionClock(period_ms * 1e-3), [0.0] * 6
    n = 500
    ipocs = list(first + step_ms * np.arange(n)) + list(50_000_001 + step_ms * np.arange(n))
    arrivals = list(np.arange(n) * step_ms * 1e-3) + list(n * step_ms * 1e-3 + 0.2 + np.arange(n) * step_ms * 1e-3)
    ts, t, verdicts = [], 0.0, []
    try:
        for ip, a in zip(ipocs, arrivals):
            link.arrival_s = float(a)
            m = link.decode(encode_rob(int(ip), q, q))
            v, dt = c.accept(m.seq, m.tm_ms)
            verdicts.append(v)
            t += dt
            ts.append(t)
    finally:
        link.close()
    ts = np.array(ts)
    assert verdicts.count("jump") == 1 and verdicts.count("clock") == 0
    assert np.array_equal(ts[:n], np.arange(n) * step_ms * 1e-3) or \
        np.abs(ts[:n] - np.arange(n) * step_ms * 1e-3).max() <= 1e-9
    assert abs(ts[n] - ts[n - 1] - period_ms * 1e-3) <= 1e-12  # (the restart's one period, as before)
    assert np.abs(ts[n:] - ts[n] - np.arange(n) * step_ms * 1e-3).max() <= 1e-9
