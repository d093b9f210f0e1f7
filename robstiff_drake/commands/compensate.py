"""``robstiff compensate``: the compensator as a process between an ABB
controller (EGM, UDP) and an ATI Net F/T (RDT, UDP), running the chain of
the simulated cell (model/compensator.py) on the real signals.

    robstiff compensate --egm-port 6510 --netft 192.168.1.1 --robot ROBOT
        --model identified.json --payload payload.yaml --reference joints.csv --log run1

Inputs are checked, the sensor's stream started and the controller's first
message awaited before the loop; anything wrong there is one line and exit
status 2.  During the loop, faults are logged and ramp the correction to
zero (cell/compensate.py).  Ctrl-C (or --duration-s, or a controller that
stays silent for --idle-exit-s) ends the run; the log folder is written
then, as a whole.
"""

import json
import math
import sys
from pathlib import Path

import numpy as np

from robstiff_drake.cell.compensate import CompensatorLoop, LoopLog, LoopSettings, Reference, cycle_stats
from robstiff_drake.cell.egm import SensorLink
from robstiff_drake.cell.rdt import NetFTReader, parse_host_port
from robstiff_drake.cell.run_log import write_log
from robstiff_drake.diagrams.scenario import checked_joint_stiffness, numbers, read_payload_calibration
from robstiff_drake.errors import InputError, excerpt
from robstiff_drake.io import RunFolder, check_outputs
from robstiff_drake.model.compensator import Compensator
from robstiff_drake.model.filters import filter_coefficients
from robstiff_drake.model.realtime import DeflectionPredictor
from robstiff_drake.model.robot import load_robot
from robstiff_drake.progress import wrote

# How far the first joint feedback may be from the reference's start (deg)
# before the run is refused: the robot must be brought to the path's start
# (MoveAbsJ) before EGMRunJoint, or the first target would jump.
START_TOLERANCE_DEG = 0.5
# A model whose nominal stiffness differs from the robot file's by more
# than this (relative) was identified against another robot file.
NOMINAL_TOLERANCE = 1e-6


def read_model(path, robot):
    """The compensator's joint stiffness (N*m/rad) from `robstiff identify
    --json`'s file; InputError if it is not one, or is for another robot."""
    path = Path(path)
    try:
        doc = json.loads(path.read_bytes().decode("utf-8-sig"))
    except OSError as e:
        raise InputError(f"--model {path}: cannot read ({e.strerror})") from None
    except (UnicodeDecodeError, ValueError) as e:
        raise InputError(f"--model {path}: not a JSON file ({e})") from None
    if not isinstance(doc, dict) or "joint_stiffness_Nm_per_rad" not in doc:
        raise InputError(f"--model {path}: no joint_stiffness_Nm_per_rad (write it with `robstiff identify DATA.csv "
                         "--json OUT`)")
    name = doc.get("robot")
    if name is not None and name != robot.name:
        raise InputError(f"--model {path}: identified for the robot {name!r}, not for {robot.name!r} ({robot.source})")
    nominal = doc.get("joint_stiffness_nominal_Nm_per_rad")
    if nominal is not None:
        nom = numbers(nominal)  # None for text, a dict or a ragged list
        if nom is None or nom.shape != (6,):
            raise InputError(f"--model {path}: joint_stiffness_nominal_Nm_per_rad: expected six numbers, got "
                             f"{excerpt(nominal)}")
        if not np.allclose(nom, robot.joint_stiffness_Nm_per_rad, rtol=NOMINAL_TOLERANCE, atol=0):
            raise InputError(f"--model {path}: identified against another robot file (its nominal stiffness "
                             f"{np.round(nom, 0).tolist()} is not {robot.name}'s "
                             f"{np.round(robot.joint_stiffness_Nm_per_rad, 0).tolist()} N*m/rad)")
    return checked_joint_stiffness(doc["joint_stiffness_Nm_per_rad"], where=f"--model {path}")


def read_reference(path, robot):
    """(times s, q (N, 6) rad) of a joint reference CSV: columns t_s,
    q1_deg .. q6_deg (header first; '#' lines are comments), times
    increasing, angles inside the robot's joint limits."""
    path = Path(path)
    try:
        lines = path.read_bytes().decode("utf-8-sig").splitlines()
    except OSError as e:
        raise InputError(f"--reference {path}: cannot read ({e.strerror})") from None
    except UnicodeDecodeError:
        raise InputError(f"--reference {path}: not UTF-8 text") from None
    want = ["t_s"] + [f"q{j}_deg" for j in range(1, 7)]
    header, idx, rows = None, None, []
    for n, line in enumerate(lines, 1):
        s = line.strip()
        if not s or s.startswith("#"):
            continue
        cells = [c.strip() for c in s.split(",")]
        if header is None:
            header = cells
            missing = [c for c in want if c not in header]
            if missing:
                raise InputError(f"{path}:{n}: missing column {missing[0]} (expected {', '.join(want)})")
            idx = [header.index(c) for c in want]
            continue
        if len(cells) != len(header):
            raise InputError(f"{path}:{n}: {len(cells)} fields, the header has {len(header)}")
        try:
            v = [float(cells[i]) for i in idx]
        except ValueError:
            raise InputError(f"{path}:{n}: not a number in {', '.join(cells[i] for i in idx)}") from None
        if not all(math.isfinite(x) for x in v):
            raise InputError(f"{path}:{n}: not a finite number")
        if rows and v[0] <= rows[-1][0]:
            raise InputError(f"{path}:{n}: t_s {v[0]:g} is not after the previous row's {rows[-1][0]:g}")
        rows.append(v)
    if len(rows) < 1:
        raise InputError(f"--reference {path}: no rows")
    a = np.array(rows)
    q = np.radians(a[:, 1:])
    bad = (q < robot.q_lower_rad - 1e-9) | (q > robot.q_upper_rad + 1e-9)
    if bad.any():
        i, j = np.argwhere(bad)[0]
        raise InputError(f"--reference {path}: row {i + 1}: q{j + 1} = {a[i, j + 1]:g} deg is outside "
                         f"{robot.name}'s joint limits")
    return a[:, 0] - a[0, 0], q


def run(*, egm_port, netft, robot_yaml=None, model, payload, reference=None, log=None, period_ms=4.0,
        sensor_rate_hz=1000.0, filter_kind="lowpass", cutoff_hz=10.0, filter_order=2, spindle_rpm=3600.0,
        max_jump_N=1000.0, saturation_deg=0.5, rate_limit_deg_per_s=5.0, delay_steps=0, netft_counts=None,
        wait_s=30.0, duration_s=0.0, idle_exit_s=0.0, sensor_timeout_ms=20.0, rt_priority=0):
    check_outputs(inputs=[model, payload, reference, robot_yaml], folders={"--log": log})
    robot = load_robot(robot_yaml)
    k = read_model(model, robot)
    cal = read_payload_calibration(payload)
    ref = Reference(*read_reference(reference, robot)) if reference else Reference()
    host, port = parse_host_port(netft)
    try:
        ba = filter_coefficients(filter_kind, cutoff_hz, filter_order, sensor_rate_hz, spindle_rpm)
    except ValueError as e:
        raise InputError(f"--cutoff-hz: {e}") from None
    tool = robot.payload.tool_point_m
    predictor = DeflectionPredictor(robot.dh, k, tool)
    counts = netft_counts or (1_000_000.0, 1_000_000.0)
    link = SensorLink(egm_port)
    sensor = NetFTReader(host, port, counts[0], counts[1])
    try:
        sensor.open(timeout_s=2.0)
        first_records = sensor.drain()
        good = [w for w, _, st in first_records if all(v == v for v in w)]
        w0 = np.mean(good, axis=0) if good else np.zeros(6)
        comp = Compensator(predictor=predictor, calibration=cal, tool_m=tool, filter_ba=ba, max_jump_N=max_jump_N,
                           saturation_rad=math.radians(saturation_deg),
                           rate_limit_rad_per_s=math.radians(rate_limit_deg_per_s), delay_steps=delay_steps,
                           initial_wrench=w0)
        settings = LoopSettings(period_s=period_ms / 1e3, sensor_timeout_s=sensor_timeout_ms / 1e3,
                                feedback_timeout_s=sensor_timeout_ms / 1e3, idle_exit_s=idle_exit_s,
                                duration_s=duration_s, rate_limit_rad_per_s=math.radians(rate_limit_deg_per_s))
        loop = CompensatorLoop(comp, link, sensor, ref, settings, log=LoopLog())
        print(f"robstiff: compensate: sensor {host}:{port} streaming; waiting for the controller on UDP port "
              f"{egm_port}", file=sys.stderr, flush=True)
        gc_frozen = _quiet_gc()
        _realtime(rt_priority)
        first = loop.first_message(wait_s)
        q0 = first[4]
        if ref.q is None:
            ref.hold(q0)
        off = np.degrees(np.abs(q0 - ref.q[0]))
        if off.max() > START_TOLERANCE_DEG:
            j = int(np.argmax(off))
            raise InputError(f"--reference {reference}: the robot is {off[j]:.3f} deg from the reference's start on "
                             f"joint {j + 1} (at most {START_TOLERANCE_DEG:g}); move it there (MoveAbsJ) before "
                             "EGMRunJoint")
        log_data = loop.run(first)
        _restore_gc(gc_frozen)
    finally:
        sensor.close()
        link.close()
    stats = cycle_stats(log_data, period_ms / 1e3)
    c = stats["compute_ms"]
    print(f"robstiff: compensate: {stats['messages']} messages; computation per message median {c['median']:.3f} ms, "
          f"p99 {c['p99']:.3f} ms, max {c['max']:.3f} ms; correction age median "
          f"{stats['correction_age_ms']['median']:.2f} ms; missed cycles {stats['missed_cycles']}; "
          f"{len(stats['faults'])} fault events", file=sys.stderr)
    if log:
        summary = {"command": "compensate", "egm_port": egm_port, "netft": f"{host}:{port}", "robot": robot.name,
                   "model": str(model), "payload": str(payload), "reference": str(reference) if reference else None,
                   "joint_stiffness_Nm_per_rad": k, "settings": {
                       "period_ms": period_ms, "sensor_rate_hz": sensor_rate_hz, "filter_kind": filter_kind,
                       "cutoff_hz": cutoff_hz, "filter_order": filter_order, "max_jump_N": max_jump_N,
                       "saturation_deg": saturation_deg, "rate_limit_deg_per_s": rate_limit_deg_per_s,
                       "delay_steps": delay_steps, "sensor_timeout_ms": sensor_timeout_ms},
                   "cycles": stats}
        with RunFolder(log) as run_folder:
            written = write_log(run_folder, log_data, comp.model, summary, f"robot {robot.name}, model {model}")
        wrote(log, ", ".join(written), folder=True, to_stderr=True)
    return 0


def _realtime(priority):
    """Run the loop's thread under SCHED_FIFO at ``priority`` (1-99), as a
    real-time PC would; 0: leave the scheduling alone.  Not permitted (no
    privilege): a warning, and the loop runs anyway."""
    if not priority:
        return
    import os

    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(int(priority)))
    except (AttributeError, PermissionError, OSError) as e:
        print(f"robstiff: warning: --rt-priority {priority}: cannot switch to real-time scheduling ({e}); running "
              "without it", file=sys.stderr)


def _quiet_gc():
    """Freeze the objects made so far out of the garbage collector's reach
    (fewer and shorter collection pauses in the loop)."""
    import gc

    gc.collect()
    gc.freeze()
    return True


def _restore_gc(frozen):
    import gc

    if frozen:
        gc.unfreeze()
