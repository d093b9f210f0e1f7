"""A compensator run's log folder (``robstiff compensate --log DIR``), in
the formats of a simulated run folder so that the same tools read both:

* ``timeseries_compensated.csv``: the columns of ``robstiff simulate``'s
  time series (commands/simulate.py timeseries_csv) that a cell knows:
  t_s, raw / filtered wrench (sensor frame), tool_wrench (base frame, tool
  point), dq, correction, q*_deg (the joint angles commanded: reference +
  correction); the simulation-only columns (tool_*, commanded_*) are not
  there, a cell does not measure them;
* ``wrench_log.csv`` and ``joint_log.csv``: the cell files of the run-folder
  formats (t_s, fx_N .. mz_Nm, an empty row for an invalid record; t_s,
  q1_deg .. q6_deg, corr1_deg .. corr6_deg);
* ``cycles.csv``: per EGM message, the measured joints, the computation
  time, the correction's age and whether a fault was on;
* ``summary.json``: the settings, the cycle-time figures and the faults.

Every file carries the run id.
"""

import csv
import io
import math

import numpy as np

from robstiff_drake.io import json_text

WRENCH = ("fx_N", "fy_N", "fz_N", "mx_Nm", "my_Nm", "mz_Nm")


def _table(run_id, notes, header, rows, fmt=".7g"):
    buf = io.StringIO()
    buf.write(f"# run_id: {run_id}\n")
    for n in notes:
        buf.write(f"# {n}\n")
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(header)
    for row in rows:
        w.writerow(["" if (isinstance(v, float) and not math.isfinite(v)) else format(v, fmt) for v in row])
    return buf.getvalue()


def _columns(log):
    r = np.asarray(log.rows, dtype=float).reshape(-1, 42)
    return {"t": r[:, 0], "t_wall": r[:, 1], "q_ref": r[:, 2:8], "q": r[:, 8:14], "corr": r[:, 14:20],
            "dq": r[:, 20:26], "filtered": r[:, 26:32], "process": r[:, 32:38], "fault": r[:, 38],
            "compute": r[:, 39], "age": r[:, 40], "seq": r[:, 41]}


def raw_at_cycles(log, t_wall):
    """The latest raw record (6) at each cycle's arrival (NaN before any)."""
    if not log.wrench:
        return np.full((len(t_wall), 6), np.nan)
    w = np.asarray(log.wrench, dtype=float)
    i = np.searchsorted(w[:, 0], t_wall, side="right") - 1
    out = w[np.clip(i, 0, len(w) - 1), 1:]
    out[i < 0] = np.nan
    return out


def write_log(run, log, model, summary, note):
    """Write the log files into ``run`` (an io.RunFolder); ``model``: the
    compensator's DeflectionModel (for the tool wrench)."""
    c = _columns(log)
    n = len(c["t"])
    raw = raw_at_cycles(log, c["t_wall"])
    tool = np.array([model.tool_wrench(w.tolist(), q.tolist()) for w, q in zip(c["process"], c["q"])]).reshape(n, 6)
    q_cmd_deg = np.degrees(c["q_ref"] + c["corr"])
    header = (["t_s"] + [f"raw_{x}" for x in WRENCH] + [f"filtered_{x}" for x in WRENCH]
              + [f"tool_wrench_{x}" for x in WRENCH] + [f"dq_q{j}_rad" for j in range(1, 7)]
              + [f"correction_q{j}_rad" for j in range(1, 7)] + [f"q{j}_deg" for j in range(1, 7)])
    rows = np.column_stack([c["t"], raw, c["filtered"], tool, c["dq"], c["corr"], q_cmd_deg])
    run.write("timeseries_compensated.csv", _table(
        run.run_id, [f"robstiff compensate: {note}; one row per EGM message (t_s: the controller's clock from the "
                     "first message). Wrenches: raw/filtered in the sensor frame, tool_wrench = the gravity-free "
                     "estimate at the tool point in the base frame. q*_deg: the joint angles commanded (reference + "
                     "correction). The simulation-only columns of `robstiff simulate` (tool_*, commanded_*) are not "
                     "measured by a cell."], header, rows.tolist(), ".6g"))
    w = np.asarray(log.wrench, dtype=float).reshape(-1, 7)
    run.write("wrench_log.csv", _table(
        run.run_id, ["wrench_log: the wrist sensor's raw readings as the Net F/T delivered them (bias and payload "
                     "weight included): force (N) and moment (N*m, about the sensor origin) in the sensor frame; "
                     "t_s: seconds since the first EGM message (this PC's clock, at the record's arrival); an empty "
                     f"row is an invalid record. {note}"], ("t_s",) + WRENCH, w.tolist()))
    run.write("joint_log.csv", _table(
        run.run_id, ["joint_log: once per controller period, q*_deg: the joint angles sent to the controller "
                     "(the reference plus the compensator's correction, controller degrees); corr*_deg: the "
                     f"correction included in them. {note}"],
        ["t_s"] + [f"q{j}_deg" for j in range(1, 7)] + [f"corr{j}_deg" for j in range(1, 7)],
        np.column_stack([c["t"], q_cmd_deg, np.degrees(c["corr"])]).tolist(), ".10g"))
    run.write("cycles.csv", _table(
        run.run_id, ["cycles: per EGM message: the controller's sequence number, the measured joints (deg, "
                     "motor side), the compensator's computation time from the message's arrival to the answer "
                     "(ms), the correction's age (ms since the newest sensor record it used arrived) and whether a "
                     "fault held the correction at a ramp to zero (1)."],
        ["t_s", "seqno"] + [f"measured_q{j}_deg" for j in range(1, 7)] + ["compute_ms", "age_ms", "fault"],
        np.column_stack([c["t"], c["seq"], np.degrees(c["q"]), c["compute"] * 1e3, c["age"] * 1e3,
                         c["fault"]]).tolist()))
    run.write("summary.json", json_text(dict(summary, run_id=run.run_id)))
    return ["timeseries_compensated.csv", "wrench_log.csv", "joint_log.csv", "cycles.csv", "summary.json"]
