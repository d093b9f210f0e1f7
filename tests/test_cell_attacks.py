"""`robstiff compensate` attacked as a stranger on the network would and
as a faulty network would (issue 18's measured failures), against a
scripted controller on 127.0.0.1 that sends each message exactly as the
test says and waits for its answer (no timing assumption on a loaded
machine).  Every target the controller receives is checked against the
robot's working ranges and against where the arm is and should be;
strangers must get no answer at all."""

import json
import os
import subprocess
import sys

import numpy as np
import pytest

pytest.importorskip("pynetft", reason="the cell tests need pynetft (pip install '.[test]')")
pytest.importorskip("abb_robot_client", reason="the cell tests need abb-robot-client (pip install '.[test]')")

sys.path.insert(0, os.path.dirname(__file__))
import cell_helpers as h  # noqa: E402

from robstiff_drake.model.robot import load_robot  # noqa: E402

T_MS = 4.0
SATURATION_DEG = 0.5  # compensate's default clamp


@pytest.fixture(scope="module")
def robot():
    return load_robot()


@pytest.fixture()
def cell(tmp_path, robot):
    """(model, payload, reference path, reference function rad, sensor)."""
    model, payload, ref, ref_fn = h.write_inputs(str(tmp_path), robot, duration_s=3.0)
    sensor = h.FakeSensor(h.hold_wrench(robot, ref_fn(0.0)))
    yield model, payload, ref, ref_fn, sensor
    sensor.close()


def _finish(proc, ctrl, end=True):
    """End the run (``end``: the script is over; False: wait for its own
    exit), then (exit status, stderr, the answers left queued for ``ctrl``:
    after the exit, all it ever sent there)."""
    try:
        code, err = h.finish(proc, end=end)
        return code, err, ctrl.answers()
    finally:
        ctrl.close()


def _summary(log):
    return json.loads(open(os.path.join(log, "summary.json")).read())


def _within_limits(robot, targets):
    lo, hi = np.degrees(robot.q_lower_rad), np.degrees(robot.q_upper_rad)
    t = np.asarray(targets, dtype=float)
    return bool(np.all(np.isfinite(t)) and np.all(t >= lo - 1e-6) and np.all(t <= hi + 1e-6))


def test_a_stranger_is_never_heard_nor_answered(tmp_path, robot, cell):
    """A stranger on another address sends every cycle, first while the
    compensator waits (its pose 30 deg away would have become the hold
    pose) and then between the controller's messages, with a flood of
    2-byte datagrams (before: 26 % of the controller's messages answered):
    no answer ever reaches it, its pose is never streamed, it is counted,
    and every one of the controller's messages is answered."""
    model, payload, _, ref_fn, sensor = cell
    q0 = np.degrees(ref_fn(0.0))
    far = q0 + [30.0, 10.0, 10.0, 45.0, 20.0, 90.0]
    port = h.free_udp_port()
    log = str(tmp_path / "log")
    proc = h.start_compensate(model, payload, sensor, port, log=log, extra=["--controller", "127.0.0.1"])
    stranger = h.ScriptedController(port, host="127.0.0.2")
    ctrl = h.ScriptedController(port)
    try:
        for k in range(1, 60):  # the stranger first, while the compensator waits for its controller
            stranger.send(k, k * T_MS, far)
            if k % 10 == 0:
                import time

                time.sleep(0.05)
        targets = []
        for k in range(1, 300):
            stranger.send(1000 + k, k * T_MS, far)
            for _ in range(20):  # and a flood of 2-byte datagrams
                stranger.sock.sendto(b"\x00\x01", stranger.addr)
            got = ctrl.exchange(k, k * T_MS, q0)
            assert got is not None, "the controller got no answer"
            targets.append(got)
    finally:
        code, err, _ = _finish(proc, ctrl)
        heard = stranger.answers()  # (the run has ended: everything it ever sent the stranger is queued)
        stranger.close()
    assert code == 0, err
    assert heard == []
    t = np.array(targets)
    assert _within_limits(robot, t)
    # streamed: the controller's own pose (plus at most the correction's clamp), never the stranger's
    assert np.abs(t - q0).max() <= SATURATION_DEG + 1e-6
    s = _summary(log)["cycles"]
    assert s["strangers_dropped"] >= 300 * 21
    assert s["answered"] == 299  # every one of the controller's messages, flood or not


def test_a_spoofed_clock_moves_the_reference_one_period_at_most(tmp_path, robot, cell):
    """One message with the controller's next sequence number and a clock
    400 ms ahead: a fault, and the streamed reference advances one period
    (before: 0.4 s of path in one answer)."""
    model, payload, ref, ref_fn, sensor = cell
    port = h.free_udp_port()
    log = str(tmp_path / "log")
    proc = h.start_compensate(model, payload, sensor, port, reference=ref, log=log)
    ctrl = h.ScriptedController(port)
    answers = []
    try:
        for k in range(0, 400):
            tm = k * T_MS + (400.0 if k == 250 else 0.0)
            # the arm stands where the path says (its feedback: the reference at this cycle)
            got = ctrl.exchange(k + 1, tm, np.degrees(ref_fn(k * T_MS / 1e3)))
            assert got is not None
            answers.append(got)
    finally:
        code, err, extra = _finish(proc, ctrl)
    assert code == 0, err
    assert extra == []  # one answer per message
    assert "clock disagrees with its sequence" in err
    a = np.array(answers)
    ref_deg = np.array([np.degrees(ref_fn(k * T_MS / 1e3)) for k in range(400)])
    # every answer is the reference at its own cycle plus at most the clamp (the spoofed
    # message did not advance it by 0.4 s: on this path that is 8 mm, about 0.3 deg on q2)
    assert np.abs(a - ref_deg).max() <= SATURATION_DEG + 1e-6
    jump = np.degrees(ref_fn(0.4 + 250 * T_MS / 1e3)) - np.degrees(ref_fn(250 * T_MS / 1e3))
    assert np.abs(jump).max() > 0.05  # a spoof of 0.4 s would show
    assert np.abs(a[250] - ref_deg[250]).max() < 0.2 * np.abs(jump).max()
    assert _summary(log)["cycles"]["clock_faults"] >= 1


def test_duplicated_and_reordered_datagrams_do_not_speed_up_the_reference(tmp_path, robot, cell):
    """A network that repeats every datagram and swaps some pairs: each
    duplicate and each older datagram is dropped unanswered, and the
    reference runs at the controller's pace (before: twice its speed)."""
    model, payload, ref, ref_fn, sensor = cell
    port = h.free_udp_port()
    log = str(tmp_path / "log")
    proc = h.start_compensate(model, payload, sensor, port, reference=ref, log=log)
    ctrl = h.ScriptedController(port)
    n = 300
    answers = []
    try:
        k = 1
        while k <= n:
            if k % 20 == 0 and k < n:  # k+1 arrives before k (reordered), both duplicated
                for seq in (k + 1, k, k + 1, k):
                    ctrl.send(seq, (seq - 1) * T_MS, np.degrees(ref_fn((seq - 1) * T_MS / 1e3)))
                answers += ctrl.answers(timeout_s=h.HANG_GUARD_S)  # (k + 1's; any other is counted at the end)
                k += 2
                continue
            for _ in range(2):  # every datagram twice
                ctrl.send(k, (k - 1) * T_MS, np.degrees(ref_fn((k - 1) * T_MS / 1e3)))
            answers += ctrl.answers(timeout_s=h.HANG_GUARD_S)
            k += 1
    finally:
        code, err, extra = _finish(proc, ctrl)
    answers += extra  # (after the run's end: every answer it sent, however late)
    assert code == 0, err
    s = _summary(log)["cycles"]
    assert s["duplicates_dropped"] + s["old_dropped"] >= n - 5
    assert len(answers) <= n  # one answer per message at most, none to a duplicate
    last = np.array(answers[-1])
    # the last answer is the reference at the last message's time, not at twice it
    assert np.abs(last - np.degrees(ref_fn((n - 1) * T_MS / 1e3))).max() <= SATURATION_DEG + 1e-6
    twice = np.degrees(ref_fn(2 * (n - 1) * T_MS / 1e3)) - np.degrees(ref_fn((n - 1) * T_MS / 1e3))
    assert np.abs(twice).max() > 0.05


def test_absurd_feedback_is_refused_and_never_echoed(tmp_path, robot, cell):
    """Joint feedback of 1e300 deg mid-run: a fault, and no target beyond the
    limits or near the absurd value is sent; a first message with q6 = 1e6
    deg: one line, exit 2, nothing sent."""
    model, payload, _, ref_fn, sensor = cell
    q0 = np.degrees(ref_fn(0.0))
    port = h.free_udp_port()
    log = str(tmp_path / "log")
    proc = h.start_compensate(model, payload, sensor, port, log=log)
    ctrl = h.ScriptedController(port)
    targets = []
    try:
        for k in range(1, 200):
            q = q0.copy()
            if 100 <= k < 150:
                q[1] = 1e300
            got = ctrl.exchange(k, k * T_MS, q)
            if got is not None:
                targets.append(got)
    finally:
        code, err, extra = _finish(proc, ctrl)
    targets += extra
    assert code == 0, err
    assert "q2 = 1e+300 deg is outside" in err
    t = np.array(targets)
    assert _within_limits(robot, t)
    assert np.abs(t - q0).max() <= SATURATION_DEG + 1e-6

    port = h.free_udp_port()
    proc = h.start_compensate(model, payload, sensor, port)
    ctrl = h.ScriptedController(port)
    bad = q0.copy()
    bad[5] = 1e6
    ctrl.send(1, 0.0, bad)
    code, err, got = _finish(proc, ctrl, end=False)  # (it ends by itself; then all it sent is queued)
    assert got == []
    assert code == 2
    lines = [ln for ln in err.splitlines() if "error:" in ln]
    assert len(lines) == 1 and "q6 = 1e+06 deg is outside" in lines[0] and "Traceback" not in err, err


@pytest.mark.untimed
@pytest.mark.parametrize("edit, words", [
    (lambda rows: rows.__setitem__(5, [rows[5][0]] + [rows[5][1] + 90.0] + rows[5][2:]), ("moves at", "axis speed")),
    (lambda rows: rows.__setitem__(5, [rows[4][0] + 5e-324] + rows[5][1:]), ("controller period",)),
    (lambda rows: rows.__setitem__(5, [rows[5][0], rows[5][1], 1000.0] + rows[5][3:]), ("outside", "working range")),
    (lambda rows: [r.__setitem__(0, i * 0.002) for i, r in enumerate(rows)], ("controller period",)),
], ids=["90-deg-step", "5e-324-s-apart", "beyond-limit", "2-ms-rows"])
def test_a_reference_that_asks_the_impossible_is_refused(tmp_path, robot, edit, words):
    model, payload, ref, _ = h.write_inputs(str(tmp_path), robot, duration_s=0.2)
    lines = open(ref).read().splitlines()
    head = [ln for ln in lines if ln.startswith("#")] + [lines[[i for i, ln in enumerate(lines)
                                                               if not ln.startswith("#")][0]]]
    rows = [[float(v) for v in ln.split(",")] for ln in lines[len(head):]]
    edit(rows)
    with open(ref, "w") as f:
        f.write("\n".join(head) + "\n" + "\n".join(",".join(repr(v) for v in r) for r in rows) + "\n")
    cp = subprocess.run([sys.executable, "-m", "robstiff_drake", "compensate", "--egm-port", str(h.free_udp_port()),
                         "--netft", "127.0.0.1:1", "--model", model, "--payload", payload, "--reference", ref],
                        cwd=h.ROOT, capture_output=True, text=True, timeout=60)
    assert cp.returncode == 2, cp.stderr
    err = [ln for ln in cp.stderr.splitlines() if "error:" in ln]
    assert len(err) == 1 and "Traceback" not in cp.stderr, cp.stderr
    assert ref in err[0] and all(w in err[0] for w in words), err[0]


@pytest.mark.untimed
@pytest.mark.parametrize("args, words", [
    (["--netft-counts", "1e-300,1e-300", "--netft-units", "N,N-m"], ("--netft-counts", "not a Net F/T")),
    (["--netft-counts", "1e6,1e6"], ("--netft-units",)),
    (["--netft-counts", "1e6,1e6", "--netft-units", "N,furlongs"], ("torque unit",)),
], ids=["tiny-counts", "no-units", "bad-unit"])
def test_a_calibration_override_that_cannot_be_is_one_line(tmp_path, robot, args, words):
    model, payload, _, _ = h.write_inputs(str(tmp_path), robot, duration_s=0.1)
    cp = subprocess.run([sys.executable, "-m", "robstiff_drake", "compensate", "--egm-port", str(h.free_udp_port()),
                         "--netft", "127.0.0.1:1", "--model", model, "--payload", payload, *args],
                        cwd=h.ROOT, capture_output=True, text=True, timeout=60)
    assert cp.returncode == 2
    err = [ln for ln in cp.stderr.splitlines() if "error:" in ln]
    assert len(err) == 1 and "Traceback" not in cp.stderr, cp.stderr
    assert all(w in err[0] for w in words), err[0]


@pytest.mark.untimed
def test_deeply_nested_model_json_is_one_line(tmp_path, robot):
    _, payload, _, _ = h.write_inputs(str(tmp_path), robot, duration_s=0.1)
    model = tmp_path / "deep.json"
    model.write_text("[" * 100000 + "]" * 100000)
    cp = subprocess.run([sys.executable, "-m", "robstiff_drake", "compensate", "--egm-port", str(h.free_udp_port()),
                         "--netft", "127.0.0.1:1", "--model", str(model), "--payload", payload],
                        cwd=h.ROOT, capture_output=True, text=True, timeout=60)
    assert cp.returncode == 2
    assert "Traceback" not in cp.stderr and "RecursionError" not in cp.stderr, cp.stderr
    err = [ln for ln in cp.stderr.splitlines() if "error:" in ln]
    assert len(err) == 1 and "--model" in err[0], cp.stderr


def test_moment_spikes_and_clipped_records_are_refused_and_counted(tmp_path, robot):
    """2,000 N*m spikes (before: the correction moved 0.37 deg, no fault)
    and records at the end of int32's counts are refused, counted and
    logged; the correction does not move with them."""
    model, payload, _, ref_fn = h.write_inputs(str(tmp_path), robot, duration_s=0.1)
    q0 = np.degrees(ref_fn(0.0))
    rest = h.hold_wrench(robot, ref_fn(0.0))(0.0)

    def wrench(k):  # of the record's index, not of this machine's pace (the first ten good)
        w = np.array(rest, dtype=float)
        if k % 50 == 10:
            w[4] += 2000.0  # a moment spike
        elif k % 50 == 35:
            w[2] += 5000.0  # beyond what 1e6 counts per N carry in int32 (2147 N): clipped
        return w

    sensor = h.FakeSensor(wrench, by_record=True)
    port = h.free_udp_port()
    log = str(tmp_path / "log")
    proc = h.start_compensate(model, payload, sensor, port, log=log)
    ctrl = h.ScriptedController(port)
    targets = []
    try:
        import time

        k, first = 1, None
        # 399 messages at least, and on until the sensor has sent 400 records (8 spikes, 8 clipped) after the
        # first answer, however slowly this machine sends them (before: 399 messages, the spikes by the clock)
        while k < 400 or sensor.sent < first + 400:
            got = ctrl.exchange(k, k * T_MS, q0)
            assert got is not None, "the controller got no answer"
            first = sensor.sent if first is None else first
            targets.append(got)
            k += 1
            time.sleep(0.002)  # (pacing only, about real time: some records between messages)
    finally:
        code, err, _ = _finish(proc, ctrl)
        sensor.close()
    assert code == 0, err
    s = _summary(log)["cycles"]
    assert s["moment_spikes"] > 0 and s["sensor_clipped"] > 0, s
    assert "moment jumped more than" in err and "int32" in err
    assert np.abs(np.array(targets) - q0).max() < 0.01  # (the spikes did not move the correction)
