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

import json
import os
import struct
import subprocess
import sys
import time

import pytest

pytest.importorskip("pynetft", reason="the cell tests need pynetft (pip install '.[test]')")
pytest.importorskip("abb_robot_client", reason="the cell tests need abb-robot-client (pip install '.[test]')")

sys.path.insert(0, os.path.dirname(__file__))
import cell_helpers as h  # noqa: E402
from port_attacks import _report, _summary, robot  # noqa: E402,F401 (robot: the fixture)
from sensor_attacks import (PACE_S, PROCESS_W, TIMEOUT_MESSAGES, Run, ScriptedSensor, air_until_taken,  # noqa: E402,F401
                            finish, inputs, start)

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
    r = Run(robot, ref_deg, ctrl, sensor)
    try:
        steady = r.engage(sensor)
        r.run(ATTACK, pace_s=PACE_S)
        silent_zero = r.zero_tail(TIMEOUT_MESSAGES)
        # (until compensating again, each record sent once the stream is there: a silence this machine's load
        # stretched past pynetft's 1 s receive timeout restarts the stream, and records sent during its back-off
        # reach no one; before, 150 records sent at once could all fall there: sensor_attacks.streaming)
        back = r.recover(sensor, steady)
    finally:
        code, err, extra = finish(proc, ctrl, sensor)
    assert code == 0 and extra == [], err[-2000:]
    assert "sensor: no record for 200 ms" + RAMPS in err, err[-3000:]
    assert silent_zero and "sensor: valid records again" in err, err[-3000:]
    assert back is not None and r.dev[r.k - 1] > 0.5 * steady  # (compensating again)
    with open(os.path.join(log, "summary.json")) as f:
        summary = json.load(f)
    checks = summary["cycles"]["sensor_checks"]  # (the honest start and rate pass: the silence cut out of the rate's windows)
    assert checks["start"]["passed"] and checks["start"]["apart_N"] < 1.0, checks
    # (the tool points down, the payload's centre of mass on the sensor's axis: its torque scale not checked, said
    # as a note of the run's course, not a warning: a common pose, nothing implausible read)
    assert "cannot check the sensor's torque scale" in checks["start"]["unchecked"], checks
    assert "sensor: the start pose cannot check the sensor's torque scale" in err, err[-3000:]
    assert not [ln for ln in summary["warnings"] if "torque scale" in ln], summary["warnings"]
    assert checks["rate"]["fault"] is None and checks["rate"]["windows_judged"] >= 2, checks
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
    r = Run(robot, ref_deg, ctrl, sensor)
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


@pytest.mark.parametrize("before", ["invalid", "stale"])
def test_no_usable_record_at_the_first_message(robot, inputs, before):
    """At the controller's first message the sensor has sent nothing usable:
    only records whose status flags them (the chain would start on zeros:
    the payload's weight read as a process force), or valid records of
    another reading (400 N more: read at another pose) older than the
    timeout (1 s before, a lower bound: the records are stamped when this
    process's reader takes them, which a loaded machine delays; with 0.3 s
    this case failed once at load 5).  Without --log, compensating from
    the first message.  40 messages (fewer than the timeout's 50) with the
    same invalid records or none: zero correction, the reason logged from
    the first message (before: corrections of up to 0.0340 deg from the
    zeros and 0.0873 deg from the old reading were sent); then valid records
    of the tool in the air (the chain's first level, checked against the
    payload calibration: it passes), then of the true reading: compensating
    on it."""
    *_, ref_deg, w, log = inputs
    sensor = ScriptedSensor(w if before == "invalid" else w + [0.0, 0.0, 400.0, 0.0, 0.0, 0.0])
    if before == "invalid":
        sensor.auto_status = 0x20000000
    proc, ctrl = start(inputs, sensor, log=False)
    sensor.wrench = w  # (the true reading, once the sensor sends valid records)
    r = Run(robot, ref_deg, ctrl)
    try:
        if before == "stale":
            time.sleep(1.0)
        r.run(40, lambda k: sensor.send(status=0x20000000) if before == "invalid" else None)
        first = max(r.dev.values())
        # the tool in the air: the chain's first level, checked against the payload calibration there
        air_until_taken(r, sensor, w - PROCESS_W)
        back = r.recover(sensor, 0.0532)
    finally:
        code, err, extra = finish(proc, ctrl, sensor)
    assert code == 0 and extra == [], err[-2000:]
    assert "sensor: no valid record within 200 ms of the controller's first message" in err, err[-3000:]
    assert first <= 1e-6, first
    assert "where the payload calibration predicts" not in err, err[-3000:]  # (its check passed on the first level)
    _report(f"start with {before} records", first_40_worst_deg=round(first, 4), messages_to_compensate=back,
            worst_deg=round(r.chk.worst_deg, 4), worst_step_deg=round(r.worst_step_deg, 4))


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
    refused and counted, a logged fault, zero correction; or (one count
    inside: 2147 N) a jump the guard refuses for the timeout, then re-armed
    on the new level, whose correction is beyond the tool bound (6.4 mm):
    a logged fault, zero correction."""
    *_, ref_deg, w, log = inputs
    sensor = ScriptedSensor(w)
    proc, ctrl = start(inputs, sensor)
    r = Run(robot, ref_deg, ctrl, sensor)
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
    assert zero, err[-3000:]
    if counts[0] == INT32_MAX - 1:  # (2147 N: the guard re-armed on it, then the correction's bound)
        assert "the guard rejected every sample for 200 ms" in err and "correction bound: the model's" in err
    else:
        assert s["sensor_clipped"] >= ATTACK - TIMEOUT_MESSAGES and "int32" in err
        assert "sensor: invalid records (status flags, NaN or clipped), then none for 200 ms" + RAMPS in err, \
            err[-3000:]
    _report(f"int32 counts {counts}", **r.figures(s, steady_deg=round(steady, 4), zero_at_end=zero))


@pytest.mark.parametrize("page", [(1e9, 1e9), (1e3, 1e3), (1e6, 1e3)], ids=["1000x_fewer_N", "1000x_more_N", "torque"])
def test_a_calibration_page_that_lies_about_the_scale(robot, inputs, page):
    """The sensor's page advertises counts per unit 1000 times off what its
    records are encoded with (1e6), a calibration usable on its face
    (rdt.calibration_problem): every reading 1000 times too small or too
    large.  At the controller's first message (the tool in the air) the
    reading is checked against what the payload calibration predicts at the
    start pose (cell/sensor_checks.py): a sensor fault from the first
    message for the session, one line naming what disagrees and by how
    much, zero correction throughout, summary.json's sensor_checks.start
    failed.  (Before: forces too small or moments too large were not
    detected: a correction of 0.034 deg from minus the payload's weight, up
    to 0.048 deg with the moments 1000 times large, where the true one is
    0.053; too large was caught by the correction's tool bound.)"""
    *_, ref_deg, w, log = inputs
    sensor = ScriptedSensor(w, page_counts=page)
    proc, ctrl = start(inputs, sensor)
    r = Run(robot, ref_deg, ctrl, sensor)
    try:
        r.run(300, lambda k: sensor.send())
    finally:
        code, err, extra = finish(proc, ctrl, sensor)
    assert code == 0 and extra == [], err[-2000:]
    s = _summary(log)
    lines = [ln for ln in err.splitlines() if "where the payload calibration predicts" in ln]
    assert len(lines) == 1 and "calibration page, tare, payload mass or mounting wrong" in lines[0], err[-3000:]
    unit = "N*m" if page == (1e6, 1e3) else "N"  # (the moments alone 1000 times off: named in N*m)
    assert f"the sensor reads " in lines[0] and f" {unit} where " in lines[0], lines[0]
    assert r.chk.worst_deg <= 1e-6, r.chk.worst_deg
    assert s["sensor_checks"]["start"]["passed"] is False and s["health"]["seen_of_the_other_side"]["sensor_faults"] >= 1
    _report(f"page counts {page}", line=lines[0].split(": sensor: ")[-1][:120],
            **r.figures(s, end_deg=round(r.dev[r.k - 1], 4)))


@pytest.mark.parametrize("counts", [1e6, 1e5], ids=["clipped", "carried"])
def test_a_step_of_5000_N(robot, inputs, counts):
    """The force steps by 5000 N on x and stays, 150 messages.  At 1e6
    counts per N the int32 counts cannot carry it (2147 N): clipped records,
    refused, a logged fault, zero correction.  At 1e5 (21,474 N carried):
    the guard refuses the jump for the timeout, then re-arms on the new
    level (a step that stays, as documented), and the model's correction for
    5000 N is beyond the tool bound (5 mm): a logged fault, zero correction;
    no target beyond the checks either way."""
    *_, ref_deg, w, log = inputs
    sensor = ScriptedSensor(w, counts=(counts, counts))
    proc, ctrl = start(inputs, sensor)
    r = Run(robot, ref_deg, ctrl, sensor)
    step = w + [5000.0, 0.0, 0.0, 0.0, 0.0, 0.0]
    try:
        steady = r.engage(sensor)
        r.run(ATTACK, lambda k: sensor.send(step), pace_s=PACE_S)
        zero = r.zero_tail(TIMEOUT_MESSAGES)
    finally:
        code, err, extra = finish(proc, ctrl, sensor)
    assert code == 0 and extra == [], err[-2000:]
    assert zero, err[-3000:]
    if counts == 1e6:
        assert "int32" in err and "sensor: invalid records (status flags, NaN or clipped)" in err
    else:
        assert "the guard rejected every sample for 200 ms" in err and "correction bound: the model's" in err
    _report(f"5000 N step at {counts:g} counts/N", **r.figures(_summary(log), steady_deg=round(steady, 4)))


@pytest.mark.parametrize("page", [(0.0, 1e6), (1e6, -1.0), (1e-3, 1e6)])
def test_a_calibration_page_that_cannot_be_is_one_line(robot, inputs, page):
    """The sensor's own page advertises counts per unit of zero, negative, or
    so few that one count is 1000 N: refused before the loop, one line, exit
    2, nothing sent."""
    model, payload, ref, ref_deg, w, log = inputs
    sensor = ScriptedSensor(w, page_counts=page)
    cmd = h.compensate_cmd(model, payload, ref, egm_port=h.free_udp_port(), netft_port=sensor.port, log=log)
    cmd[cmd.index("--netft-http-port") + 1] = str(sensor.http_port)
    try:
        cp = subprocess.run(cmd, capture_output=True, text=True, cwd=h.ROOT, timeout=h.HANG_GUARD_S)
    finally:
        sensor.close()
    lines = [ln for ln in cp.stderr.splitlines() if "error:" in ln]
    assert cp.returncode == 2 and len(lines) == 1 and "--netft" in lines[0], cp.stderr[-2000:]
    assert "Traceback" not in cp.stderr and not os.path.exists(os.path.join(log, "summary.json"))
    _report(f"page counts {page}", exit=cp.returncode, line=lines[0][:160])
