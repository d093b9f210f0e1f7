"""`robstiff compensate --mode preview --job SCENARIO.yaml`: its inputs
refused before any socket opens (one line, exit status 2), and the preview
run over EGM and Net F/T against the Drake station (`robstiff sim-cell`,
lockstep) beside a plain run of the same job: the targets stay inside the
robot's limits and the correction's clamp, the preview is applied (its
correction leads the plain chain's where the force changes) and the face
cut at the block's entry is closer to the path."""

import json
import os
import subprocess
import threading

import numpy as np
import pytest

from cell_helpers import HANG_GUARD_S, ROOT, cached_preview_table, compensate_cmd, free_udp_port, \
    run_compensate_until_cell_done, write_inputs
from robstiff_drake.model.robot import load_robot

SHORT = os.path.join(ROOT, "tests", "data", "short_block.yaml")
KUKA_JOB = os.path.join(ROOT, "tests", "data", "short_block_kr240_r2900.yaml")


def _refused(tmp_path, extra, reference=None):
    robot = load_robot()
    model, payload, ref, _ = write_inputs(str(tmp_path), robot, duration_s=0.1)
    cmd = compensate_cmd(model, payload, ref if reference == "own" else None, egm_port=free_udp_port(),
                         netft_port=free_udp_port(), extra=extra)
    p = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=300)
    lines = p.stderr.strip().splitlines()
    assert p.returncode == 2, p.stderr
    assert "Traceback" not in p.stderr, p.stderr
    assert "waiting for" not in p.stderr, p.stderr  # refused before any socket opened
    return lines[-1]


@pytest.mark.untimed
@pytest.mark.parametrize("extra, words", [
    (["--mode", "preview"], "--mode preview needs --job"),
    (["--job", SHORT], "is read only with --mode preview"),
    (["--mode", "preview", "--job", "no_such_job.yaml"], "no_such_job.yaml: no such scenario file"),
    (["--mode", "preview", "--job", KUKA_JOB], "identified for the robot 'irb6400', not for 'kr240_r2900'"),
    (["--mode", "preview", "--job", KUKA_JOB, "--robot", "irb6400"], "disagrees with the robot of"),
    (["--mode", "preview", "--job", SHORT, "--period-ms", "12"], "controller.period_ms 4 is not --period-ms 12"),
], ids=["no-job", "job-without-preview", "missing-job", "job-for-another-robot", "robot-disagrees",
        "another-period"])
def test_bad_preview_inputs_are_one_line_exit_2(tmp_path, extra, words):
    line = _refused(tmp_path, extra)
    assert words in line, line


@pytest.mark.untimed
def test_a_reference_that_is_not_the_jobs_path_is_refused(tmp_path):
    """--reference with --job must be the job's planned path (here the
    helpers' straight pass at another place and time): refused once the
    table is computed, before any socket opens."""
    line = _refused(tmp_path, ["--mode", "preview", "--job", SHORT], reference="own")
    assert "not the planned path of --job" in line and "drop --reference" in line, line


def _log(path):
    lines = [line for line in open(path) if not line.startswith("#")]
    names = lines[0].strip().split(",")
    data = np.array([[float(v) if v else np.nan for v in line.strip().split(",")] for line in lines[1:]])
    return {n: data[:, i] for i, n in enumerate(names)}


@pytest.fixture(scope="module")
def pair(tmp_path_factory):
    """The short block over EGM/RDT in lockstep, plain and preview:
    {mode: (sim-cell's JSON, compensate's summary.json, its time series,
    its joint log, stderr)}.  Each pair judged on the loop's logic as
    test_sim_cell's (_run_pair_judged: the sensor's silence at a second, a
    run in which this machine stalled the lockstep controller run once more):
    a sensor fault or a silence of the controller that a loaded machine makes
    pauses the preview's learning and ramps the correction (the preview over
    the protocols failed once at a load of 6)."""
    from test_sim_cell import _run_pair_judged

    robot = load_robot()
    cached_preview_table(SHORT)  # (the job run again: its table from the disk cache, previewing from the start)
    out = {}
    for mode in ("plain", "preview"):
        tmp = tmp_path_factory.mktemp(mode)
        model, payload, _, _ = write_inputs(str(tmp), robot, duration_s=0.1)
        extra = ["--mode", "preview", "--job", SHORT] if mode == "preview" else []
        run, cell, comp, js = _run_pair_judged(tmp, model, payload, lockstep=True, comp_extra=extra)
        assert cell.returncode == 0, (mode, cell.stderr, comp.stderr)
        assert comp.returncode == 0, (mode, comp.stderr)
        out[mode] = (json.loads(js.read_text()), json.loads((run / "log" / "summary.json").read_text()),
                     _log(run / "log" / "timeseries_compensated.csv"), _log(run / "log" / "joint_log.csv"),
                     comp.stderr)
    return out


def test_preview_over_the_protocols_runs_inside_the_limits(pair):
    robot = load_robot()
    res, summary, _, joints, err = pair["preview"]
    print(err)
    assert summary["mode"] == "preview" and summary["preview"]["table_rows"] > 1000, summary
    assert "short_block.yaml)" in err.split("inputs/ (")[-1]  # the job is kept in the log's inputs/, as the model and payload are
    pv = summary["preview"]
    # no preview fault during the cut: at most the table's end (after the pass and its run-out)
    assert pv["fallback"] is None or "table ended" in pv["fallback"]["why"], pv
    assert pv["scale_updates"] > 100, pv  # the force scales learnt during the cut
    # the checks' margins on the job it describes: the arm within a few ms of the plan (the bound 25 ms), the
    # measured force within tens of N of the model's (the bound 150 N + half the model's force)
    assert pv["max_plan_offset_ms"] < 10.0 and pv["max_force_departure_N"] < 50.0, pv
    assert res["targets_refused"] == 0 and res["unanswered"] == 0, res
    assert summary["cycles"]["targets_refused"] == 0, summary["cycles"]
    q = np.column_stack([joints[f"q{j}_deg"] for j in range(1, 7)])
    lo, hi = np.degrees(robot.q_lower_rad), np.degrees(robot.q_upper_rad)
    assert np.all(q >= lo) and np.all(q <= hi)
    corr = np.column_stack([joints[f"corr{j}_deg"] for j in range(1, 7)])
    assert np.max(np.abs(corr)) <= 0.5 + 1e-9, np.max(np.abs(corr))  # the correction's clamp (deg)
    assert np.max(np.abs(corr)) > 0.005  # a correction was sent


def test_preview_is_applied_where_the_force_changes(pair):
    """Where the cutter enters the block (the force ramps in) the preview's
    correction leads the plain chain's (its 2 Hz filter lags the force):
    the two differ there by more than a fifth of the plain correction, and
    the face cut at the entry is closer to the path."""
    _, _, plain, _, _ = pair["plain"]
    res_p, _, prev, _, _ = pair["preview"]
    res_0 = pair["plain"][0]
    j = int(np.argmax([np.max(np.abs(plain[f"correction_q{i}_rad"])) for i in range(1, 7)])) + 1
    cp, cv = plain[f"correction_q{j}_rad"], prev[f"correction_q{j}_rad"]
    tp, tv = plain["t_s"], prev["t_s"]
    final = np.median(cp[(tp > 2.0) & (tp < 2.5)])  # the plain correction in the steady cut
    assert abs(final) > 50e-6, final

    def reach(t, c, frac):
        i = np.flatnonzero(np.abs(c) >= frac * abs(final))
        return t[i[0]] if i.size else np.inf

    lead = reach(tp, cp, 0.5) - reach(tv, cv, 0.5)
    diff = np.max(np.abs(np.interp(tp, tv, cv) - cp)[(tp > 0.5) & (tp < 2.0)])
    print(f"q{j}: plain reaches half its steady correction {lead * 1e3:.0f} ms after the preview; largest "
          f"difference over the entry {diff * 1e6:.1f} urad of {abs(final) * 1e6:.1f}")
    print("surface (mm): plain", res_0["surface_error_mm"], "preview", res_p["surface_error_mm"])
    assert lead > 0.05, lead
    assert diff > 0.2 * abs(final), (diff, final)
    assert res_p["surface_error_mm"]["entry_max_abs"] < 0.5 * res_0["surface_error_mm"]["entry_max_abs"]


@pytest.mark.parametrize("case", ["force", "restart"])
def test_preview_falls_back_to_plain_when_the_plan_no_longer_holds(tmp_path, case):
    """Against the stand-in arm streaming the job's path: a force the job
    does not describe (400 N from t = 0.3 s, the job's cut starts later)
    or a controller restart (its clock from zero) ends the preview with one
    log line; the run goes on (plain, or the restart's fault ramp) and
    every target stays inside the limits."""
    from cell_helpers import cutting_wrench, start_cell
    from robstiff_drake.cell.sim_cell import Faults
    from robstiff_drake.diagrams.milling_cell import planned_path
    from robstiff_drake.diagrams.scenario import load_scenario

    robot = load_robot()
    model, payload, _, _ = write_inputs(str(tmp_path), robot, duration_s=0.1)
    _, t_ref, q_ref = planned_path(load_scenario(SHORT), robot, robot.payload.tool_point_m)

    def reference(t):
        return np.array([np.interp(t, t_ref, q_ref[:, j]) for j in range(6)])

    cached_preview_table(SHORT)  # (the job run again: its table from the disk cache, previewing from the start)
    egm_port, netft_port = free_udp_port(), free_udp_port()
    faults = Faults(restart_at=0.6) if case == "restart" else Faults()
    # lockstep (the physics without this machine's scheduling: a shared PC holds cycles), ended by the cell after
    # 4 s of its controller's clock and the compensator by the test once the cell is done: no wall-clock check
    # between the two (a compensator ended on its own clock left the cell unanswered, which it reported as a
    # fault; one ended by a 5 s silence, a controller stalled that long mid-run)
    th, net = start_cell(robot, reference, egm_port=egm_port, netft_port=netft_port, duration_s=600.0,
                         faults=faults, wrench=cutting_wrench(t0=0.3 if case == "force" else 5.0, ramp_s=0.05),
                         lockstep=True, cut_s=4.0, answer_timeout_s=60.0)
    log = tmp_path / "log"
    try:
        p = run_compensate_until_cell_done(
            compensate_cmd(model, payload, None, egm_port=egm_port, netft_port=netft_port, log=str(log),
                           idle_exit_s=HANG_GUARD_S, extra=["--mode", "preview", "--job", SHORT]),
            th.is_alive, bound_s=600.0)
    finally:
        net.stop = True
        th.join(30)
        net.close()
    assert p.returncode == 0, p.stderr
    pv = json.loads((log / "summary.json").read_text())["preview"]
    why = {"force": "the measured force departs from the job's model", "restart": "the controller's clock"}[case]
    assert pv["fallback"] is not None and why in pv["fallback"]["why"], (pv, p.stderr)
    events = (log / "events.csv").read_text()
    assert events.count("preview: ") == 1 and "plain compensation from now on" in events, events
    assert net.stats.refused == 0 and not net.stats.stop_reason, net.stats.stop_reason
    joints = _log(log / "joint_log.csv")
    corr = np.column_stack([joints[f"corr{j}_deg"] for j in range(1, 7)])
    assert np.max(np.abs(corr)) <= 0.5 + 1e-9
    if case == "force":  # plain from then on: the correction follows the measured force's deflection
        assert 0.3 < pv["fallback"]["t_s"] < 0.8, pv  # (the 2 Hz filter crosses the bound, then 0.1 s)
        late = corr[joints["t_s"] > joints["t_s"][-1] - 0.2]
        print("fallback at", pv["fallback"]["t_s"], "s; the last 0.2 s's largest correction", np.max(np.abs(late)),
              "deg; run to", joints["t_s"][-1], "s")
        assert np.max(np.abs(late)) > 0.005, late


def test_a_cold_cache_computes_the_table_in_the_background_while_the_stream_runs(tmp_path):
    """A job run for the first time (an empty disk cache): the stream starts
    at once, plain, while another process computes the table; the loop then
    previews (one line says so), the table is left in the cache for the
    next run, and every target stays inside the limits."""
    from cell_helpers import cutting_wrench, start_cell
    from robstiff_drake.diagrams.milling_cell import planned_path
    from robstiff_drake.diagrams.scenario import load_scenario

    robot = load_robot()
    model, payload, _, _ = write_inputs(str(tmp_path), robot, duration_s=0.1)
    _, t_ref, q_ref = planned_path(load_scenario(SHORT), robot, robot.payload.tool_point_m)

    def reference(t):
        return np.array([np.interp(t, t_ref, q_ref[:, j]) for j in range(6)])

    cache = tmp_path / "cache"
    egm_port, netft_port = free_udp_port(), free_udp_port()
    log = tmp_path / "log"
    # lockstep, ended by what the run says, not by a clock: the cell runs until the compensator's events say the
    # table is taken, then 1 s more (previewed cycles), or at most 300 s of its controller's time.  (A fixed 8 s
    # cut failed on a loaded machine: the table's process, its interpreter's start and the job's 1156 cycles, took
    # longer than the cut, and the run ended plain throughout.)
    th, net = start_cell(robot, reference, egm_port=egm_port, netft_port=netft_port, duration_s=900.0,
                         wrench=cutting_wrench(t0=5.0, ramp_s=0.05), lockstep=True, cut_s=300.0, answer_timeout_s=60.0)
    done = threading.Event()

    def stop_once_taken():
        events = log / "events.csv"
        while not done.is_set():
            if events.exists() and "preview: the job's table is ready" in events.read_text():
                done.wait(1.0)
                net.stop = True
                return
            done.wait(0.2)

    watcher = threading.Thread(target=stop_once_taken, daemon=True)
    watcher.start()
    try:
        p = run_compensate_until_cell_done(
            compensate_cmd(model, payload, None, egm_port=egm_port, netft_port=netft_port, log=str(log),
                           idle_exit_s=HANG_GUARD_S, extra=["--mode", "preview", "--job", SHORT]),
            th.is_alive, bound_s=900.0, env=dict(os.environ, ROBSTIFF_CACHE_DIR=str(cache)))
    finally:
        done.set()
        net.stop = True
        th.join(30)
        net.close()
    assert p.returncode == 0, p.stderr
    assert "not in the disk cache; computed in another process while the loop runs" in p.stderr, p.stderr
    summary = json.loads((log / "summary.json").read_text())
    table = summary["preview_table"]
    assert table.startswith("computed in another process"), table
    t_taken = float(table.split("plain compensation until t = ")[1].split(" s")[0])
    cycles = _log(log / "cycles.csv")
    assert t_taken > 0 and np.sum(cycles["t_s"] < t_taken) > 0  # answered (plain) before the table was ready
    events = (log / "events.csv").read_text()
    assert "preview: the job's table is ready" in events, events
    assert len(list(cache.glob("preview-table-*.npz"))) == 1  # (the next run reads it)
    assert net.stats.refused == 0 and not net.stats.stop_reason, net.stats.stop_reason
    joints = _log(log / "joint_log.csv")
    corr = np.column_stack([joints[f"corr{j}_deg"] for j in range(1, 7)])
    assert np.max(np.abs(corr)) <= 0.5 + 1e-9
