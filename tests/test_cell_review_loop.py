"""The adversarial review of `robstiff compensate` (tests/test_cell_review.py),
the loop's part: every fault path over a real EgmLink (its one send path,
decoded back from a sink socket as the controller reads it), the messages
and the sensor's records handed over by script on a clock the test sets, so
every fault's timeout is decided by the script alone (no timing)."""

import math
import os
import socket
import sys

import numpy as np
import pytest

sys.path.insert(0, os.path.dirname(__file__))
import cell_helpers as h  # noqa: E402

from robstiff_drake.cell.safety import clamp_deg  # noqa: E402

T = 0.004
Q0 = [0.0, 7.008, 29.517, 0.0, 53.476, 0.0]


# ---------------------------------------------------------------------------------------------- the loop's faults
#
# The loop over a real EgmLink (its one send path: the check of the pose the controller will command, the encoding,
# a datagram to a sink socket), its messages and the sensor's records handed over by script with their arrival
# times as data (a clock the test sets: 4 ms a message, however fast this PC runs them), so every fault's timeout
# is decided by the script alone.

RATE_DEG_PER_S = 5.0  # compensate's default rate limit (hold_compensator's)
# Where the test's clock starts (s): fixed, and the loop reads this clock for every time it takes of this PC's
# (CompensatorLoop.pc_time): a run's verdicts then follow from the script alone.  (It started at this PC's
# time.monotonic() + 100 s: the rounding of its 4 ms steps, and with it a timeout met exactly at 5 periods, moved
# with the machine's uptime, and one case passed or failed by the hour.)
ORIGIN_S = 1000.0


def scripted_clock(origin_s=ORIGIN_S):
    """[now, origin] (s): the test's clock, set by the scripted link and read by the loop (_run_scripted)."""
    return [0.0, float(origin_s)]


def answer_sink():
    """A UDP socket on 127.0.0.1 where a scripted link's answers go, read back as the controller reads them (a
    buffer for a whole run's datagrams)."""
    sink = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sink.bind(("127.0.0.1", 0))
    sink.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 22)
    return sink


class ScriptedLink:
    """A protocol's link whose receive hands over one scripted item at a time (None: the controller silent for
    that read), each ``step_s`` after the last on the test's clock, the script's end a KeyboardInterrupt; the
    answers it sent are read back from a sink as the controller reads them.  A protocol gives ``_message`` (an
    item -> the link's decoded message) and ``_answer`` (an answer datagram -> what the test keeps)."""

    def __init__(self, link, script, clock, step_s):
        self.sink = answer_sink()
        link.reply_to = self.sink.getsockname()
        self.link, self.script, self.clock, self.answers = link, list(script), clock, []

        def receive(timeout_s):
            self._collect()
            if not self.script:
                raise KeyboardInterrupt  # the script's end
            item = self.script.pop(0)
            clock[0] += step_s
            return [] if item is None else [(self._message(item), clock[0])]

        link.receive = receive

    def _collect(self):
        self.sink.setblocking(False)
        while True:
            try:
                data = self.sink.recv(65536)
            except BlockingIOError:
                return
            self.answers.append(self._answer(data))

    def close(self):
        self._collect()
        self.link.close()
        self.sink.close()


class _ScriptedEgm(ScriptedLink):
    """An EgmLink whose receive hands over one scripted message at a time, one period apart on the test's clock
    (ScriptedLink); ``commanded``: the poses it sent, deg."""

    def __init__(self, script, clock):
        from robstiff_drake.cell.egm import EgmLink

        super().__init__(EgmLink(0, ("127.0.0.1", None)), script, clock, T)
        self.commanded = self.answers

    def _message(self, msg):
        return msg

    def _answer(self, data):
        m = self.link.pb2.EgmSensor()
        m.ParseFromString(data)
        return list(m.planned.joints.joints)


class _ScriptedSensor:
    """Per read: the records the script gives for the message the loop is at (default: one record of ``w``),
    stamped on the test's clock; ``records(seq)`` -> list of wrenches (NaN: invalid), or [] (silent)."""

    def __init__(self, w, clock, records=None):
        self.w, self.clock, self.records = list(w), clock, records or (lambda seq: None)
        self.seq = 0

    def drain(self):
        got = self.records(self.seq)
        got = [self.w] if got is None else got
        return [(list(x), self.clock[0], 0, False) for x in got]


def _messages(n, q_deg, *, seq0=1, tm=None, joints=None):
    from robstiff_drake.cell.link import Message

    out = []
    for k in range(n):
        seq = seq0 + k
        out.append(Message(seq, int(round((seq - 1) * T * 1e3)) if tm is None else tm(seq),
                           list(q_deg if joints is None else joints(seq))))
    return out


def _drive(robot, script, *, push_N=(3000.0, -2000.0, 0.0), records=None):
    """Run the loop over ``script`` (messages; None: a silent read) holding Q0, the sensor reading the hold pose's
    wrench plus ``push_N`` (a correction of about 0.14 deg); returns (loop, link, the corrections answered)."""
    import io

    from robstiff_drake.cell.compensate import CompensatorLoop, LoopSettings, Reference

    w = (np.asarray(h.hold_wrench(robot, np.radians(Q0))(0.0)) + [*push_N, 0.0, 0.0, 0.0]).tolist()
    clock = scripted_clock()
    link = _ScriptedEgm(script[1:], clock)
    sensor = _ScriptedSensor(w, clock, records)
    ref = Reference(period_s=T)
    ref.hold(Q0)
    # no bound on the correction's tool motion, explicitly: the 3.6 kN push's correction moves the tool 6.3 mm,
    # beyond compensate's 5 mm (LoopSettings' default), and no start check against the payload calibration (the
    # push is held from the first message); these are the other faults' tests (the bound's: tests/
    # test_correction_bound.py; the start's: tests/test_sensor_checks.py); the sensor's rate is its script's, one
    # record a message
    loop = CompensatorLoop(h.hold_compensator(robot, w), link.link, sensor, ref, robot,
                           LoopSettings(max_jump_Nm=350.0, max_correction_mm=math.inf, max_correction_deg=math.inf,
                                        start_tolerance_N=math.inf, sensor_rate_hz=1.0 / T),
                           out=io.StringIO())
    _run_scripted(loop, link, sensor, script, clock)
    return loop, link


def _run_scripted(loop, link, sensor, script, clock):
    """Run ``loop`` over the scripted ``link`` from ``script``'s first message at the test clock's origin, the
    scripted ``sensor`` told each message's sequence number as its cycle starts (its records follow the script);
    the link closed after."""
    real_cycle = loop.cycle

    def cycle(msg, t_arr, dt, **kw):
        sensor.seq = msg.seq
        return real_cycle(msg, t_arr, dt, **kw)

    loop.cycle = cycle
    loop.pc_time = lambda: clock[0]  # (this PC's clock as the loop reads it: the test's)
    clock[0] = clock[1]
    try:
        loop.run((script[0], clock[0]))
    finally:
        link.close()


def _check_every_pose(robot, link, ref=Q0):
    """Every pose the controller was told: finite, in the working ranges, within the clamp of the (standing)
    reference; between answers the correction moved at most the rate limit over MAX_STEP_PERIODS periods."""
    from robstiff_drake.cell.compensate import MAX_STEP_PERIODS

    poses = np.array(link.commanded)
    assert len(poses) and np.all(np.isfinite(poses))
    assert np.all(poses >= np.degrees(robot.q_lower_rad)) and np.all(poses <= np.degrees(robot.q_upper_rad))
    assert np.all(np.abs(poses - ref) <= clamp_deg(robot, 0.5) + 1e-9)
    step = np.abs(np.diff(poses, axis=0)).max() if len(poses) > 1 else 0.0
    assert step <= RATE_DEG_PER_S * MAX_STEP_PERIODS * T + 1e-9, step
    return poses - ref


def _ramped_down(corr, first, last):
    """The correction's size (max over joints) never grew between messages ``first`` and ``last`` (indices into the
    answers) and is zero at the end."""
    size = np.abs(corr[first:last]).max(axis=1)
    assert np.all(np.diff(size) <= 1e-12), size
    assert size[-1] == 0.0, size[-1]


def test_the_loop_ramps_in_and_holds_the_bounds_when_all_is_well(robot):
    loop, link = _drive(robot, _messages(60, Q0))
    corr = _check_every_pose(robot, link)
    assert np.abs(corr[-1]).max() > 0.05  # (compensating: the push's deflection, ramped in)
    assert not loop.faults


@pytest.mark.parametrize("fault", ["sensor NaN", "sensor silent", "clock frozen", "clock leaping",
                                   "clock 1.5 times fast", "sequence leaping", "feedback outside the ranges"])
def test_every_lasting_fault_ramps_the_correction_to_zero_and_is_logged(robot, fault):
    """60 good messages (the correction ramped in), then the fault for 60
    messages: the correction never grows and reaches zero, one log line,
    every pose the controller was told within the bounds."""
    n_good, n_bad = 60, 60
    records = None
    tail = _messages(n_bad, Q0, seq0=n_good + 1)
    if fault == "sensor NaN":
        records = lambda seq: [[float("nan")] * 6] if seq > n_good else None  # noqa: E731
    elif fault == "sensor silent":
        records = lambda seq: [] if seq > n_good else None  # noqa: E731
    elif fault == "clock frozen":  # every message stamped with the last good one's time
        tail = _messages(n_bad, Q0, seq0=n_good + 1, tm=lambda seq: (n_good - 1) * 4)
    elif fault == "clock leaping":  # 400 ms a message
        tail = _messages(n_bad, Q0, seq0=n_good + 1, tm=lambda seq: (n_good - 1) * 4 + 400 * (seq - n_good))
    elif fault == "clock 1.5 times fast":  # 6 ms a 4 ms message: each step within the 3 ms allowed, their sum not
        tail = _messages(n_bad, Q0, seq0=n_good + 1, tm=lambda seq: (n_good - 1) * 4 + 6 * (seq - n_good))
    elif fault == "sequence leaping":  # 10 numbers a message, the clock with it
        tail = _messages(n_bad, Q0, seq0=n_good + 1)
        for k, m in enumerate(tail):
            m.seq, m.tm_ms = n_good + 10 * (k + 1), (n_good + 10 * (k + 1) - 1) * 4
    else:
        bad = list(Q0)
        bad[1] = 500.0
        tail = _messages(n_bad, Q0, seq0=n_good + 1, joints=lambda seq: bad)
    loop, link = _drive(robot, _messages(n_good, Q0) + tail, records=records)
    corr = _check_every_pose(robot, link)
    assert len(corr) >= n_good + n_bad - 1
    assert np.abs(corr[n_good - 1]).max() > 0.05, "the correction had ramped in before the fault"
    # the fault's onset is judged within 20 ms (5 messages): from there the correction only shrinks, to zero
    _ramped_down(corr, n_good + 6, n_good + n_bad - 1)
    said = loop.out.getvalue()
    assert "the correction ramps to zero" in said, said


@pytest.mark.parametrize("fault", ["clock stepped back", "sequence stepped back", "controller restarted"])
def test_a_one_off_fault_ramps_to_zero_and_compensates_again_only_after_it_cleared(robot, fault):
    """A single inconsistent message, then consistent ones on the new
    numbering: the correction ramps to zero and ramps in again only once
    CLEAR_MESSAGES consistent messages have come since the fault with the
    correction at zero; the bounds hold throughout."""
    from robstiff_drake.cell.compensate import CLEAR_MESSAGES

    n_good, n_after, s0 = 100, 90, 5001  # (a restart more than the reorder window's 64 numbers after the start)
    if fault == "clock stepped back":  # its clock from n_good on 1 s behind
        tail = _messages(n_after, Q0, seq0=s0 + n_good, tm=lambda seq: (seq - 1) * 4 - 1000)
    elif fault == "sequence stepped back":  # numbered 1000 back, its clock going on
        tail = _messages(n_after, Q0, seq0=s0 + n_good - 1000, tm=lambda seq: (seq + 999) * 4)
    else:  # both from zero again
        tail = _messages(n_after, Q0, seq0=1)
    loop, link = _drive(robot, _messages(n_good, Q0, seq0=s0) + tail)
    corr = _check_every_pose(robot, link)
    size = np.abs(corr).max(axis=1)
    assert size[n_good - 1] > 0.05
    zero = n_good + int(np.argmax(size[n_good:] == 0.0))
    assert size[zero] == 0.0 and np.all(np.diff(size[n_good - 1:zero + 1]) <= 1e-12)
    back = zero + int(np.argmax(size[zero:] > 0.0))
    assert back >= n_good + CLEAR_MESSAGES, (zero, back)  # (25 consistent messages since the fault, at zero)
    assert size[-1] > 0.05  # compensating again
    assert "the correction ramps to zero" in loop.out.getvalue()


@pytest.mark.parametrize("refused", [3, 8, 25])
def test_after_refused_targets_the_correction_ramps_down_from_the_one_the_controller_holds(robot, refused):
    """The arm's feedback 5 deg off (a corrupted message within the
    ranges) for ``refused`` messages: their targets and the last safe one
    are refused (unanswered; the controller holds its last target).  Before:
    the correction went on ramping down unsent, so when the feedback came
    back the next target was further from the held one than the
    controller's acceleration supervision allows (from 6 refused messages at
    a 0.17 deg correction), refused too, and the last safe target, with the
    old correction, was sent again for good: the arm held the correction the
    log said was ramped to zero, and compensation never resumed (100
    messages later).  Now the ramp goes on from the correction the
    controller holds: every answer moves it by at most MAX_STEP_PERIODS
    periods of the rate limit, it reaches zero, the fault clears and
    compensation ramps in again."""
    n_good, n_after = 60, 100
    off = list(Q0)
    off[1] += 5.0
    script = (_messages(n_good, Q0) + _messages(refused, Q0, seq0=n_good + 1, joints=lambda seq: off)
              + _messages(n_after, Q0, seq0=n_good + refused + 1))
    loop, link = _drive(robot, script)
    corr = _check_every_pose(robot, link)  # (every answer's step within the rate limit over two periods)
    size = np.abs(corr).max(axis=1)
    assert len(corr) == n_good + n_after  # the refused ones unanswered, every other answered
    assert size[n_good - 1] > 0.15
    zero = n_good + int(np.argmax(size[n_good:] == 0.0))
    assert size[zero] == 0.0 and np.all(np.diff(size[n_good - 1:zero + 1]) <= 1e-12), size[n_good - 1:zero + 1]
    assert size[-1] > 0.15, size[-20:]  # compensating again
    assert "target: 25 consistent messages and the correction at zero; compensating again" in loop.out.getvalue()
