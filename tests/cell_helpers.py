"""Helpers of the cell tests: the inputs `robstiff compensate` reads (a
model JSON as `robstiff identify` writes it, a payload YAML as `robstiff
calibrate-payload` writes it, a joint reference CSV), free UDP ports on
127.0.0.1, and a simulated cell (cell/sim_cell.py with its stand-in arm)
running in a thread."""

import json
import os
import socket
import subprocess
import sys
import threading
import time

import numpy as np

from scripted_compensate import (HANG_GUARD_S, EndWhenIdle, ScriptedController, finish, held_run,  # noqa: F401
                                 start_compensate)

from robstiff_drake.cell.sim_cell import CellNetwork, Faults
from robstiff_drake.cell.stand_in_arm import ServoArmStandIn
from robstiff_drake.model import ik
from robstiff_drake.model.payload import PayloadCalibration
from robstiff_drake.model.robot import load_robot

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
# Where the tool works: the block test's start point (mm, base frame), spindle down
START_MM = (1600.0, 0.0, 700.0)
# The payload calibration's sensor bias (N, N*m): made up for the tests
FORCE_BIAS_N = (3.0, -2.0, 5.0)
TORQUE_BIAS_NM = (0.2, -0.1, 0.05)


def free_udp_port():
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    return port


def calibration(robot):
    return PayloadCalibration(mass_kg=robot.payload.mass_kg, com_mm=list(robot.payload.com_m * 1e3),
                              force_bias_N=list(FORCE_BIAS_N), torque_bias_Nm=list(TORQUE_BIAS_NM),
                              sensor_mount_rpy_deg=[0.0, 0.0, 0.0])


_PASSES = {}  # the reference passes solved in this process: (the robot's kinematics and limits, the pass) -> (ts, qs)


def _pass(robot, feed_mm_per_s, duration_s, start_mm):
    """A straight pass along x at the feed for 3 s (60 mm), then at rest; by IK every 4 ms: (t s, joints rad).
    Solved once a process for the same robot and pass (875 solves, about 0.6 s, in each of some 80 tests
    before), and copied out."""
    dh = robot.dh
    key = (repr([None if v is None else np.asarray(v, dtype=float).tolist()
                 for v in (dh.d_m, dh.a_m, dh.alpha_rad, dh.home_rad, dh.base, dh.beta_rad)]),
           np.asarray(robot.payload.tool_point_m).tobytes(),
           np.asarray(robot.q_lower_rad).tobytes(), np.asarray(robot.q_upper_rad).tobytes(),
           float(feed_mm_per_s), float(duration_s), None if start_mm is None else tuple(map(float, start_mm)))
    if key not in _PASSES:
        ts = np.arange(0.0, min(duration_s, 3.5) + 1e-9, 0.004)
        q_prev, qs = None, []
        for t in ts:
            p = np.array(start_mm or START_MM) / 1e3 + [feed_mm_per_s * min(t, 3.0) / 1e3, 0.0, 0.0]
            q_prev = ik.solve_ik(robot.dh, ik.tool_down_pose(p, 0.0), robot.payload.tool_point_m, q_ref_rad=q_prev,
                                 q_lower_rad=robot.q_lower_rad, q_upper_rad=robot.q_upper_rad)
            qs.append(q_prev)
        _PASSES[key] = (ts, np.array(qs))
    ts, qs = _PASSES[key]
    return ts.copy(), qs.copy()


def write_inputs(folder, robot, *, feed_mm_per_s=20.0, duration_s=3.0, robot_name=None, nominal=None, start_mm=None):
    """model.json, payload.yaml and reference.csv in ``folder``; returns
    their paths and the reference as a function of time (rad)."""
    model = os.path.join(folder, "model.json")
    with open(model, "w") as f:
        json.dump({"robot": robot_name or robot.name,
                   "joint_stiffness_Nm_per_rad": robot.joint_stiffness_Nm_per_rad.tolist(),
                   "joint_stiffness_nominal_Nm_per_rad": (nominal if nominal is not None
                                                          else robot.joint_stiffness_Nm_per_rad).tolist()}, f)
    cal = calibration(robot)
    payload = os.path.join(folder, "payload.yaml")
    with open(payload, "w") as f:
        f.write("# test payload calibration: the robot file's payload and a made-up bias\npayload_calibration:\n"
                f"  robot: {robot.name}\n  mass_kg: {float(cal.mass_kg)}\n  com_mm: {[float(v) for v in cal.com_mm]}\n"
                f"  force_bias_N: {[float(v) for v in cal.force_bias_N]}\n"
                f"  torque_bias_Nm: {[float(v) for v in cal.torque_bias_Nm]}\n  sensor_mount_rpy_deg: [0.0, 0.0, 0.0]\n")
    ts, qs = _pass(robot, feed_mm_per_s, duration_s, start_mm)
    ref = os.path.join(folder, "reference.csv")
    with open(ref, "w") as f:
        f.write("# test joint reference: a straight pass along +x from (1600, 0, 700) mm for 3 s, IK every 4 ms\n")
        f.write("t_s," + ",".join(f"q{j}_deg" for j in range(1, 7)) + "\n")
        for t, q in zip(ts, np.degrees(qs)):
            f.write(f"{t:.4f}," + ",".join(f"{v:.9f}" for v in q) + "\n")

    def reference(t):
        return np.array([np.interp(t, ts, qs[:, j]) for j in range(6)])

    return model, payload, ref, reference


def cutting_wrench(t0=0.8, ramp_s=0.3, force_N=(-300.0, 260.0, 50.0)):
    """A process wrench on the tool (base frame) that ramps in from t0 over
    ramp_s (about the block test's forces)."""
    F = np.array(force_N)

    def W(t):
        a = min(max((t - t0) / ramp_s, 0.0), 1.0)
        s = 0.5 - 0.5 * np.cos(np.pi * a)
        return np.r_[F * s, 0.0, 0.0, 0.0]

    return W


def start_cell(robot, reference, *, egm_port, netft_port, duration_s, faults=None, wrench=None, rt_priority=0,
               lockstep=False, link=None, supervise=True, transport_delay_cycles=None, cut_s=None,
               answer_timeout_s=1.0, cpus=None, spread_records=False):
    """A simulated cell (stand-in arm) in a thread; returns (thread, network).
    ``rt_priority``: run the thread under SCHED_FIFO (a controller is hard
    real-time; the benchmark's option); ``cut_s``: end after this much of
    the controller's time once engaged (lockstep); ``spread_records``: the
    sensor's records at their own instants (CellNetwork)."""
    station = ServoArmStandIn(robot=robot, joint_stiffness_Nm_per_rad=robot.joint_stiffness_Nm_per_rad,
                              calibration=calibration(robot), process_wrench=wrench or cutting_wrench(),
                              reference=reference, q_start_rad=reference(0.0), seed=3)
    limits = ((np.degrees(robot.q_lower_rad), np.degrees(robot.q_upper_rad), robot.speed_limit_deg_per_s,
               robot.acceleration_limit_deg_per_s2) if supervise else None)
    net = CellNetwork(station, egm_to=("127.0.0.1", egm_port), netft_port=netft_port, faults=faults or Faults(),
                      netft_http_port=netft_port, lockstep=lockstep, limits=limits, link=link,
                      transport_delay_cycles=transport_delay_cycles, answer_timeout_s=answer_timeout_s,
                      spread_records=spread_records)

    def run():
        if cpus:
            os.sched_setaffinity(0, set(cpus))
        if rt_priority:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(rt_priority))
        net.run(duration_s, reference(0.0), cut_s=cut_s)

    th = threading.Thread(target=run, daemon=True)
    th.start()
    return th, net


def compensate_cmd(model, payload, reference, *, egm_port, netft_port, log=None, extra=(), idle_exit_s=0.5):
    cmd = [sys.executable, "-m", "robstiff_drake", "compensate", "--egm-port", str(egm_port),
           "--netft", f"127.0.0.1:{netft_port}", "--netft-http-port", str(netft_port), "--model", model,
           "--payload", payload,
           "--wait-s", "20", "--idle-exit-s", f"{idle_exit_s:g}", "--sensor-rate-hz", "1000"]
    if reference:
        cmd += ["--reference", reference]
    if log:
        cmd += ["--log", log]
    return cmd + list(extra)


def run_compensate_against_cell(tmp, *, duration_s=3.0, faults=None, extra=(), wrench=None, stream_reference=False,
                                cell_rt_priority=0, lockstep=True, reference_first_line=None):
    """Start `robstiff compensate` as a separate process and the simulated
    cell; returns (completed process, network stats, log folder).  Without
    ``stream_reference`` the compensator holds the start pose (no
    --reference) and the stand-in measures its error against that pose.
    ``lockstep`` (the tests' default): the cell steps when answered and
    ends after ``duration_s`` of its controller's time, the compensator
    when the test ends it (SIGTERM, scripted_compensate.EndWhenIdle) once
    the cell is done and the loop has said the controller is silent: the
    loop's logic whatever this machine's load (--idle-exit-s only a hang
    guard: at 0.5 s a pause of the test process, whose thread is the
    controller, ended the run mid-cut); False: both in real time for
    ``duration_s``.  ``reference_first_line``: a line put before the
    reference file's own (e.g. compensate-program's corrected mark)."""
    robot = load_robot()
    model, payload, ref, ref_fn = write_inputs(str(tmp), robot, duration_s=duration_s + 1.0)
    if reference_first_line is not None:
        with open(ref) as f:
            text = f.read()
        with open(ref, "w") as f:
            f.write(reference_first_line + text)
    q0 = ref_fn(0.0)
    reference = ref_fn if stream_reference else (lambda t: q0)
    egm_port, netft_port = free_udp_port(), free_udp_port()
    log = os.path.join(str(tmp), "log")
    # the cell first, standing still (its sensor streaming, its controller
    # sending EGM messages) until the compensator answers, as a real one
    wall_s = duration_s * (30.0 if lockstep else 1.0) + 15.0  # (lockstep: a bound; the cut ends the run)
    th, net = start_cell(robot, reference, egm_port=egm_port, netft_port=netft_port, duration_s=wall_s,
                         faults=faults, wrench=wrench, rt_priority=cell_rt_priority, lockstep=lockstep,
                         cut_s=duration_s if lockstep else None, answer_timeout_s=10.0 if lockstep else 1.0)
    end = [] if lockstep else ["--duration-s", str(duration_s)]
    proc = subprocess.Popen(compensate_cmd(model, payload, ref if stream_reference else None, egm_port=egm_port,
                                           netft_port=netft_port, log=log, extra=list(extra) + end,
                                           idle_exit_s=HANG_GUARD_S if lockstep else 0.5), cwd=ROOT,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    watch = EndWhenIdle(proc)
    try:
        if lockstep:
            t_end = time.monotonic() + wall_s
            while th.is_alive() and proc.poll() is None and time.monotonic() < t_end:
                th.join(0.1)  # (the cut's end or the cell's stop; or the process ended: a refused start)
            watch.cell_done()
        code, out, err = watch.wait(timeout=wall_s + 60 + HANG_GUARD_S)
    finally:
        if proc.poll() is None:
            proc.kill()
        net.stop = True
        th.join(30)
        net.close()
    return subprocess.CompletedProcess(proc.args, code, out, err), net.stats, log


def run_compensate_until_cell_done(cmd, cell_running, *, bound_s, env=None, started=None):
    """`robstiff compensate` (``cmd``, its --idle-exit-s HANG_GUARD_S: a hang guard) against a cell that ends
    its own scenario (a lockstep cell with its cut, or sim-cell's pass): the process is ended by the test once
    ``cell_running()`` is False and its loop has said the controller is silent (EndWhenIdle: SIGTERM, the log
    written whole), not by a silence alone, which a stalled controller (a loaded machine deschedules a process
    for a second) would cause mid-run too.  ``bound_s``: how long the cell may run at most (a bound, not a
    measure); ``started(proc)``: called once the process is started (a test's stall injection).  A completed
    process (text)."""
    last = max(k for k, a in enumerate(cmd) if a == "--idle-exit-s")
    assert cmd[last + 1] == f"{HANG_GUARD_S:g}", cmd  # (the run's end is the test's, not a short silence's)
    proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env)
    watch = EndWhenIdle(proc)
    try:
        if started is not None:
            started(proc)
        t_end = time.monotonic() + bound_s
        while cell_running() and proc.poll() is None and time.monotonic() < t_end:
            time.sleep(0.1)  # (the cell's end; or the process ended: a refused start)
        watch.cell_done()
        code, out, err = watch.wait(timeout=HANG_GUARD_S * 2)
    finally:
        if proc.poll() is None:
            proc.kill()
    return subprocess.CompletedProcess(cmd, code, out, err)


def run_compensate_against_thread_cell(cmd, th, net, *, bound_s=600.0):
    """run_compensate_until_cell_done against a cell of start_cell (its thread ``th``, its network ``net``),
    then the cell stopped and closed whatever happened.  A completed process (text)."""
    try:
        return run_compensate_until_cell_done(cmd, th.is_alive, bound_s=bound_s)
    finally:
        net.stop = True
        th.join(30)
        net.close()


class FakeSensor:
    """A Net F/T on 127.0.0.1 (RDT and its calibration page) streaming
    ``wrench(t)`` (N, N*m, sensor frame; ``by_record``: ``wrench(i)`` of the
    record's index i among those sent to the client, so that what it
    streams does not depend on this machine's pace) at about 1 kHz from a
    thread; ``sent``: the records sent to the client so far."""

    def __init__(self, wrench, units=("N", "N-m"), counts=(1e6, 1e6), by_record=False):
        from robstiff_drake.cell.rdt import RDTServer

        self.server = RDTServer(0, http_port=0, units=units, counts_per_force=counts[0],
                                counts_per_torque=counts[1])
        self.port, self.http_port = self.server.port, self.server.http_port
        self.wrench = wrench
        self.by_record = by_record
        self.sent = 0
        self._stop = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self):
        import time

        t0 = time.monotonic()
        while not self._stop.is_set():
            self.server.poll()
            if self.server.send(list(self.wrench(self.sent if self.by_record else time.monotonic() - t0))):
                self.sent += 1  # (a record counts once a client has started the stream)
            time.sleep(0.001)

    def close(self):
        self._stop.set()
        self.thread.join(5)
        self.server.close()


class ScriptedLink:
    """A controller link for CompensatorLoop that hands over scripted batches
    of messages, one batch per read, each read after the answers before it
    (as in lockstep); the script's end stops the loop (KeyboardInterrupt)."""

    name, option, port = "EGM", "--egm-port", 0
    strangers = malformed = 0
    answer_deadline_periods = 1.0

    def __init__(self, batches):
        self.batches = batches

    def send_targets(self, msg, target, env):
        pass

    def receive(self, timeout_s):
        if not self.batches:
            raise KeyboardInterrupt  # the script's end
        t = time.monotonic()
        return [(m, t) for m in self.batches.pop(0)]


class HeldSensor:
    """A sensor for CompensatorLoop whose every read is ``per_read`` records
    of ``w`` (4: a 1 kHz sensor, compensate's default --sensor-rate-hz, at
    one read a 4 ms message)."""

    def __init__(self, w, per_read=4):
        self.w, self.per_read = w, per_read

    def drain(self):
        t = time.monotonic()
        return [(self.w, t, 0, False)] * self.per_read


def hold_wrench(robot, q_rad):
    """What the wrist sensor reads at rest at ``q_rad`` (payload weight and bias, no noise)."""
    from robstiff_drake.model.payload import payload_wrench
    from robstiff_drake.model.realtime import DeflectionPredictor

    kin = DeflectionPredictor(robot.dh, robot.joint_stiffness_Nm_per_rad, robot.payload.tool_point_m)
    R, _ = kin.flange_rotation_and_tool_point(np.asarray(q_rad, dtype=float))
    w = payload_wrench(R, calibration(robot))
    return lambda t: w


def hold_compensator(robot, w):
    """The chain compensate runs (model/compensator.Compensator: the
    library's stiffness, a 10 Hz low-pass at 1 kHz, 1000 N guard, 0.5 deg
    saturation, 5 deg/s rate limit, no delay) started on the wrench ``w``."""
    import math

    from robstiff_drake.model.compensator import Compensator
    from robstiff_drake.model.filters import filter_coefficients
    from robstiff_drake.model.realtime import DeflectionPredictor

    tool = robot.payload.tool_point_m
    return Compensator(predictor=DeflectionPredictor(robot.dh, robot.joint_stiffness_Nm_per_rad, tool),
                       calibration=calibration(robot), tool_m=tool,
                       filter_ba=filter_coefficients("lowpass", 10.0, 2, 1000.0, 3600.0), max_jump_N=1000.0,
                       saturation_rad=math.radians(0.5), rate_limit_rad_per_s=math.radians(5.0), delay_steps=0,
                       initial_wrench=w)


def logging_run(tmp, answered, timeout_s=60.0):
    """`compensate --log` (a process, holding the start pose) against the
    stand-in cell, returned once the controller has had ``answered``
    answers: (process, cell thread, network, log folder)."""
    import time

    robot = load_robot()
    model, payload, _, ref_fn = write_inputs(str(tmp), robot, duration_s=1.0)
    egm_port, netft_port = free_udp_port(), free_udp_port()
    # the test ends the run (SIGTERM, SIGKILL): --idle-exit-s a hang guard only, and the cell waits out a
    # stalled compensator (at 0.5 s and 1 s, a test process or a compensate process descheduled that long on a
    # loaded machine ended the run before its count of answers)
    th, net = start_cell(robot, lambda t: ref_fn(0.0), egm_port=egm_port, netft_port=netft_port,
                         duration_s=timeout_s + 30.0, answer_timeout_s=HANG_GUARD_S)
    log = os.path.join(str(tmp), "log")
    proc = subprocess.Popen(compensate_cmd(model, payload, None, egm_port=egm_port, netft_port=netft_port, log=log,
                                           idle_exit_s=HANG_GUARD_S),
                            cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    t0 = time.monotonic()
    while net.stats.answered < answered and time.monotonic() - t0 < timeout_s and proc.poll() is None:
        time.sleep(0.05)
    return proc, th, net, log


def cached_preview_table(job, robot_yaml=None, *, k_Nm_per_rad=None, cutoff_hz=2.0, rate_hz=1000.0, delay_steps=0,
                         servo=None, period_s=0.004):
    """Compute the preview's table of ``job`` into the disk cache as `compensate --mode preview` with these
    options keys it (cell/preview_cache.py: the job run again; a cold cache computes it in the background while
    the run is plain); returns the cache file."""
    from robstiff_drake.cell import preview_cache
    from robstiff_drake.cell.preview_job import build_plan, load_job, table_file
    from robstiff_drake.model.filters import filter_coefficients

    sc, robot = load_job(job, robot_yaml, period_s=period_s)
    k = robot.joint_stiffness_Nm_per_rad if k_Nm_per_rad is None else np.asarray(k_Nm_per_rad, dtype=float)
    ba = filter_coefficients("lowpass", cutoff_hz, 2, rate_hz, 3600.0)
    file = table_file(sc, robot, k, period_s=period_s, filter_ba=ba, rate_hz=rate_hz, delay_steps=delay_steps,
                      servo=servo)
    if preview_cache.load(file) is None:
        plan = build_plan(sc, robot, k, period_s=period_s, filter_ba=ba, rate_hz=rate_hz, delay_steps=delay_steps,
                          servo_option=servo)
        assert preview_cache.save(plan, file)
    return file
