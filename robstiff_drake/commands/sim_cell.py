"""``robstiff sim-cell SCENARIO.yaml --egm-to HOST:PORT --netft-port PORT``:
the scenario's Drake station (robot, drives, spindle, workpiece, wrist
sensor) as a real cell looks from the compensator's PC: a robot controller
(an IRC5 over EGM, a KUKA over RSI or a FANUC over Stream Motion) sending
joint feedback every cycle and following the joint targets it gets back,
with a controller's supervision (a target outside the working ranges or
a step faster than the axis speeds stops it), and an ATI Net F/T
streaming RDT records with its calibration page.

Order: the station is built, the network listens, then the path's joint
reference is written (``--reference-out``: its appearance tells a waiting
`compensate` that the cell is up); the controller waits at rest up to
``--wait-s`` for the compensator's first answer, then cuts the pass and
reports the machined surface (the simulation's truth) and the run's
health."""

import threading
import time
from pathlib import Path

import numpy as np

from robstiff_drake.errors import InputError
from robstiff_drake.io import Warnings, check_outputs, emit_json, write_atomic
from robstiff_drake.progress import wrote

# The simulated controller's exit status when its supervision stopped the
# run (a refused target) or the compensator stopped answering mid-cut.
EXIT_FAULT = 3


def _controller_link(protocol, host, port, period_s):
    if protocol == "egm":
        from robstiff_drake.cell.egm import ControllerLink

        return ControllerLink(host, port)
    if protocol == "rsi":
        from robstiff_drake.cell.rsi import RsiControllerLink

        return RsiControllerLink(host, port, period_s)
    from robstiff_drake.cell.stream_motion import StreamMotionControllerLink

    return StreamMotionControllerLink(host, port)


def run(*, scenario, egm_to, netft_port, wait_s=30.0, reference_out=None, json_out=None, robot_yaml=None,
        period_ms=None, lockstep=False, protocol="egm", netft_http_port=None, netft_units=("N", "N-m"),
        transport_delay_cycles=None, scan_out=None, answer_timeout_s=1.0):
    from robstiff_drake.cell.health import verdict
    from robstiff_drake.cell.pass_check import FOLLOW_TOL_DEG, left_path
    from robstiff_drake.cell.rdt import parse_host_port
    from robstiff_drake.cell.sim_cell import CellNetwork
    from robstiff_drake.diagrams.cell_station import CellStation
    from robstiff_drake.diagrams.run_vibration import cell_vibration, vibration_warnings
    from robstiff_drake.diagrams.scenario import load_scenario, scenario_robot

    check_outputs(inputs=[scenario, robot_yaml], files={"--reference-out": reference_out, "--json": json_out,
                                                        "--scan-out": scan_out})
    if ":" not in str(egm_to):
        raise InputError(f"--egm-to {egm_to!r}: expected HOST:PORT (the compensator's --listen-port; for "
                         "Stream Motion the port this controller listens on)")
    host, port = parse_host_port(egm_to, what="--egm-to")
    sc = load_scenario(scenario)
    robot = scenario_robot(sc, robot_yaml)
    from robstiff_drake.commands.options import protocol_warning

    protocol_warning(robot, protocol)
    if robot.speed_limit_deg_per_s is None:
        raise InputError(f"{robot.source}: key 'joint_limits.speed_deg_per_s': missing; the simulated controller's "
                         "supervision needs the axis speeds")
    # would the cut chatter? (the cell's station leaves the regenerative chip out: diagrams/chatter_check.py)
    from robstiff_drake.diagrams.chatter_check import check_job

    warnings = Warnings()
    chatter = check_job(sc, robot, warnings)
    # the controller's cycle: the scenario's (its controller.period_ms, the period its joint reference, its
    # transport delay and its `simulate` run are for), unless --period-ms says otherwise (then a warning: a
    # FANUC R-30iB Plus streams J519 every 8 ms where the packaged scenarios' 4 ms is an IRC5's EGM)
    scenario_ms = float(sc.controller.period_ms)
    if period_ms is None:
        period_ms = scenario_ms
    elif abs(float(period_ms) - scenario_ms) > 1e-9:
        warnings.add(f"sim-cell: --period-ms {float(period_ms):g} differs from {scenario} controller.period_ms "
                     f"{scenario_ms:g}: the cell runs at {float(period_ms):g} ms, the scenario's transport delay "
                     f"(controller.delay_steps {int(sc.controller.delay_steps)}) counts these cycles, and "
                     f"`compensate` must run with --period-ms {float(period_ms):g}")
    T = period_ms / 1e3
    station = CellStation(sc, robot, period_s=T)
    limits = (np.degrees(robot.q_lower_rad), np.degrees(robot.q_upper_rad), robot.speed_limit_deg_per_s,
              robot.acceleration_limit_deg_per_s2)
    # the scenario's transport delay (controller.delay_steps: "one period of transport delay") is the
    # simulated controller's: it acts on the answer to a message that many cycles after the next tick, as
    # the diagram's compensator delays its correction; `compensate` then runs with --delay-steps 0
    if transport_delay_cycles is None:
        transport_delay_cycles = int(sc.controller.delay_steps)
    link = _controller_link(protocol, host, port, T)
    net = CellNetwork(station, egm_to=(host, port), netft_port=netft_port, period_s=T, lockstep=lockstep,
                      limits=limits, netft_http_port=netft_port if netft_http_port is None else netft_http_port,
                      netft_units=netft_units, link=link, transport_delay_cycles=transport_delay_cycles,
                      answer_timeout_s=answer_timeout_s)
    # in lockstep the pass may run slower than real time: allow ten times it
    run_s = wait_s + station.t_end * (10.0 if lockstep else 1.0) + 5.0
    th = None
    try:
        th = threading.Thread(target=net.run, daemon=True,
                              args=(run_s, robot.joint_map.to_controller(station.q_ref[0])))
        th.start()
        if reference_out is not None:  # the cell is up: its reference tells a waiting compensator so
            write_atomic(reference_out, station.reference_csv())
        t0 = time.monotonic()
        while th.is_alive():
            if station.done or (not station.times and time.monotonic() - t0 > wait_s):
                net.stop = True
            th.join(0.05)
    finally:
        # (a signal or an error here: the network thread ends its tick before its sockets close and before
        # the interpreter exits; closed under it, its select raised on fd -1, and Drake's simulator torn
        # down mid-step aborted the process)
        net.stop = True
        if th is not None:
            th.join(10.0)
        net.close()
    if not station.times:
        raise InputError(f"sim-cell: no compensator answered the {link.name} messages sent to {host}:{port} within "
                         f"{wait_s:g} s (is `robstiff compensate --listen-port {port}` running?)")
    stats = net.stats
    status = 0
    if stats.stop_reason:
        warnings.add(f"the simulated controller stopped at t = {stats.t_stop:.3f} s of the cut: {stats.stop_reason}")
        status = EXIT_FAULT
    elif not station.done:
        warnings.add(f"the compensator stopped answering after {stats.last_answer_t:.2f} s of the "
                     f"{station.t_end:.2f} s pass: the surface is of the part cut so far")
        status = EXIT_FAULT
    if stats.late_ticks and not lockstep:
        warnings.add(f"{stats.late_ticks} of {stats.cycles} cycles were more than half a period late (this machine "
                     "is busy: the simulated controller is not hard real-time)")
    # did the cut itself vibrate? (simulate's check, on the link angles the station logs once per cycle)
    vib = cell_vibration(station)
    warnings.extend_from(vibration_warnings({"sim-cell": vib}, sc))
    scans, surface = station.surface()
    cut = "mean" in surface
    if scan_out is not None and cut:
        write_atomic(scan_out, station.scan_csv(scans))
    if not cut:
        warnings.add("no face was cut (the run stopped before the cutter reached the part)")
    # did the arm travel the pass? (every answer fresh says nothing of where its targets took the arm: a compensator
    # holding the start, or playing the reference at half speed, was "health GOOD"; cell/pass_check.py)
    n_eng = len(station.times)
    q_eng = np.degrees(np.asarray(stats.q_cmd[-n_eng:], dtype=float)) if n_eng else np.zeros((0, 6))
    q_ref = np.degrees([robot.joint_map.to_controller(q) for q in station.q_ref])
    off = left_path(np.asarray(station.times) - T, q_eng, station.t_ref, q_ref)
    partial = ""
    if off is not None:
        partial = (f"the arm did not travel the pass: its target q{off[2] + 1} was {off[1]:.2f} deg from the path's "
                   f"reference at t = {off[0]:.3f} s, more than a correction ({FOLLOW_TOL_DEG:g} deg), and its last "
                   f"target is the reference's of t = {off[3]:.2f} s of the {station.t_ref[-1]:.2f} s path (a "
                   f"compensator at another --period-ms than this controller's {period_ms:g} ms, or streaming "
                   "another reference?)")
        warnings.add(f"sim-cell: {partial}")
        status = EXIT_FAULT  # (as a pass the compensator stopped answering in)
    lost = stats.lost_fraction()
    word, reasons, line = verdict(cycles=stats.cycles, answered=stats.answered, late=stats.late_answers,
                                  unanswered=stats.unanswered, faults=int(bool(stats.stop_reason)),
                                  lost_fraction=lost, refused=stats.refused,
                                  stopped=stats.stop_reason or ("" if station.done else "the pass was not finished")
                                  or partial,
                                  # a held target jerks the arm through the servo's velocity feed-forward: one
                                  # or two held cycles moved the short block's face by 1-18 um (docs/real_cell.md)
                                  unanswered_good=0.0,
                                  seen=f"seen of the compensator: {stats.answered} fresh answers, {stats.late_answers} "
                                       f"late, {stats.unanswered} missing; its corrections, not why it ramped "
                                       "them down (its own faults: compensate's verdict)")
    if word != "good":
        warnings.add(f"sim-cell: {line}")
    res = {"scenario": str(Path(scenario)), "robot": robot.name, "protocol": protocol,
           "surface_error_mm": surface if cut else None, "cycles": stats.cycles, "answered": stats.answered,
           "late": stats.late_answers, "unanswered": stats.unanswered, "late_ticks": stats.late_ticks,
           "skipped_ticks": stats.skipped_ticks, "targets_refused": stats.refused,
           "stopped": stats.stop_reason or None,
           "pass_left_path": None if off is None else {"t_s": off[0], "deviation_deg": off[1], "joint": off[2] + 1,
                                                       "last_target_at_reference_t_s": off[3]},
           "t_stop_s": stats.t_stop if stats.stop_reason else None,
           "last_answer_s": stats.last_answer_t, "sim_seconds": station.times[-1], "lockstep": bool(lockstep),
           "transport_delay_cycles": net.delay_cycles,
           "station_step_ms": {"median": float(np.median(stats.step_ms)) if stats.step_ms else None,
                               "p99": float(np.percentile(stats.step_ms, 99)) if stats.step_ms else None},
           "tick_late_ms": {"median": float(np.median(stats.tick_error_s) * 1e3) if stats.tick_error_s else None,
                            "p99": float(np.percentile(stats.tick_error_s, 99) * 1e3) if stats.tick_error_s else None},
           "health": {"verdict": word, "reasons": reasons, "compensation_lost_fraction": lost, "line": line,
                      "seen_of_the_other_side": {"fresh_answers": stats.answered, "late_answers": stats.late_answers,
                                                 "missing_answers": stats.unanswered}},
           "chatter_check": chatter, "vibration": vib, "warnings": list(warnings)}
    if json_out is not None:
        emit_json(res, json_out)
    if json_out != "-":
        if cut:
            s = surface
            print(f"{sc.name}: machined surface over {link.name} and RDT (mm, + = cut more): mean {s['mean']:+.4f}, "
                  f"rms {s['rms']:.4f}, max|e| {s['max_abs']:.4f}, PV {s['pv']:.4f}")
        print(f"{stats.cycles} cycles, {stats.answered} answered, {stats.late_answers} late, {stats.unanswered} "
              f"unanswered, {stats.late_ticks} late ticks; {line}")
    wrote(reference_out, "the path's joint reference (compensate --reference)", to_stderr=json_out == "-")
    wrote(scan_out if cut else None, "the scan of the cut face (diagnose-run --scan)", to_stderr=json_out == "-")
    wrote(json_out, to_stderr=json_out == "-")
    return status


