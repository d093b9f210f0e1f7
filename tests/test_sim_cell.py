"""`robstiff sim-cell`: the Drake station behind the real cell's protocols.

Two checks against what the cell adapter did not produce: the adapter,
stepped one EGM cycle at a time with the path's own targets, cuts the same
surface as the closed-loop diagram that commands the station inside Drake;
and `robstiff compensate` (a separate process, over EGM and Net F/T on the
loopback interface) removes most of the deflection the station's physics
(Drake's plant, the gears' lost motion, the servo) puts on the part.
"""

import json
import os
import subprocess
import sys
import threading

import numpy as np
import pytest

from cell_helpers import FORCE_BIAS_N, HANG_GUARD_S, ROOT, TORQUE_BIAS_NM, free_udp_port, \
    run_compensate_until_cell_done, write_inputs
from robstiff_drake.diagrams.cell_record import servo_settings
from robstiff_drake.diagrams.cell_station import CellStation
from robstiff_drake.identification.runs.settings import SERVO_KEYS
from robstiff_drake.diagrams.experiment import run_cut
from robstiff_drake.diagrams.scenario import load_scenario
from robstiff_drake.model.robot import load_robot

SHORT = os.path.join(ROOT, "tests", "data", "short_block.yaml")
# the same pass on the KUKA (its A3 offset by -90 deg) and the FANUC (its J3 measured from the horizontal):
# robot files with a `controller:` map between the controller's angles and the model's
OTHER_ROBOTS = {name: os.path.join(ROOT, "tests", "data", f"short_block_{name}.yaml")
                for name in ("kr240_r2900", "r2000ic_165f")}


@pytest.fixture(scope="module")
def short():
    sc = load_scenario(SHORT)
    robot = load_robot()
    return sc, robot, run_cut(sc, robot, compensation=False).surface_error_mm


@pytest.fixture(scope="module")
def short_compensated(short):
    sc, robot, _ = short
    return run_cut(sc, robot, compensation=True)


def test_stepped_station_cuts_what_the_diagram_cuts(short):
    sc, robot, diagram = short
    st = CellStation(sc, robot, period_s=sc.controller.period_ms / 1e3)
    ctrl = robot.joint_map.to_controller
    while not st.done:
        t = st.sim.get_context().get_time() + st.T
        q = np.array([np.interp(t, st.t_ref, st.q_ref[:, j]) for j in range(6)])
        st.step(ctrl(q))
    _, adapter = st.surface()
    # the same plant, forces and commands: the targets differ only in being
    # held per 4 ms cycle here and interpolated by the station in the
    # diagram (a few micrometres)
    assert adapter["mean"] > 0.05, adapter
    assert abs(adapter["mean"] - diagram["mean"]) < 0.05 * abs(diagram["mean"]) + 0.003, (adapter, diagram)
    assert abs(adapter["pv"] - diagram["pv"]) < 0.15 * diagram["pv"] + 0.005, (adapter, diagram)


def _sim_cell(tmp_path, *, egm_port, netft_port, lockstep, scenario=SHORT, extra=()):
    ref = tmp_path / "cell_reference.csv"
    out = tmp_path / "cell.json"
    cell = subprocess.Popen([sys.executable, "-m", "robstiff_drake", "sim-cell", scenario,
                             "--egm-to", f"127.0.0.1:{egm_port}", "--netft-port", str(netft_port),
                             "--reference-out", str(ref), "--json", str(out), "--wait-s", f"{HANG_GUARD_S * 5:g}"]
                            + (["--lockstep"] if lockstep else []) + list(extra),
                            cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    return cell, ref, out


def _read_log(path):
    lines = [line for line in open(path) if not line.startswith("#")]
    names = lines[0].strip().split(",")
    data = np.array([[float(v) if v else np.nan for v in line.strip().split(",")] for line in lines[1:]])
    return {n: data[:, i] for i, n in enumerate(names)}


@pytest.mark.parametrize("lockstep", [True, False], ids=["lockstep", "real-time"])
def test_compensate_over_the_protocols_against_the_drake_station(tmp_path, short, short_compensated, lockstep):
    sc, robot, plain = short
    model, payload, _, _ = write_inputs(str(tmp_path), robot)
    # the payload calibration's bias is the scenario's sensor bias
    assert np.allclose(sc.sensor.force_bias_N, FORCE_BIAS_N) and np.allclose(sc.sensor.torque_bias_Nm, TORQUE_BIAS_NM)
    servo = servo_settings(sc)
    comp_extra = ["--servo", ",".join(str(servo[k]) for k in SERVO_KEYS), "--cutter-diameter-mm",
                  str(sc.cutter.diameter_mm)]
    run_dir, cell, comp, out = _run_pair_judged(tmp_path, model, payload, lockstep=lockstep, comp_extra=comp_extra,
                                                scan_name="my_scan.csv", deadline=True)
    cerr = cell.stderr
    assert cell.returncode == 0, (cerr, comp.stderr)
    assert comp.returncode == 0, comp.stderr
    res = json.loads(out.read_text())
    # the cut checked for chatter before the cell started (diagrams/chatter_check.py), its warning when unstable
    chk = res["chatter_check"]
    assert chk is not None and chk["poses_checked"] > 0, res
    assert any(w.startswith("chatter:") for w in res["warnings"]) == (not chk["stable"]), res["warnings"]
    surf, diagram = res["surface_error_mm"], short_compensated.surface_error_mm
    print("uncompensated (diagram)", plain["mean"], "compensated: diagram", diagram["mean"], "over EGM/RDT",
          surf["mean"], "late cycles", res["late_ticks"], "of", res["cycles"])
    # The same chain: over the steady part of the cut (t = 1.5-2.5 s, the
    # force constant) the six joint corrections the compensator sent agree
    # with the diagram compensator's within 3 % of the largest one.
    _same_steady_corrections(run_dir, short_compensated, "irb6400 egm")
    assert plain["mean"] > 0.1 and abs(diagram["mean"]) < 0.2 * plain["mean"], (plain, diagram)
    if lockstep:
        # Each answer before the next step: the diagram's loop, its surface
        # to a few micrometres (the network's timing of the sensor records
        # against the EGM messages differs from the diagram's by a sample).
        assert abs(surf["mean"] - diagram["mean"]) < 0.005, (surf, diagram)
        assert res["unanswered"] == 0, res
        assert res["health"]["verdict"] == "good", res["health"]
        # the two sides' verdicts on the run agree, and each names what it saw of the other (in lockstep the
        # sensor's silence is judged on the controller's clock too: a loaded PC does not ramp the correction)
        summary = json.loads((run_dir / "log" / "summary.json").read_text())
        assert summary["health"]["verdict"] == "good", summary["health"]
        assert "seen of the controller" in summary["health"]["line"] and "seen of the compensator" in \
            res["health"]["line"], (summary["health"]["line"], res["health"]["line"])
        assert summary["health"]["seen_of_the_other_side"]["sensor_faults"] == 0, summary["health"]
        # the simulated sensor agrees with the payload calibration at the start (the tool in the air) and streams
        # at the configured rate (cell/sensor_checks.py)
        checks = summary["cycles"]["sensor_checks"]
        print("start check", checks["start"], "rate check", checks["rate"])
        assert checks["start"]["passed"] and checks["rate"]["fault"] is None and checks["rate"]["windows_judged"] > 2
        # the log is a run folder diagnose-run reads, with the scan made outside it attached
        dr = subprocess.run([sys.executable, "-m", "robstiff_drake", "diagnose-run", str(run_dir / "log"), "--scan",
                             str(run_dir / "my_scan.csv"), "--json", str(tmp_path / "dr.json"), "--out",
                             str(tmp_path / "dr")], cwd=ROOT, capture_output=True, text=True, timeout=300)
        assert dr.returncode == 0, dr.stderr
        rep = json.loads((tmp_path / "dr.json").read_text())
        assert rep["n_scan_points"] > 100 and rep["run_id"] == (run_dir / "log" / "RUN_ID").read_text().strip()
        print("diagnose-run of the cell's log:", rep["rms_before_mm"], [c["name"] for c in rep["causes"]])
    # In real time nothing is asserted of the surface: on a shared machine
    # some cycles of the simulated controller (a Python thread) come late;
    # it then steps through the missed ones and the target jumps, the servo's
    # velocity feed-forward jerks the arm by tens of micrometres and the face
    # mill keeps the deepest dip over a cutter's width (docs/real_cell.md).


def _same_steady_corrections(tmp_path, diagram, label):
    """The same chain: over the steady part of the cut (t = 1.5-2.5 s, the
    force constant) the six joint corrections the compensator sent agree
    with the diagram compensator's within 3 % of the largest one."""
    log = _read_log(tmp_path / "log" / "timeseries_compensated.csv")
    tc, c = diagram.logs["correction"]
    m_net = (log["t_s"] > 1.5) & (log["t_s"] < 2.5)
    m_dia = (tc > 1.5) & (tc < 2.5)
    net = np.array([np.mean(log[f"correction_q{j}_rad"][m_net]) for j in range(1, 7)])
    dia = c[m_dia].mean(axis=0)
    print(label, "steady corrections (urad): diagram", np.round(dia * 1e6, 1), "over the protocols",
          np.round(net * 1e6, 1))
    assert np.max(np.abs(dia)) > 50e-6, dia  # a correction worth comparing
    assert np.max(np.abs(net - dia)) < 0.03 * np.max(np.abs(dia)), (net, dia)


def _run_pair(tmp_path, model, payload, *, lockstep, scenario=SHORT, robot=None, comp_extra=(), cell_extra=(),
              protocol="egm", during=None):
    """sim-cell and compensate, started together as docs/real_cell.md pastes them (compensate waits for
    the reference sim-cell writes when it is up); (sim-cell's, compensate's completed process, JSON path).
    The pair ends with the pass: sim-cell at its end, compensate then by the test (SIGTERM once its loop says
    the controller is silent: cell_helpers.run_compensate_until_cell_done).  Neither waits out a short silence
    of the other (before: compensate's --idle-exit-s 1 and sim-cell's 1 s answer timeout, which a process
    descheduled that long on a loaded machine met mid-pass: the run ended early, the test failed on the machine);
    their hang guards are HANG_GUARD_S; their waits for each other at the start (--wait-s: sim-cell builds its
    Drake station before it writes the reference compensate waits for, then waits for its first answer) five
    times that, a bound only: a machine at a load of 15 took longer than the 40 s and 60 s they had.  ``during(cell, comp)``: run in a thread beside the pair (a test's stall
    injection; both processes started)."""
    egm_port, netft_port = free_udp_port(), free_udp_port()
    cell, ref, out = _sim_cell(tmp_path, egm_port=egm_port, netft_port=netft_port, lockstep=lockstep,
                               scenario=scenario, extra=list(cell_extra) + ["--controller-protocol", protocol,
                                                                           "--answer-timeout-s", f"{HANG_GUARD_S:g}"])
    cell_out = []
    reader = threading.Thread(target=lambda: cell_out.append(cell.communicate(timeout=HANG_GUARD_S * 10)),
                              daemon=True)
    reader.start()
    if protocol == "stream-motion":  # the PC is the client: it sends to the robot's port
        comp_extra = list(comp_extra) + ["--controller", f"127.0.0.1:{egm_port}"]
    try:
        comp = run_compensate_until_cell_done(
            [sys.executable, "-m", "robstiff_drake", "compensate", "--controller-protocol", protocol,
             "--listen-port", str(0 if protocol == "stream-motion" else egm_port),
             "--netft", f"127.0.0.1:{netft_port}", "--netft-http-port", str(netft_port), "--model", model,
             "--payload", payload, "--reference", str(ref), "--wait-s", f"{HANG_GUARD_S * 5:g}", "--cutoff-hz", "2",
             "--sensor-rate-hz",
             "1000", "--delay-steps", "0", "--log", str(tmp_path / "log")] + (["--robot", robot] if robot else [])
            + list(comp_extra) + ["--idle-exit-s", f"{HANG_GUARD_S:g}"],
            reader.is_alive, bound_s=HANG_GUARD_S * 10,
            started=None if during is None else lambda comp: threading.Thread(target=during, args=(cell, comp),
                                                                                daemon=True).start())
    finally:
        reader.join(HANG_GUARD_S * 3)  # (the cell ends with its pass, or after --wait-s without a compensator)
        if cell.poll() is None:
            cell.kill()
            reader.join(HANG_GUARD_S)
    cerr = cell_out[0][1] if cell_out else ""
    return subprocess.CompletedProcess(cell.args, cell.returncode, "", cerr), comp, out


_DIAGRAMS = {}


def _diagram_run(name):
    if name not in _DIAGRAMS:
        _DIAGRAMS[name] = run_cut(load_scenario(OTHER_ROBOTS[name]), load_robot(name), compensation=True)
    return _DIAGRAMS[name]


# The conventions' check is one of logic: the lockstep pair on this machine's scheduling must not decide it.  Two
# of compensate's watchdogs run on this PC's wall clock as well, and a loaded machine tripped each mid-cut (the
# correction ramped to zero and back, the filter restarted: the face 0.019 mm off the diagram's at load 6,
# 0.09 mm at load 8-10, the steady corrections still within 0.5 %):
# * the sensor's silence: 20 ms on both clocks.  The simulated Net F/T sends a cycle's records before that
#   cycle's controller message, but compensate's reader thread, starved of a core, took them five cycles late
#   (events.csv: "sensor: no record for 20 ms" at t = 2.104 s of the controller's clock, "valid records again"
#   4 ms later).  Here the sensor never stops sending, so the test sets the timeout to a second (SENSOR_TIMEOUT_MS,
#   compensate's --sensor-timeout-ms; 250 cycles, and lockstep is never faster than real time) and asserts that
#   no sensor fault happened: with that timeout one is a real silence.
# * the controller's silence: 100 ms without a message on this PC's clock (no option sets it), i.e. the
#   lockstep controller itself stalled by the machine.  It is detected in compensate's events (a "messages
#   again" after it: a silence inside the run, not the run's end); such a run judges the machine, so the pair
#   runs once more, saying why, and the second run is asserted whatever it shows.
# * compensate's own deadline: an answer that left more than a period after its message arrived is late in its
#   verdict (health "degraded" beyond a few per cent), on this PC's clock; in lockstep the controller waits for
#   it, so only a machine that held compensate makes one (72 of 1068 at load 10: "degraded", the surface and
#   the corrections as the diagram's).  Such a run judges the machine too, and runs once more the same way where
#   the test asserts compensate's verdict (``deadline``).
SENSOR_TIMEOUT_MS = 1000


def _controller_stalls(log_dir, deadline=False):
    """What this machine's scheduling did to a lockstep run, as compensate logged it: its events of a silence
    of the controller inside the run (one followed by "messages again"), and its answers that left later than
    their deadline after their message arrived (summary.json's late_over_deadline; with ``deadline``)."""
    events = [line for line in (log_dir / "events.csv").read_text().splitlines() if not line.startswith("#")][1:]
    late = json.loads((log_dir / "summary.json").read_text())["cycles"]["late_over_deadline"] if deadline else 0
    return [e for e in events if "messages again" in e] + ([f"{late} answers over compensate's deadline"]
                                                            if late else [])


def _real_time_stop_by_load(cell, out):
    """In real time: the simulated controller's supervision stopped the pass on a target while this machine
    made that controller or compensate late (sim-cell's JSON: late ticks, late or unanswered answers).  A real
    controller is never late, and a late compensator's target taken after the one before was skipped is a
    double step: the acceleration the supervision refuses is this machine's (docs/real_cell.md), not the
    chain's.  ([] otherwise.)"""
    if cell.returncode == 0 or "the controller refused a target" not in cell.stderr or not out.exists():
        return []
    res = json.loads(out.read_text())
    late = {k: res.get(k) for k in ("late_ticks", "skipped_ticks", "late", "unanswered") if res.get(k)}
    return [f"the controller refused a target with {late}"] if late else []


def _run_pair_judged(tmp_path, model, payload, *, lockstep, scan_name=None, comp_extra=(), deadline=False, **kw):
    """_run_pair in a folder of its own (run1), judged on the loop's logic in lockstep: compensate's sensor
    silence at SENSOR_TIMEOUT_MS, and a run in which this machine stalled the lockstep controller for 100 ms
    or compensate (_controller_stalls), or a real-time pass stopped by the controller's supervision while this
    machine made the pair late (_real_time_stop_by_load), run once more in a fresh folder (run2), saying why;
    the second run is asserted whatever it shows.  ``scan_name``: sim-cell's --scan-out in the run's folder.  (run folder, sim-cell's and
    compensate's completed processes, sim-cell's JSON path)."""
    if lockstep:
        comp_extra = list(comp_extra) + ["--sensor-timeout-ms", str(SENSOR_TIMEOUT_MS)]
    for attempt in (1, 2):
        run_dir = tmp_path / f"run{attempt}"
        run_dir.mkdir()
        cell_extra = ["--scan-out", str(run_dir / scan_name)] if scan_name else []
        cell, comp, out = _run_pair(run_dir, model, payload, lockstep=lockstep, comp_extra=comp_extra,
                                    cell_extra=cell_extra, **kw)
        stalls = _controller_stalls(run_dir / "log", deadline) if lockstep and comp.returncode == 0 else []
        if not lockstep:
            stalls = _real_time_stop_by_load(cell, out)
        if not stalls or attempt == 2:
            return run_dir, cell, comp, out
        print(f"attempt 1: this machine stalled the lockstep controller for 100 ms or more, or compensate past its "
              f"deadline, or made the real-time pair late where the controller refused a target ({stalls}): run "
              "again")


@pytest.mark.parametrize("name, protocol", [("kr240_r2900", "egm"), ("kr240_r2900", "rsi"),
                                            ("r2000ic_165f", "egm"), ("r2000ic_165f", "stream-motion")])
def test_kuka_and_fanuc_conventions_over_the_protocols_match_the_diagram(tmp_path, name, protocol):
    """The controller's convention: the KUKA's and the FANUC's references,
    feedback and targets are in their controllers' angles (A3 offset by
    -90 deg; J3 from the horizontal), mapped through the robot file's
    `controller:` block; in lockstep the corrections sent and the surface
    cut match the in-diagram run's."""
    robot = load_robot(name)
    assert not robot.joint_map.is_identity
    diagram = _diagram_run(name)
    start = (robot.workspace.reference_tool_point_m * 1e3).tolist()
    model, payload, _, _ = write_inputs(str(tmp_path), robot, duration_s=0.1, start_mm=start)
    run_dir, cell, comp, out = _run_pair_judged(tmp_path, model, payload, lockstep=True, scenario=OTHER_ROBOTS[name],
                                                robot=name, protocol=protocol)
    assert cell.returncode == 0, (cell.stderr, comp.stderr)
    assert comp.returncode == 0, comp.stderr
    res = json.loads(out.read_text())
    summary = json.loads((run_dir / "log" / "summary.json").read_text())
    # the simulated sensor sent every cycle's records: no silence of a second on both clocks
    assert summary["health"]["seen_of_the_other_side"]["sensor_faults"] == 0, summary["health"]
    _same_steady_corrections(run_dir, diagram, f"{name} {protocol}")
    print(name, protocol, "surface", res["surface_error_mm"]["mean"], "diagram", diagram.surface_error_mm["mean"])
    assert abs(res["surface_error_mm"]["mean"] - diagram.surface_error_mm["mean"]) < 0.005, (res, diagram)
    assert res["unanswered"] == 0, res


def _wait_for(path, timeout_s=60.0):
    import time

    t0 = time.monotonic()
    while not path.exists():
        assert time.monotonic() - t0 < timeout_s, f"sim-cell wrote no {path.name}"
        time.sleep(0.1)
    return path


def test_sim_cell_says_when_the_compensator_went_silent_before_the_cut(tmp_path):
    """The compensator answers 20 messages, then nothing, before the cutter
    reaches the part (before: KeyError 'mean' in --lockstep): sim-cell
    says when it stopped being answered, that no face was cut, and exits 3."""
    from test_cell_io import _AnsweringCompensator

    comp = _AnsweringCompensator(lambda k, q: q if k <= 20 else None)
    try:
        cell, ref, out = _sim_cell(tmp_path, egm_port=comp.port, netft_port=free_udp_port(), lockstep=True)
        _, err = cell.communicate(timeout=180)
    finally:
        comp.close()
    assert cell.returncode == 3, err
    assert "Traceback" not in err, err
    assert "no answer from the compensator for 1 s after t = 0.0" in err
    assert "no face was cut" in err
    res = json.loads(out.read_text())
    assert res["surface_error_mm"] is None and res["stopped"].startswith("no answer")
    assert res["health"]["verdict"] == "poor"


def test_lockstep_takes_a_skipped_message_at_engagement_as_unanswered_not_silence(tmp_path):
    """A compensator that stalls as the cell engages and then answers only the newest of the messages queued
    meanwhile (as compensate does) skips the messages in between.  Lockstep stopped the run at the first of
    them ("no answer from the compensator for 1 s after t = 0.000 s", with a newer answer in hand; seen under
    load in tests/test_run_vibration_commands.py): now it is a cycle unanswered, and the pass is cut.  (The
    stall lands the skip at engagement in most runs, not all: before the fix this failed 2 runs of 3.)"""
    import time

    from test_cell_io import _AnsweringCompensator

    from test_run_vibration_commands import _reference

    ref_file, period_s, answered = tmp_path / "cell_reference.csv", 0.004, []

    def answer(k, q):  # the path's reference (no correction), clocked by the answers' count
        if not ref_file.exists():
            return None
        if not answered:
            time.sleep(0.3)  # the stall: the cell sends about 75 messages meanwhile, before it engages
            answered.append(_reference(ref_file))
        table = answered[0]
        answered.append(None)
        return [float(np.interp(period_s * len(answered), table[:, 0], table[:, j])) for j in range(1, 7)]

    comp = _AnsweringCompensator(answer, newest_only=True)
    try:
        cell, ref, out = _sim_cell(tmp_path, egm_port=comp.port, netft_port=free_udp_port(), lockstep=True)
        assert ref == ref_file
        _, err = cell.communicate(timeout=600)
    finally:
        comp.close()
    assert "Traceback" not in err, err
    res = json.loads(out.read_text())
    assert cell.returncode == 0 and res["stopped"] is None, (res["stopped"], err)
    assert res["surface_error_mm"] is not None, err
    print({k: res[k] for k in ("unanswered", "late_answers", "answered") if k in res}, res.get("health", {}).get("seen_of_the_compensator"))
