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
import sys

import numpy as np
import pytest

from cell_helpers import ROOT, compensate_cmd, free_udp_port, write_inputs
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
    its joint log, stderr)}."""
    from test_sim_cell import _run_pair

    robot = load_robot()
    out = {}
    for mode in ("plain", "preview"):
        tmp = tmp_path_factory.mktemp(mode)
        model, payload, _, _ = write_inputs(str(tmp), robot, duration_s=0.1)
        extra = ["--mode", "preview", "--job", SHORT] if mode == "preview" else []
        cell, comp, js = _run_pair(tmp, model, payload, lockstep=True, comp_extra=extra)
        assert cell.returncode == 0, (mode, cell.stderr, comp.stderr)
        assert comp.returncode == 0, (mode, comp.stderr)
        out[mode] = (json.loads(js.read_text()), json.loads((tmp / "log" / "summary.json").read_text()),
                     _log(tmp / "log" / "timeseries_compensated.csv"), _log(tmp / "log" / "joint_log.csv"),
                     comp.stderr)
    return out


def test_preview_over_the_protocols_runs_inside_the_limits(pair):
    robot = load_robot()
    res, summary, _, joints, err = pair["preview"]
    print(err)
    assert summary["mode"] == "preview" and summary["preview"]["table_rows"] > 1000, summary
    pv = summary["preview"]
    # no preview fault during the cut: at most the table's end (after the pass and its run-out)
    assert pv["fallback"] is None or "table ended" in pv["fallback"]["why"], pv
    assert pv["scale_updates"] > 100, pv  # the force scales learnt during the cut
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
    assert res_p["surface_error_mm"]["max_abs"] < res_0["surface_error_mm"]["max_abs"]
