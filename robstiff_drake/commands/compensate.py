"""``robstiff compensate``: the compensator as a process between a robot
controller (ABB EGM, KUKA RSI or FANUC Stream Motion, UDP) and an ATI Net
F/T (RDT, UDP), running the chain of the simulated cell
(model/compensator.py) on the real signals.

    robstiff compensate --egm-port 6510 --controller 192.168.125.1 --netft 192.168.1.1
        --robot ROBOT --model identified.json --payload payload.yaml --reference joints.csv --log run1

Inputs are checked (the reference against the robot's working ranges,
axis speeds and accelerations and the controller period), the correction
loop's stability at the start pose by the linear loop model
(cell/loop_guard.py; --allow-unstable-loop overrides it), the sensor's
calibration read and its stream started and the controller's first
message awaited and checked before the loop; anything wrong there is one
line and exit status 2.  The sensor's reading at the first message is
checked against the payload calibration, its record rate against
--sensor-rate-hz (cell/sensor_checks.py: a fault for the session).  The start's slow work (without --reference the
loop check and the correction bound's check at the hold pose; the log
folder's start) runs off the loop's
thread while the controller is answered with its own pose
(cell/start_gate.py), and --mode preview's table, when the disk cache
does not hold it, in another process while the loop runs plain
(cell/preview_job.BackgroundTable).  During the loop faults are logged and ramp the
correction to zero (cell/compensate.py); every target passes
cell/safety.py's check.  Ctrl-C, SIGTERM, --duration-s or a controller
silent for --idle-exit-s end the run; --log DIR is written as the run goes
(cell/run_log.py); the run ends with its health verdict.
"""

import math
import sys
from pathlib import Path

import numpy as np

from robstiff_drake.commands.compensate_inputs import CORRECTED_FLAG, check_axis_limits, check_reference_claim, \
    endpoint_clash, json_doc, payload_mass_note, payload_robot_note, read_model, read_reference, sensor_timeout_note, \
    wait_for_file
from robstiff_drake.errors import InputError
from robstiff_drake.cell.realtime_thread import CpuLatency, pin_to_cpu as _pin_to_cpu, quiet_gc as _quiet_gc, \
    realtime as _realtime, restore_gc as _restore_gc
from robstiff_drake.cell.correction_bound import DEFAULT_MAX_CORRECTION_DEG, DEFAULT_MAX_CORRECTION_MM
from robstiff_drake.cell.end_hold import EndHold
from robstiff_drake.commands.compensate_report import report
from robstiff_drake.progress import info

# How far the first joint feedback may be from the reference's start (deg)
# before the run is refused: the robot must be brought to the path's start
# (MoveAbsJ) before streaming starts, or the first target would jump.
START_TOLERANCE_DEG = 0.5
# The force filter's default low-pass cutoff (Hz).  Not 10 Hz (the old default): the loop model
# (model/loop_check.py) at the block test's start on the IRB 6400, 4 ms period, 1 kHz sensor, calls 10 Hz
# unstable (spectral radius per period 1.0003 in air and 1.0028 cutting at the plant's assumed 5 % modal
# damping on the drives-closed modes, 1.0034 and 1.0058 at the check's 2 %: benchmarks/bench_loop_check.py;
# 1.0018 / 1.0043 and 1.0047 / 1.0071 with the damping on the motors-held modes and the drives' integral
# corner at 7.5 Hz), and the Drake cell diverges above it (studies/loop_stability_check.py, docs/results.md):
# the sensor feeds the payload's inertial force back and a filter near the arm's first mode (4.5-4.8 Hz with
# the drives closed) takes its damping.  2 Hz: the block scenario's filter, near the least radius (0.9970 in
# air, 0.9967 cutting at 2 %), stable with the check's margin up to 4 Hz there; a 75 mm cutter entering at 20 mm/s changes the force over seconds, so the
# lag costs little (entry error 0.036 mm simulated, docs/results.md).
DEFAULT_CUTOFF_HZ = 2.0
SWITCH_INTERVAL_S = 0.0005
# ASSUMPTION: --mode preview stops previewing (plain from then on) when the measured force departs from the
# job's model by more than --preview-force-bound-N plus this fraction of the model's force (its scales may
# learn 0.3-2.0 times the coefficients: systems/preview_correction.SCALE_LIMITS).
FORCE_BOUND_FRACTION = 0.5
PROTOCOL_PORTS = {"egm": None, "rsi": None, "stream-motion": 60015}  # the controller's port when not given


def _link(protocol, listen_port, controller, period_s):
    if protocol == "egm":
        from robstiff_drake.cell.egm import EgmLink

        return EgmLink(listen_port, controller)
    if protocol == "rsi":
        from robstiff_drake.cell.rsi import RsiLink

        return RsiLink(listen_port, controller, period_s)
    from robstiff_drake.cell.stream_motion import StreamMotionLink

    return StreamMotionLink(listen_port, controller)


def run(*, listen_port, netft, robot_yaml=None, model, payload, reference=None, log=None, period_ms=4.0,
        sensor_rate_hz=1000.0, filter_kind="lowpass", cutoff_hz=DEFAULT_CUTOFF_HZ, filter_order=2, spindle_rpm=3600.0,
        max_jump_N=1000.0, max_jump_Nm=None, saturation_deg=0.5, rate_limit_deg_per_s=5.0, delay_steps=0,
        max_correction_mm=DEFAULT_MAX_CORRECTION_MM, max_correction_deg=DEFAULT_MAX_CORRECTION_DEG,
        netft_counts=None, netft_units=None, netft_http_port=80, netft_open_s=2.0,
        wait_s=30.0, duration_s=0.0, idle_exit_s=0.0,
        sensor_timeout_ms=20.0, rt_priority=0, cpu=None, cpu_latency_us=None, controller="127.0.0.1", protocol="egm",
        servo=None, cutter_diameter_mm=None, allow_unstable_loop=False, mode="plain", job=None, preview_sync_ms=25.0,
        preview_force_bound_N=150.0, reference_is_corrected=False, start_tolerance_N=None):
    from robstiff_drake.io import check_outputs
    from robstiff_drake.cell.sensor_checks import DEFAULT_START_TOLERANCE_N

    start_tolerance_N = DEFAULT_START_TOLERANCE_N if start_tolerance_N is None else start_tolerance_N

    # before the heavy imports (scipy, Drake): a wrong --log or a missing --job is refused at once
    check_outputs(inputs=[model, payload, reference, robot_yaml, job], folders={"--log": log})
    if reference_is_corrected and not reference:
        raise InputError(f"{CORRECTED_FLAG} says what --reference FILE is: give the corrected reference with it")
    if reference_is_corrected and mode == "preview":
        raise InputError(f"{CORRECTED_FLAG} holds the online correction at zero: --mode preview would have nothing "
                         "to add; stream the corrected reference in --mode plain, without --job")
    # a corrected reference (compensate-program's) streamed with online compensation corrects twice: refused here
    # (and again once a file waited for has appeared), before any socket is opened
    exists = reference and Path(reference).exists()
    correction_off = check_reference_claim(reference, reference_is_corrected) if exists else None
    if mode == "preview" and job is None:
        raise InputError("--mode preview needs --job SCENARIO.yaml (the job's program, tool, cutting model and "
                         "servo: the preview's plan)")
    if job is not None and mode != "preview":
        raise InputError(f"--job {job} is read only with --mode preview (plain compensation needs no plan)")
    from robstiff_drake.cell.compensate import CompensatorLoop, Reference
    from robstiff_drake.cell.loop_settings import LoopSettings
    from robstiff_drake.cell.link import parse_controller
    from robstiff_drake.cell.loop_guard import LoopGuard, feed_direction
    from robstiff_drake.cell.play_note import job_play, play_note, read_play
    from robstiff_drake.cell.rdt import NetFTReader, calibration_problem, parse_host_port
    from robstiff_drake.cell.run_log import StreamLog
    from robstiff_drake.cell.safety import pose_problem
    from robstiff_drake.diagrams.scenario_models import read_payload_calibration
    from robstiff_drake.model.compensator import Compensator
    from robstiff_drake.model.filters import filter_coefficients
    from robstiff_drake.model.realtime import DeflectionPredictor
    from robstiff_drake.model.robot import load_robot

    if netft_counts is not None or netft_units is not None:
        if netft_counts is None or netft_units is None:
            raise InputError("--netft-counts and --netft-units go together (the counts per force and per torque "
                             "unit, and those units, e.g. --netft-counts 1000000,1000 --netft-units N,N-mm)")
        problem = calibration_problem(netft_counts, netft_units)
        if problem:
            raise InputError(f"--netft-counts {','.join(f'{c:g}' for c in netft_counts)} --netft-units "
                             f"{','.join(netft_units)}: {problem}")
    ctrl = parse_controller(controller, PROTOCOL_PORTS[protocol])
    period_s = period_ms / 1e3
    if job is not None:
        from robstiff_drake.cell.preview_job import load_job

        sc_job, robot = load_job(job, robot_yaml, period_s=period_s)
    else:
        robot = load_robot(robot_yaml)
    check_axis_limits(robot)
    from robstiff_drake.commands.options import protocol_warning

    protocol_warning(robot, protocol)
    k = read_model(model, robot)
    play = read_play(json_doc(model, "--model"), f"--model {model}") or (job_play(sc_job, job) if job else None)
    try:
        cal = read_payload_calibration(payload)
    except RecursionError:
        raise InputError(f"--payload {payload}: nested too deeply to be a payload calibration") from None
    robot_line, robot_note = payload_robot_note(robot, cal, payload, robot_yaml)
    start_warnings = [line for line in (robot_line, payload_mass_note(robot, cal, payload),
                                       sensor_timeout_note(sensor_timeout_ms, sensor_rate_hz)) if line]
    for line in start_warnings:
        print(f"robstiff: warning: compensate: {line}", file=sys.stderr)
    if robot_note:
        info(f"robstiff: note: compensate: {robot_note}", file=sys.stderr)
    host, port = parse_host_port(netft)
    same = endpoint_clash(ctrl, parse_controller(f"{host}:{port}", what="--netft"), listen_port)
    if same:
        raise InputError(same)
    try:
        ba = filter_coefficients(filter_kind, cutoff_hz, filter_order, sensor_rate_hz, spindle_rpm)
    except ValueError as e:
        raise InputError(f"--cutoff-hz: {e}") from None
    plan = table_file = None
    if job is not None:
        from robstiff_drake.cell.preview_job import build_plan, job_reference

        def given():
            wait_for_file(reference, wait_s)
            check_reference_claim(reference, False)  # (preview: never a corrected reference)
            return read_reference(reference, robot, period_s)

        plan, table_file, t_ref, q_ref = job_reference(sc_job, robot, k, job=job, reference=reference,
                                                       read_reference=given, period_s=period_s, filter_ba=ba,
                                                       rate_hz=sensor_rate_hz, delay_steps=delay_steps, servo=servo)
        if plan is None and table_file is None:  # (no writable cache folder: computed here, before any socket)
            plan = build_plan(sc_job, robot, k, period_s=period_s, filter_ba=ba, rate_hz=sensor_rate_hz,
                              delay_steps=delay_steps, servo_option=servo)
        ref = Reference(t_ref, np.degrees(q_ref), period_s=period_s)
    elif reference:
        wait_for_file(reference, wait_s)
        correction_off = check_reference_claim(reference, reference_is_corrected)
        t_ref, q_ref = read_reference(reference, robot, period_s)
        ref = Reference(t_ref, np.degrees(q_ref, out=q_ref), period_s=period_s)  # (in place: a long path is large)
        del t_ref, q_ref
    else:
        ref = Reference(period_s=period_s)
    tool = robot.payload.tool_point_m
    # the loop model's stability check, before any socket is opened (with --reference: at its first row and at
    # poses along it; without, at the hold pose when the controller's first message gives it, while the loop
    # answers with zero correction)
    guard = LoopGuard(robot=robot, k_Nm_per_rad=k, servo=servo, sensor_rate_hz=sensor_rate_hz, period_s=period_s,
                      delay_steps=delay_steps, filter_kind=filter_kind, filter_ba=ba, cutoff_hz=cutoff_hz,
                      filter_order=filter_order, allow_unstable=allow_unstable_loop)
    if ref.q is not None:
        what = f"--job {Path(job).name}'s path" if job and not reference else f"--reference {Path(reference).name}"
        to_model = lambda q: robot.joint_map.to_model(np.radians(q))  # noqa: E731
        _say(guard.at(ref.q[0], f"{what}'s first row", feed_direction(robot, tool, ref.q, to_model=to_model)), guard)
        along = guard.along(ref.q, what, ref.t, to_model=to_model)  # (and along it: the drives tuned at its start)
        if along:
            _say(along, guard)
    # the gears' play the inputs carry: not compensated by the real-time chain; said once, with the twist ignored
    play_line, play_summary = play_note(robot, play, None if ref.q is None else ref.q[0], "the reference's first row")
    if play_line:
        print(f"robstiff: warning: compensate: {play_line}", file=sys.stderr)
    if max_jump_Nm is None:  # (the loop's default, said in summary.json: cell/loop_settings.py)
        from robstiff_drake.cell.loop_settings import default_max_jump_Nm

        max_jump_Nm = default_max_jump_Nm(max_jump_N, tool)
    predictor = DeflectionPredictor(robot.dh, k, tool)
    bound_line = None  # (the bound against the model's deflection under --max-jump-N along the reference: a warning)
    if ref.q is not None:
        from robstiff_drake.cell.correction_bound import start_note

        bound_line = start_note(predictor, ref.q, lambda q: robot.joint_map.to_model(np.radians(q)), max_jump_N,
                                max_correction_mm, max_correction_deg, "the reference")
        if bound_line:
            print(f"robstiff: warning: compensate: {bound_line}", file=sys.stderr)
    hold_said = []  # (without a reference: the bound's warning at the hold pose, from the start's work)
    link = _link(protocol, listen_port, ctrl, period_s)
    sensor = NetFTReader(host, port, counts=netft_counts, units=netft_units, http_port=netft_http_port)
    stream_log = background = remote = qos = None
    # a stop request once the loop has ended is held until the run's end is written (cell/end_hold.py)
    end_hold = EndHold()
    try:
        try:
            if ref.q is None:  # (the hold pose's check: its process started now, asked once the first message comes)
                remote = guard.elsewhere(robot_yaml)
            if job is not None and plan is None:
                # the table in a process of its own from now on (the sensor's start, the controller's first message
                # and the stream never wait for it: plain compensation until it is ready; cell/preview_job.py)
                from robstiff_drake.cell import preview_cache
                from robstiff_drake.cell.preview_job import BackgroundTable

                background = BackgroundTable(preview_cache.build_input(
                    job=job, robot_yaml=robot_yaml, k_Nm_per_rad=k, period_s=period_s, filter_ba=ba,
                    rate_hz=sensor_rate_hz, delay_steps=delay_steps, servo_option=servo, file=table_file), table_file)
            sensor.open(timeout_s=netft_open_s)
            good = [w for w, _, _, clipped in sensor.drain() if all(v == v for v in w) and not clipped]
            # the guard's and filter's start: the median of the first records (a spike among them moves a mean)
            w0 = np.median(good, axis=0) if good else np.zeros(6)
            comp = Compensator(predictor=predictor, calibration=cal, tool_m=tool, filter_ba=ba, max_jump_N=max_jump_N,
                               saturation_rad=math.radians(saturation_deg),
                               rate_limit_rad_per_s=math.radians(rate_limit_deg_per_s), delay_steps=delay_steps,
                               initial_wrench=w0)
            settings = LoopSettings(period_s=period_s, sensor_timeout_s=sensor_timeout_ms / 1e3,
                                    feedback_timeout_s=sensor_timeout_ms / 1e3, idle_exit_s=idle_exit_s,
                                    duration_s=duration_s, rate_limit_rad_per_s=math.radians(rate_limit_deg_per_s),
                                    saturation_deg=saturation_deg, max_jump_Nm=max_jump_Nm,
                                    max_correction_mm=max_correction_mm, max_correction_deg=max_correction_deg,
                                    correction_off=correction_off, sensor_rate_hz=sensor_rate_hz,
                                    start_tolerance_N=start_tolerance_N)
            c = sensor.calibration
            cal_text = (f"{c[0]:g} counts/{c[2]}, {c[1]:g} counts/{c[3]} ({'from the sensor' if c[4] == 'sensor' else 'override'})"
                        if c else "unknown")
            if log:
                from robstiff_drake.cell.settings_file import compensator_yaml
                from robstiff_drake.diagrams.run_inputs import kept_files

                kept = kept_files(robot, {"model": model, "payload": payload, "reference": reference, "job": job})
                stream_log = StreamLog(log, compensator_yaml(
                    robot=robot, robot_spec=robot_yaml, k=k, cal=cal, tool_m=tool, period_ms=period_ms,
                    delay_steps=delay_steps, filter_kind=filter_kind, cutoff_hz=cutoff_hz, filter_order=filter_order,
                    sensor_rate_hz=sensor_rate_hz, max_jump_N=max_jump_N, spindle_rpm=spindle_rpm,
                    saturation_deg=saturation_deg, rate_limit_deg_per_s=rate_limit_deg_per_s, servo=servo,
                    cutter_diameter_mm=cutter_diameter_mm, robot_ref=kept.robot, mode=mode), f"robot {robot.name}, model {model}",
                    inputs={rel: kept.sources[key].read_bytes() for key, rel in kept.names.items()})
            preview = None
            if job is not None:
                from robstiff_drake.cell.preview_table import PreviewDeflection

                def make_preview(p, plain=comp.model):
                    return PreviewDeflection(plain, p, sync_s=preview_sync_ms / 1e3,
                                             force_bound_N=preview_force_bound_N,
                                             force_bound_fraction=FORCE_BOUND_FRACTION)

                if plan is not None:
                    preview = comp.model = make_preview(plan)
                else:
                    background.then(make_preview)
            loop = CompensatorLoop(comp, link, sensor, ref, robot, settings, log=stream_log, preview=preview)
            loop.pending_preview = background
            loop.end_hold = end_hold
            where = f"{ctrl[0]}" + (f":{ctrl[1]}" if ctrl[1] else "")
            link.open()
            print(f"robstiff: compensate: sensor {host}:{port} streaming (calibration {cal_text}); waiting for "
                  f"{link.name} messages from {where} on UDP port {link.port}", file=sys.stderr, flush=True)
            loop.gc_token = gc_frozen = _quiet_gc()  # (the collector off: the loop collects after its answers)
            # the sensor's records come through pynetft's thread: let it have the interpreter within half a
            # millisecond when the loop is busy (the default switch interval, 5 ms, is longer than a cycle)
            switch = sys.getswitchinterval()
            sys.setswitchinterval(SWITCH_INTERVAL_S)
            qos = CpuLatency(cpu_latency_us)  # (held until the run ends: the finally below)
            for line in filter(None, (_pin_to_cpu(cpu), _realtime(rt_priority), qos.warning, qos.caution)):
                print(f"robstiff: warning: compensate: {line}", file=sys.stderr, flush=True)
                stream_log is not None and stream_log.event(0.0, 0.0, f"warning: {line}")
            for line in start_warnings if stream_log is not None else ():
                stream_log.event(0.0, 0.0, f"warning: {line}")  # (events.csv, as the other start warnings)
            first = loop.first_message(wait_s)
            q0 = first[0].joints_deg
            if ref.q is None:
                # the loop check at the hold pose (70-220 ms) runs off the real-time path while the loop answers with
                # zero correction, the controller's own pose (cell/start_gate.py): RSI expects each answer within its
                # cycle; the loop compensates once the check has passed
                ref.hold(q0)
                problem = pose_problem(robot, q0)
                if problem:
                    raise InputError(f"the hold pose (the controller's first message) is refused: {problem}")
                loop.start_jobs.append(("the loop check at the hold pose", lambda: _hold_check(remote, q0)))
                # and the correction bound against 1000 N's deflection there, as --reference's rows before the run
                loop.start_jobs.append(("the correction bound at the hold pose", lambda: _hold_bound(
                    hold_said, robot, k, q0, max_jump_N, max_correction_mm, max_correction_deg)))
            elif guard.warning and stream_log is not None:
                stream_log.event(0.0, 0.0, f"warning: {guard.warning}")  # (events.csv, before the first message's)
            off = np.abs(np.asarray(q0) - ref.q[0])
            if off.max() > START_TOLERANCE_DEG:
                j = int(np.argmax(off))
                named = f"--job {job}" if job and not reference else f"--reference {reference}"
                raise InputError(f"{named}: the robot is {off[j]:.3f} deg from the reference's start on joint {j + 1} "
                                 f"(at most {START_TOLERANCE_DEG:g}); move it there before streaming starts")
            try:
                loop.run(first)
            finally:
                _restore_gc(gc_frozen)
                sys.setswitchinterval(switch)
        finally:
            if qos is not None:
                qos.release()  # (the CPUs idle as before: the request withdrawn however the run ended)
            if background is not None:
                background.stop()
            if remote is not None:
                remote.close()
            sensor.close()
            link.close()
        bound_line = bound_line or (hold_said[0] if hold_said else None)
        report(loop, link, guard, background, stream_log, log=log, job=job, inputs=dict(
            protocol=protocol, controller=where, netft=f"{host}:{port}", netft_calibration=c, robot=robot.name,
            model=str(model), payload=str(payload), reference=str(reference) if reference else None,
            joint_stiffness_Nm_per_rad=k, settings={
                "period_ms": period_ms, "sensor_rate_hz": sensor_rate_hz, "filter_kind": filter_kind,
                "cutoff_hz": cutoff_hz, "filter_order": filter_order, "max_jump_N": max_jump_N,
                "max_jump_Nm": max_jump_Nm, "saturation_deg": saturation_deg,
                "rate_limit_deg_per_s": rate_limit_deg_per_s, "delay_steps": delay_steps,
                "max_correction_mm": max_correction_mm, "max_correction_deg": max_correction_deg,
                "sensor_timeout_ms": sensor_timeout_ms, "start_tolerance_N": start_tolerance_N},
            mode=mode, job=str(job) if job else None,
            # (what the loop asked of the machine, and what it was given: a wish not allowed says so in the events)
            scheduling={"rt_priority": rt_priority, "cpu": cpu, "cpu_latency_us": cpu_latency_us,
                        # (held: asked, and no warning that it was not; released by now)
                        "cpu_latency_held": qos is not None and cpu_latency_us is not None and qos.warning is None,
                        "cpu_latency_caution": qos.caution if qos is not None else None},
            # (None: the correction computed online; else why it was held at zero: a corrected reference)
            correction_held_at_zero=correction_off), notes=(play_line, play_summary, bound_line, start_warnings),
            missing=(servo, cutter_diameter_mm))
    finally:
        end_hold.release()
        if end_hold.said():  # (on every path: a refused start's error line follows it)
            print(f"robstiff: compensate: {end_hold.said()}", file=sys.stderr)
    return 0


def _hold_check(remote, q0):
    """The loop check at the hold pose (a start job: cell/start_gate.py, the
    check itself in the process cell/loop_guard.RemoteCheck started); its
    refusal says that only zero correction was answered."""
    guard = remote.guard
    try:
        line = remote.at(q0, "the hold pose, the controller's first message")
    except InputError as e:
        raise InputError(str(e).replace("; nothing was sent", "; nothing but zero correction (the controller's own "
                                        "pose) was answered")) from None
    _say(line, guard)
    return f"warning: {guard.warning}" if guard.warning else None


def _hold_bound(said, robot, k, q0, force_N, max_mm, max_deg):
    """The correction bound's check at the hold pose (a start job: cell/
    start_gate.py, beside the loop's thread): a warning for the log's events
    (and ``said``, for summary.json) where ``force_N`` would deflect the tool
    beyond the bound there, as --reference's before the run (a note: not
    in the summary's list of faults and events, as that one)."""
    from robstiff_drake.cell.correction_bound import hold_note
    from robstiff_drake.cell.start_gate import StartNote

    line = hold_note(robot, k, q0, force_N, max_mm, max_deg)
    if line:
        said.append(line)
        return StartNote(f"warning: {line}")  # (as --reference's: a warning, not among the run's faults)
    return None


def _say(line, guard):
    """The loop check's line: a warning when --allow-unstable-loop ran an unstable loop, else information."""
    if guard.warning:
        print(f"robstiff: warning: compensate: {line}", file=sys.stderr, flush=True)
    else:
        info(f"robstiff: compensate: {line}", file=sys.stderr)
