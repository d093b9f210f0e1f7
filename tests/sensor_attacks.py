"""Shared by the wrist sensor's hostile tests (tests/test_sensor_attacks.py,
tests/test_sensor_attacks_stream.py): a Net F/T whose every record the test
sends (``ScriptedSensor``: RDT from 127.0.0.1 and its calibration page),
the scripted controller driven in lockstep with it (``Run``), and the checks
of every target the controller received: finite, inside the working ranges,
within the correction's clamp of the reference, and never a step of the
correction larger than the loop's rate limit allows (MAX_STEP_DEG)."""

import os
import sys
import threading
import time

import numpy as np
import pytest

sys.path.insert(0, os.path.dirname(__file__))
import cell_helpers as h  # noqa: E402
from cell_helpers import HANG_GUARD_S  # noqa: E402
from port_attacks import T, T_MS, Checker  # noqa: E402

from robstiff_drake.cell.compensate import MAX_STEP_PERIODS  # noqa: E402
from robstiff_drake.cell.rdt import CalibrationPage, RDTServer, encode_record  # noqa: E402
from robstiff_drake.cell.sensor_intake import START_RECORDS  # noqa: E402


def air_until_taken(r, sensor, air, n=START_RECORDS, most=1000):
    """Messages (at least PACE_S apart: pynetft's restart of a stream waits its back-off), each after one record of
    ``air`` (the tool in the air), until ``n`` of them have reached the client (a stream started)."""
    sent = [0]

    def one(k):
        sent[0] += bool(sensor.send(air))

    while sent[0] < n and r.k < most:
        r.step(one, pace_s=PACE_S)
    assert sent[0] >= n, "the sensor's stream never restarted"

def streaming(sensor, wrench=None):
    """One record of ``wrench`` (default: the held one) sent once a client has the stream: after a silence longer
    than pynetft's receive timeout (1 s: a loaded machine stretches the test's silence past it) pynetft stops the
    stream and starts it again after its back-off, and a record sent meanwhile reaches no one (before, the 150
    records after test_silence_ramps_to_zero_and_the_sensors_return_restarts' silence could all fall there:
    no "valid records again"; a silence of 150 messages 25 ms apart did it every time)."""
    t_end = time.monotonic() + HANG_GUARD_S
    while not sensor.send(wrench):
        assert time.monotonic() < t_end, "the sensor's stream never restarted"
        time.sleep(0.001)


# the most the correction may move between two answers: compensate's rate limit (5 deg/s) over MAX_STEP_PERIODS
# periods (cell/compensate.py), + rounding
MAX_STEP_DEG = 5.0 * MAX_STEP_PERIODS * T + 1e-6
# the deviation from the reference of a target whose correction is zero (the reference file's rows, 9 decimals,
# interpolated by compensate and by the test alike)
ZERO_DEG = 1e-6
# the sensor's timeout compensate is run with here (tests/scripted_compensate.start_compensate: 200 ms); a
# silence is made longer than that on both clocks: the controller's (messages, 4 ms each) and this PC's (each
# message at least PACE_S after the last: a lower bound, which a loaded machine only lengthens)
TIMEOUT_MESSAGES = 50
PACE_S = 0.005
ENGAGED_DEG = 0.02  # the correction the held process force asks, once ramped in (0.053 deg here), is beyond this
# the process force the fixture's wrench holds (N, N*m, sensor frame): the sensor reads without it at the start
# (the tool in the air: what compensate checks against the payload calibration, cell/sensor_checks.py)
PROCESS_W = np.array([500.0, -400.0, 300.0, 0.0, 0.0, 0.0])
# the scripted sensor's rate on the controller's clock: one record a message (4 ms), compensate's --sensor-rate-hz
# here (its records are counted against it: cell/sensor_checks.py)
RATE_HZ = 1.0 / T
# the force filter (compensate's 2 Hz low-pass at RATE_HZ) settled within 0.1 % of the process force's step at the
# first message (the tool entering the part) this many messages after it (its step response: 204)
SETTLED_MESSAGES = 210


class ScriptedSensor:
    """A Net F/T on 127.0.0.1 that streams ``wrench`` (N, N*m, sensor frame)
    at about 1 kHz from a thread until ``manual()``; from then on it sends
    only what the test gives ``send`` / ``send_raw`` (its thread still
    answers the client's start and stop requests).  ``page_counts``: the
    calibration its page advertises (counts per N and per N*m), when not the
    ``counts`` its records are encoded with."""

    def __init__(self, wrench, counts=(1e6, 1e6), page_counts=None):
        self.server = RDTServer(0, http_port=0 if page_counts is None else None, counts_per_force=counts[0],
                                counts_per_torque=counts[1])
        self.page = None
        if page_counts is not None:
            self.page = CalibrationPage(0, page_counts, ("N", "N-m"))
        self.port = self.server.port
        self.http_port = self.server.http_port if self.page is None else self.page.port
        self.counts = counts
        self.wrench = np.asarray(wrench, dtype=float)
        self.sent = 0  # records sent to the client (auto and scripted)
        self.lock = threading.Lock()
        self.auto = True
        self.auto_status = 0  # (the status word of the records streamed until manual())
        self.auto_wrench = None  # (what they carry, when not ``wrench``: start() streams the tool in the air)
        self._stop = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self):
        while not self._stop.is_set():
            with self.lock:
                self.server.poll()
                auto = self.wrench if self.auto_wrench is None else self.auto_wrench
                if self.auto and self.server.send(list(auto), status=self.auto_status):
                    self.sent += 1
            time.sleep(0.001)

    def manual(self):
        with self.lock:
            self.auto = False

    @property
    def client(self):
        return self.server.client

    def send(self, wrench=None, status=0):
        """One record (the sensor's own sequence numbers) of ``wrench`` (default: the held one), when a client
        has started the stream (pynetft stops it to recover from a serious status, then starts it again)."""
        with self.lock:
            ok = self.server.send(list(self.wrench if wrench is None else wrench), status=status)
            self.sent += ok
        return ok

    def record(self, wrench, rdt_sequence, ft_sequence=None, status=0):
        """The bytes of a record with the sequence numbers given (a replay, a forgery)."""
        return encode_record(rdt_sequence, rdt_sequence if ft_sequence is None else ft_sequence, status, wrench,
                             self.counts[0], self.counts[1])

    def send_raw(self, data, sock=None):
        """``data`` to the client from the sensor's socket (or ``sock``: a stranger's), if there is one."""
        with self.lock:
            if self.server.client is not None:
                (sock or self.server.sock).sendto(data, self.server.client)

    def close(self):
        self._stop.set()
        self.thread.join(5)
        self.server.close()
        if self.page is not None:
            self.page.close()


class Run:
    """The scripted controller against `compensate` (--reference, --log),
    one message and its answer at a time, every answer checked (Checker:
    working ranges, the clamp of the reference) and its correction's step
    from the last answer's bounded by MAX_STEP_DEG.  ``dev[k]``: the largest
    deviation of answer k's target from the reference (deg), ``corr[k]``
    its correction (deg, 6).  ``sensor``: before the first message it sends
    START_RECORDS records of its wrench without the process force (the tool
    in the air at the start, as compensate checks it; None: nothing)."""

    def __init__(self, robot, ref_deg, ctrl, sensor=None):
        self.ref_deg, self.ctrl, self.sensor = ref_deg, ctrl, sensor
        self.chk = Checker(robot, ref_deg)
        self.k = 0
        self.dev, self.corr = {}, {}
        self.worst_step_deg = 0.0
        self._last = None

    def step(self, before=None, pace_s=0.0):
        """One message (sequence k + 1, clock k periods); ``before()``: what the sensor sends first."""
        k = self.k
        if k == 0 and self.sensor is not None:
            # the tool in the air at the first message: START_RECORDS records that reach the client (a send before
            # the sensor's thread has taken pynetft's start request is dropped: seen at load 10, the check then
            # made on the first records of the cut, 707 N off)
            t_end, taken = time.monotonic() + HANG_GUARD_S, 0
            while taken < START_RECORDS:
                taken += bool(self.sensor.send(self.sensor.wrench - PROCESS_W))
                if taken < START_RECORDS:
                    assert time.monotonic() < t_end, "the sensor's stream never started"
                    time.sleep(0.001)
        if before is not None:
            before(k)
        got = self.ctrl.exchange(k + 1, k * T_MS, self.ref_deg(k * T))
        assert got is not None, f"the controller got no answer at {k}"
        self.chk.check(got, k, "controller")
        c = np.asarray(got) - self.ref_deg(k * T)
        if self._last is not None:
            d = float(np.abs(c - self._last).max())
            self.worst_step_deg = max(self.worst_step_deg, d)
            assert d <= MAX_STEP_DEG, f"the correction jumped {d:.4f} deg at {k}"
        self._last = c
        self.corr[k], self.dev[k] = c, float(np.abs(c).max())
        self.k += 1
        if pace_s:
            time.sleep(pace_s)
        return c

    def run(self, n, before=None, pace_s=0.0):
        for _ in range(n):
            self.step(before, pace_s)

    def engage(self, sensor, most=2000):
        """Messages, each after one record of the held wrench, until the
        correction has ramped in (beyond ENGAGED_DEG, then 50 more, and at
        least SETTLED_MESSAGES from the first: the start's work passes in a
        thread, so when is a matter of load); the steady correction's
        largest joint (deg)."""
        while self.k < most and (not self.dev or self.dev[self.k - 1] <= ENGAGED_DEG):
            self.step(lambda k: sensor.send())
        assert self.dev[self.k - 1] > ENGAGED_DEG, f"the correction never ramped in; compensate said: {self.said()}"
        self.run(max(50, SETTLED_MESSAGES - self.k), lambda k: sensor.send())
        return self.dev[self.k - 1]

    def said(self):
        """What compensate has written to stderr so far and not yet read (its last 3000 characters), for a
        failure's message: the reason a correction never came (a fault's line) is in it."""
        from scripted_compensate import _err_line, _err_pending

        proc, text = getattr(self.ctrl, "proc", None), ""
        while proc is not None and proc.poll() is None and _err_pending(proc):
            line = _err_line(proc)
            proc.early_err += line
            text += line
        return text[-3000:]

    def recover(self, sensor, steady, most=500):
        """Messages, each after one record of the held wrench that reached a client (``streaming``: pynetft's
        restart of the stream waits its back-off, and each message is at least PACE_S apart), until the
        correction is back to half ``steady`` (at most ``most``); how many it took (None: not within them;
        liveness, reported, not a safety matter)."""
        for i in range(most):
            self.step(lambda k: streaming(sensor), pace_s=PACE_S)
            if self.dev[self.k - 1] > 0.5 * steady:
                return i + 1
        return None

    def zero_tail(self, n):
        """Whether the last ``n`` answers carried no correction."""
        return all(self.dev[k] <= ZERO_DEG for k in range(self.k - n, self.k))

    def moved(self, k0, k1=None):
        """The most any correction of answers k0..k1-1 differs from answer k0 - 1's (deg)."""
        ref = self.corr[k0 - 1]
        return max(float(np.abs(self.corr[k] - ref).max()) for k in range(k0, self.k if k1 is None else k1))

    def figures(self, s, **more):
        """The figures an attack's report gives (``s``: summary.json's cycles)."""
        return dict(more, worst_deg=round(self.chk.worst_deg, 4), worst_step_deg=round(self.worst_step_deg, 4),
                    answers=s["answered"], refused=s["targets_refused"], records=s["sensor_records"],
                    clipped=s["sensor_clipped"], spikes=s["moment_spikes"],
                    sensor_faults=s["health"]["seen_of_the_other_side"]["sensor_faults"],
                    fault_onsets=s["fault_onsets"])


@pytest.fixture()
def inputs(tmp_path, robot):
    """(model, payload, reference path, reference function deg, held wrench N N*m, log folder): the payload's
    weight and a process force (PROCESS_W: a correction of 0.053 deg on its largest joint once compensating),
    from the first message's records on when Run is given the sensor (before them: the tool in the air)."""
    model, payload, ref, ref_fn = h.write_inputs(str(tmp_path), robot, duration_s=3.5)
    w = np.asarray(h.hold_wrench(robot, ref_fn(0.0))(0.0), dtype=float) + PROCESS_W
    return model, payload, ref, (lambda t: np.degrees(ref_fn(t))), w, str(tmp_path / "log")


def start(inputs, sensor, extra=(), log=True):
    """`compensate` against ``sensor`` and a scripted controller; (process, controller).  ``log`` False: no
    --log (and so no start's work: compensating from the first message).  Until the first message the sensor
    streams its wrench without PROCESS_W (the tool in the air; then what the test sends)."""
    model, payload, ref, _, _, folder = inputs
    sensor.auto_wrench = sensor.wrench - PROCESS_W  # (until the first message: the tool in the air)
    port = h.free_udp_port()
    proc = h.start_compensate(model, payload, sensor, port, reference=ref, log=folder if log else None,
                              extra=["--sensor-rate-hz", f"{RATE_HZ:g}", *extra])
    sensor.manual()
    ctrl = h.ScriptedController(port)
    ctrl.proc = proc  # (Run.said: compensate's lines for a failure's message)
    return proc, ctrl


def finish(proc, ctrl, sensor):
    """(exit status, stderr, answers sent after the script's last one)."""
    try:
        code, err = h.finish(proc)
        return code, err, ctrl.answers()
    finally:
        ctrl.close()
        sensor.close()
