"""The wrist sensor's side of `robstiff compensate` attacked through the real
process, its values: a Net F/T on 127.0.0.1 whose every record the test
sends (tests/sensor_attacks.ScriptedSensor), in lockstep with a scripted EGM
controller streaming a reference (one record, then one message and its
answer), the held process force asking a correction of 0.053 deg (its
largest joint).  The wire's timing and numbering: tests/
test_sensor_attacks_stream.py.

Every target the controller receives is finite, inside the working ranges,
within the correction's clamp of the reference, and the correction never
moves more than the rate limit allows between two answers (sensor_attacks.
Run).  Where the sensor cannot be trusted the correction must end at zero
with a logged reason.  Silences are longer than the sensor timeout (200 ms
here) on both clocks: in messages (the controller's) and in a lower bound
of this PC's (each message at least PACE_S after the last); no test needs a
deadline met."""

import os
import struct
import sys

import numpy as np
import pytest

pytest.importorskip("pynetft", reason="the cell tests need pynetft (pip install '.[test]')")
pytest.importorskip("abb_robot_client", reason="the cell tests need abb-robot-client (pip install '.[test]')")

sys.path.insert(0, os.path.dirname(__file__))
import cell_helpers as h  # noqa: E402
from port_attacks import _report, _summary, robot  # noqa: E402,F401 (robot: the fixture)
from sensor_attacks import PACE_S, TIMEOUT_MESSAGES, Run, ScriptedSensor, finish, inputs, start  # noqa: E402,F401

from robstiff_drake.cell.rdt import INT32_MAX  # noqa: E402

ATTACK = 3 * TIMEOUT_MESSAGES  # messages of an attack that must end in zero correction: its onset and the ramp
RAMPS = "; the correction ramps to zero"


def _zeroed(r, err, words):
    assert words in err, err[-3000:]
    assert r.zero_tail(TIMEOUT_MESSAGES), [round(r.dev[k], 6) for k in range(r.k - TIMEOUT_MESSAGES, r.k)]


def test_silence_ramps_to_zero_and_the_sensors_return_restarts(robot, inputs):
    """The sensor stops for 150 messages (0.6 s, 3x the timeout on both
    clocks) while the controller goes on: a logged fault, the correction at
    zero; then it speaks again: compensating again."""
    *_, ref_deg, w, log = inputs
    sensor = ScriptedSensor(w)
    proc, ctrl = start(inputs, sensor)
    r = Run(robot, ref_deg, ctrl)
    try:
        steady = r.engage(sensor)
        r.run(ATTACK, pace_s=PACE_S)
        silent_zero = r.zero_tail(TIMEOUT_MESSAGES)
        r.run(150, lambda k: sensor.send())
    finally:
        code, err, extra = finish(proc, ctrl, sensor)
    assert code == 0 and extra == [], err[-2000:]
    assert "sensor: no record for 200 ms" + RAMPS in err, err[-3000:]
    assert silent_zero and "sensor: valid records again" in err
    assert r.dev[r.k - 1] > 0.5 * steady  # (compensating again)
    _report("sensor silent 150 messages", **r.figures(_summary(log), steady_deg=round(steady, 4)))


@pytest.mark.parametrize("status", [0x20000000, 0x80000000, 0x80020000, 0x00000001])
def test_a_status_word_that_flags_a_fault_is_never_used(robot, inputs, status):
    """Records whose status word is neither 0 nor ATI's monitor warning
    (0x80010000) for 150 messages: invalid (NaN), a logged fault, the
    correction at zero; pynetft restarts the stream meanwhile (its own
    recovery of a serious status); valid records again: compensating."""
    *_, ref_deg, w, log = inputs
    sensor = ScriptedSensor(w)
    proc, ctrl = start(inputs, sensor)
    r = Run(robot, ref_deg, ctrl)
    bad = w + [800.0, 0.0, 0.0, 0.0, 0.0, 0.0]  # (what the flagged records carry: it must not be used)
    try:
        steady = r.engage(sensor)
        r.run(ATTACK, lambda k: sensor.send(bad, status=status), pace_s=PACE_S)
        zero = r.zero_tail(TIMEOUT_MESSAGES)
        back = r.recover(sensor, steady)
    finally:
        code, err, extra = finish(proc, ctrl, sensor)
    assert code == 0 and extra == [], err[-2000:]
    assert "sensor: invalid records (status flags, NaN or clipped), then none for 200 ms" + RAMPS in err, err[-3000:]
    assert zero
    _report(f"status {status:#010x} 150 messages", **r.figures(_summary(log), steady_deg=round(steady, 4),
                                                               messages_to_compensate_again=back))


def _raw(sensor, counts):
    """A record of raw int32 ``counts`` (6) with the sensor's next sequence numbers."""
    srv = sensor.server
    srv.rdt_sequence += 1
    srv.ft_sequence += 1
    return struct.pack("!3I6i", srv.rdt_sequence, srv.ft_sequence, 0, *counts)


@pytest.mark.parametrize("counts", [[INT32_MAX, 0, 0, 0, 0, 0], [0, 0, -INT32_MAX - 1, 0, 0, 0],
                                    [0, 0, 0, 0, INT32_MAX, 0], [INT32_MAX - 1, -INT32_MAX + 1, 0, 0, 0, 0]],
                         ids=["fx_max", "fz_min", "ty_max", "just_inside"])
def test_int32_extremes_are_refused(robot, inputs, counts):
    """The wire's largest values (int32 counts at their ends: the wire
    carries no NaN or inf) from the sensor for 150 messages: clipped records
    refused and counted, or (one count inside: 2147 N) a jump the guard
    refuses; a logged fault; the correction ends at zero or within the
    checks (re-armed on the new level: below)."""
    *_, ref_deg, w, log = inputs
    sensor = ScriptedSensor(w)
    proc, ctrl = start(inputs, sensor)
    r = Run(robot, ref_deg, ctrl)
    base = [int(round(v * 1e6)) for v in w]
    raw = [c if c else b for c, b in zip(counts, base)]
    try:
        steady = r.engage(sensor)
        r.run(ATTACK, lambda k: sensor.send_raw(_raw(sensor, raw)), pace_s=PACE_S)
        zero = r.zero_tail(TIMEOUT_MESSAGES)
    finally:
        code, err, extra = finish(proc, ctrl, sensor)
    assert code == 0 and extra == [], err[-2000:]
    s = _summary(log)
    if counts[0] == INT32_MAX - 1:  # (2147 N: the guard re-armed on it, then the correction's bound)
        assert "the guard rejected every sample for 200 ms" in err and RAMPS in err, err[-3000:]
    else:
        assert s["sensor_clipped"] >= ATTACK - TIMEOUT_MESSAGES and "int32" in err
        assert "sensor: invalid records (status flags, NaN or clipped), then none for 200 ms" + RAMPS in err, err[-3000:]
        assert zero
    _report(f"int32 counts {counts}", **r.figures(s, steady_deg=round(steady, 4), zero_at_end=zero))
