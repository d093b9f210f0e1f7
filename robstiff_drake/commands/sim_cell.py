"""``robstiff sim-cell SCENARIO.yaml --egm-to HOST:PORT --netft-port PORT``:
the scenario's Drake station (robot, drives, spindle, workpiece, wrist
sensor) as a real cell looks from the compensator's PC: an IRC5 sending
EGM joint feedback every cycle and following the joint targets it gets
back, and an ATI Net F/T streaming RDT records.  It waits at rest until the
compensator answers, then cuts the scenario's pass in real time and
reports the machined surface (the simulation's truth)."""

import threading
import time
from pathlib import Path

from robstiff_drake.cell.sim_cell import CellNetwork
from robstiff_drake.cell.rdt import parse_host_port
from robstiff_drake.diagrams.cell_station import CellStation
from robstiff_drake.diagrams.scenario import load_scenario, scenario_robot
from robstiff_drake.errors import InputError
from robstiff_drake.io import Warnings, check_outputs, emit_json, write_atomic
from robstiff_drake.progress import wrote


def run(*, scenario, egm_to, netft_port, wait_s=30.0, reference_out=None, json_out=None, robot_yaml=None,
        period_ms=4.0, lockstep=False):
    check_outputs(inputs=[scenario, robot_yaml], files={"--reference-out": reference_out, "--json": json_out})
    if ":" not in str(egm_to):
        raise InputError(f"--egm-to {egm_to!r}: expected HOST:PORT (the compensator's --egm-port)")
    host, port = parse_host_port(egm_to, what="--egm-to")
    sc = load_scenario(scenario)
    robot = scenario_robot(sc, robot_yaml)
    station = CellStation(sc, robot, period_s=period_ms / 1e3)
    if reference_out is not None:
        write_atomic(reference_out, station.reference_csv())
    net = CellNetwork(station, egm_to=(host, port), netft_port=netft_port, period_s=period_ms / 1e3,
                      lockstep=lockstep)
    # in lockstep the pass may run slower than real time: allow ten times it
    run_s = wait_s + station.t_end * (10.0 if lockstep else 1.0) + 5.0
    warnings = Warnings()
    try:
        th = threading.Thread(target=net.run, daemon=True,
                              args=(run_s, robot.joint_map.to_controller(station.q_ref[0])))
        th.start()
        t0 = time.monotonic()
        while th.is_alive():
            if station.done or (not station.times and time.monotonic() - t0 > wait_s):
                net.stop = True
            th.join(0.05)
    finally:
        net.close()
    if not station.times:
        raise InputError(f"sim-cell: no compensator answered the EGM messages sent to {host}:{port} within "
                         f"{wait_s:g} s (is `robstiff compensate --egm-port {port}` running?)")
    if not station.done:
        warnings.add(f"the compensator stopped answering after {station.times[-1]:.2f} s of the "
                     f"{station.t_end:.2f} s pass: the surface is of the part cut so far")
    stats = net.stats
    if stats.late_ticks and not lockstep:
        warnings.add(f"{stats.late_ticks} of {stats.cycles} cycles were more than half a period late (this machine "
                     "is busy: the simulated controller is not hard real-time)")
    _, surface = station.surface()
    res = {"scenario": str(Path(scenario)), "robot": robot.name, "surface_error_mm": surface,
           "cycles": stats.cycles, "answered": stats.answered, "unanswered": stats.unanswered,
           "late_ticks": stats.late_ticks, "skipped_ticks": stats.skipped_ticks,
           "sim_seconds": station.times[-1], "lockstep": bool(lockstep), "warnings": list(warnings)}
    if json_out is not None:
        emit_json(res, json_out)
    if json_out != "-":
        s = surface
        print(f"{sc.name}: machined surface over EGM and RDT (mm, + = cut more): mean {s['mean']:+.4f}, "
              f"rms {s['rms']:.4f}, max|e| {s['max_abs']:.4f}, PV {s['pv']:.4f}")
        print(f"{stats.cycles} cycles, {stats.answered} answered, {stats.unanswered} unanswered, "
              f"{stats.late_ticks} late")
    wrote(reference_out, "the path's joint reference (compensate --reference)", to_stderr=json_out == "-")
    wrote(json_out, to_stderr=json_out == "-")
    return 0
