"""benchmarks/bench_compensate.py's in-process figures, measured in the
same run as the process over loopback: one DeflectionPredictor call and
the whole chain per 4 ms message (model/compensator.py), the loop's whole
cycle on a loopback link per protocol, and the breakdown of one message
by stage (receive and decode, session and feedback checks, the sensor's
records through guard and filter, the model's tick, the target check with
the encoding and the send, the log rows and statistics after the answer).
Not a benchmark of its own (no ``bench_`` prefix: CI runs it through
bench_compensate.py)."""

import math
import os
import statistics
import sys
import tempfile
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "tests"))
import cell_helpers as h  # noqa: E402

from robstiff_drake.model.compensator import Compensator  # noqa: E402
from robstiff_drake.model.filters import filter_coefficients  # noqa: E402
from robstiff_drake.model.realtime import DeflectionPredictor  # noqa: E402


def in_process_us(robot, repeats=3000):
    """(median us of one DeflectionPredictor call, median us of the whole
    chain per 4 ms message: 4 sensor samples through guard and filter + one
    controller tick)."""
    tool = robot.payload.tool_point_m
    pred = DeflectionPredictor(robot.dh, robot.joint_stiffness_Nm_per_rad, tool)
    comp = Compensator(predictor=pred, calibration=h.calibration(robot), tool_m=tool,
                       filter_ba=filter_coefficients("lowpass", 10.0, 2, 1000.0, 3600.0), max_jump_N=1000.0,
                       saturation_rad=math.radians(0.5), rate_limit_rad_per_s=math.radians(5.0), delay_steps=0,
                       initial_wrench=[0.0] * 6)
    rng = np.random.default_rng(0)
    qs = (rng.uniform(robot.q_lower_rad, robot.q_upper_rad, size=(64, 6)) * 0.3).tolist()
    ws = (rng.normal(size=(64, 6)) * 5.0).tolist()
    t_pred, t_chain = [], []
    for i in range(repeats):
        q, w = qs[i % 64], ws[i % 64]
        t0 = time.perf_counter()
        pred(q, w)
        t1 = time.perf_counter()
        for _ in range(4):
            comp.sensor_sample(w)
        comp.tick(q, 0.004)
        t2 = time.perf_counter()
        t_pred.append((t1 - t0) * 1e6)
        t_chain.append((t2 - t1) * 1e6)
    return statistics.median(t_pred), statistics.median(t_chain)


def _loopback_link(protocol):
    """(the controller's socket on 127.0.0.1, the loop's link of
    ``protocol`` answering it, the hold pose in controller deg)."""
    import socket

    from robstiff_drake.cell import rsi, stream_motion
    from robstiff_drake.cell.egm import EgmLink

    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    ctrl = ("127.0.0.1", sock.getsockname()[1])
    link = {"egm": lambda: EgmLink(0, ctrl), "rsi": lambda: rsi.RsiLink(0, ctrl, 0.004),
            "stream-motion": lambda: stream_motion.StreamMotionLink(0, ctrl)}[protocol]()
    link.reply_to = ctrl
    q0 = [0.0, 7.008, 29.517, 0.0, 53.476, 0.0]  # (RSI learns its start from the first message it decodes)
    return sock, link, q0


class _HoldSensor:
    """A sensor whose four records per 4 ms message all read ``w``."""

    def __init__(self, w):
        self.w = w

    def drain(self):
        now = time.monotonic()
        return [(self.w, now, 0, False)] * 4


def in_process_cycle_us(robot, protocol, repeats=1000):
    """(median, p99 us) of one whole message in-process: the session check,
    the sensor's 4 records through the guards, the chain, the target check,
    the protocol's encoding and a UDP send to a sink on 127.0.0.1, and the
    log's row formatting (cell/compensate.CompensatorLoop.cycle), without
    this machine's scheduling between two processes."""
    from robstiff_drake.cell.compensate import CompensatorLoop, LoopSettings, Reference
    from robstiff_drake.cell.link import Message
    from robstiff_drake.cell.run_log import StreamLog

    sink, link, q0 = _loopback_link(protocol)
    if protocol == "rsi":
        from robstiff_drake.cell import rsi

        link.decode(rsi.encode_rob(1_000_000, q0, q0))  # (its start, as from the controller's first message)
    w = h.hold_wrench(robot, np.radians(q0))(0.0).tolist()
    comp = h.hold_compensator(robot, w)
    ref = Reference(period_s=0.004)
    ref.hold(q0)
    with tempfile.TemporaryDirectory() as tmp:
        log = StreamLog(os.path.join(tmp, "log"), "compensator: {}\n", "bench")
        loop = CompensatorLoop(comp, link, _HoldSensor(w), ref, robot, LoopSettings(max_jump_Nm=350.0), log=log,
                               out=open(os.devnull, "w"))
        loop.run_start(Message(1, 0, q0, echo=1), time.monotonic())
        us = []
        for k in range(2, repeats + 2):
            msg = Message(k, (k - 1) * 4, q0, echo=k)
            t0 = time.perf_counter()
            t_arr = time.monotonic()
            loop.cycle(msg, t_arr, loop._session(msg)[1])
            us.append((time.perf_counter() - t0) * 1e6)
            time.sleep(0.003)
            if k % 100 == 0:
                log.tick(None)
                sink.setblocking(False)
                try:
                    while True:
                        sink.recvfrom(65536)
                except BlockingIOError:
                    pass
        log.close({})
    link.sock.close()
    sink.close()
    return float(np.median(us)), float(np.percentile(us, 99))


STAGES = ("receive (select, recvfrom: system calls)", "decode", "session + feedback", "sensor records (guard, filter)",
          "model (tick)", "safety check (target, the pose commanded, motion)", "encode (and the answer read back)",
          "send (sendto: system call)", "rest (envelope, reference, target)",
          "counters and statistics (after the answer)", "log rows (after the answer)",
          "garbage collection (after the answer)")
AFTER = STAGES[-3:]
# (inside the stages above: the collector's own time between a message's arrival and its answer)
GC_INSIDE = "of which garbage collection on the way to the answer"


class _TimedSocket:
    """The link's socket with its sendto timed (the rest passed through)."""

    def __init__(self, sock, timed, sent_at):
        self._sock = sock
        send = timed("send (sendto: system call)", sock.sendto)

        def sendto(*a):
            try:
                return send(*a)
            finally:
                sent_at[:] = [time.perf_counter()]  # (the answer has left)
        self.sendto = sendto

    def __getattr__(self, name):
        return getattr(self._sock, name)


def stage_breakdown_us(robot, protocol, repeats=1000, gc_mode="safe-point"):
    """Where one message's time goes, in-process: a datagram the controller
    would send (its encoding made beforehand) is sent to the loop's socket
    and the loop receives and decodes it, then cell/compensate's cycle
    with each part timed (the instance's methods wrapped).  ``gc_mode``:
    "safe-point" as the process runs (cell/realtime_thread.quiet_gc: the
    automatic collector off, the loop collecting after its answers), or
    "automatic" (the objects frozen, the collector left on: before this
    change).  Returns {stage: (median us, p99 us)} (GC_INSIDE: the
    collector's time inside the stages; with it the number of messages it
    ran in) and (median, p99) of the whole message, arrival to answer (the
    part the controller waits for)."""
    import gc

    from robstiff_drake.cell.realtime_thread import quiet_gc, restore_gc
    from robstiff_drake.cell import rsi, stream_motion
    from robstiff_drake.cell.compensate import CompensatorLoop, LoopSettings, Reference
    from robstiff_drake.cell.egm import ControllerLink
    from robstiff_drake.cell.run_log import StreamLog

    ctrl_sock, link, q0 = _loopback_link(protocol)
    addr = ("127.0.0.1", link.sock.getsockname()[1])
    egm = ControllerLink("127.0.0.1", 0) if protocol == "egm" else None

    def datagram(k):
        if protocol == "egm":
            return egm.robot_message(q0, q0, tm_ms=(k - 1) * 4)
        if protocol == "rsi":
            return rsi.encode_rob(1_000_000 + 4 * k, q0, q0)
        return stream_motion.encode_status(k, (k - 1) * 4, q0)

    w = h.hold_wrench(robot, np.radians(q0))(0.0).tolist()
    comp = h.hold_compensator(robot, w)
    ref = Reference(period_s=0.004)
    ref.hold(q0)
    spent = {name: [] for name in STAGES}
    current = {}

    def timed(stage, fn):
        def wrapper(*a, **k):
            t0 = time.perf_counter()
            try:
                return fn(*a, **k)
            finally:
                current[stage] = current.get(stage, 0.0) + time.perf_counter() - t0
        return wrapper

    total, gc_inside = [], []
    gc_t0 = []

    def gc_timer(phase, info):
        if phase == "start":
            gc_t0[:] = [time.perf_counter()]
        elif gc_t0:
            current["gc"] = current.get("gc", 0.0) + time.perf_counter() - gc_t0[0]

    with tempfile.TemporaryDirectory() as tmp:
        log = StreamLog(os.path.join(tmp, "log"), "compensator: {}\n", "bench")
        loop = CompensatorLoop(comp, link, _HoldSensor(w), ref, robot, LoopSettings(max_jump_Nm=350.0), log=log,
                               out=open(os.devnull, "w"))
        ctrl_sock.sendto(datagram(1), addr)
        loop.run_start(*link.receive(1.0)[-1])
        loop.gate.wait(30.0)  # (the log folder's start, off the loop's thread)
        import robstiff_drake.cell.link as link_module

        saved = link_module.unsafe_reason, link_module.motion_reason
        loop._session = timed("session + feedback", loop._session)
        loop._feedback = timed("session + feedback", loop._feedback)
        loop._read_sensor = timed("sensor records (guard, filter)", loop._read_sensor)
        comp.tick = timed("model (tick)", comp.tick)
        link.decode = timed("decode", link.decode)
        link.encode = timed("encode (and the answer read back)", link.encode)
        link.commanded_deg = timed("encode (and the answer read back)", link.commanded_deg)
        link.answer_problem = timed("safety check (target, the pose commanded, motion)", link.answer_problem)
        link_module.unsafe_reason = timed("safety check (target, the pose commanded, motion)", saved[0])
        link_module.motion_reason = timed("safety check (target, the pose commanded, motion)", saved[1])
        sent_at = []
        link.sock = _TimedSocket(link.sock, timed, sent_at)
        log.cycle = timed("log rows (after the answer)", log.cycle)
        log.wrench = timed("log rows (after the answer)", log.wrench)
        loop._safe_point = timed("garbage collection (after the answer)", loop._safe_point)
        token = quiet_gc()
        if gc_mode == "automatic":
            gc.enable()
        else:
            loop.gc_token = token
        gc.callbacks.append(gc_timer)
        for k in range(2, repeats + 2):
            current.clear()
            ctrl_sock.sendto(datagram(k), addr)
            t0 = time.perf_counter()
            got = link.receive(0.1)
            t1 = time.perf_counter()
            msg, t_arr = got[-1]
            ok, dt = loop._session(msg)
            loop.cycle(msg, t_arr, dt)
            t2 = time.perf_counter()
            inside = current.pop("gc", 0.0)
            loop._safe_point()
            current["receive (select, recvfrom: system calls)"] = t1 - t0 - current.get("decode", 0.0)
            current.pop("gc", None)  # (collections after the answer: in their stage's time)
            t_sent = sent_at[0]
            current["counters and statistics (after the answer)"] = (
                t2 - t_sent - current.get("log rows (after the answer)", 0.0))
            current["rest (envelope, reference, target)"] = (t_sent - t0) - sum(
                v for name, v in current.items() if name not in AFTER)
            for name in STAGES:
                spent[name].append(current.get(name, 0.0) * 1e6)
            gc_inside.append(inside * 1e6)
            total.append((t_sent - t0) * 1e6)
            time.sleep(0.003)
            if k % 100 == 0:
                log.tick(None)
                ctrl_sock.setblocking(False)
                try:
                    while True:
                        ctrl_sock.recvfrom(65536)
                except BlockingIOError:
                    pass
                ctrl_sock.setblocking(True)
        gc.callbacks.remove(gc_timer)
        restore_gc(token)
        log.close({})
        link_module.unsafe_reason, link_module.motion_reason = saved
    link.sock.close()
    ctrl_sock.close()
    if egm is not None:
        egm.sock.close()
    out = {name: (float(np.median(v)), float(np.percentile(v, 99))) for name, v in spent.items()}
    out[GC_INSIDE] = (float(np.max(gc_inside)), int(np.count_nonzero(gc_inside)))
    return out, (float(np.median(total)), float(np.percentile(total, 99)))
