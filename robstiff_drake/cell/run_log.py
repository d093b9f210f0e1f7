"""A compensator run's log folder (``robstiff compensate --log DIR``),
streamed to disk as the run goes (bounded memory whatever its length, and
complete up to the last ``FLUSH_S`` after a kill), in the formats of a
run folder (docs/run_files.md) so that ``robstiff diagnose-run`` reads it:

* ``RUN_ID`` and ``compensator.yaml`` (the compensator's settings, the
  robot controller's servo when ``--servo`` gives it), written at the
  start;
* ``joint_log.csv`` (t_s on the controller's clock, the joint angles sent:
  reference + correction, controller degrees, and the correction in them)
  and ``wrench_log.csv`` (the raw records in N and N*m, sensor frame;
  an empty row for an invalid one), in the run-file formats;
* ``timeseries_compensated.csv``: the columns of ``robstiff simulate``'s
  time series that a cell knows (raw / filtered wrench, tool wrench, dq,
  correction, q*_deg commanded);
* ``cycles.csv``: per answered message, the sequence number, the measured
  joints, the computation time, the correction's age, whether a fault was
  on, whether its own target was sent and how long the message had waited
  to be read (cell/link.py's ``queued_s``);
* ``events.csv``: every fault and event with its time;
* ``summary.json`` at the end: the settings, the loop check, the cycle
  figures, the health verdict;
* ``inputs/``: a copy of every file the run was made with (the robot
  file, --model, --payload, --reference; diagrams/run_inputs.py), as a
  simulated run folder keeps them, written at the start.

The loop formats each row after its answer has left (tens of
microseconds) into an in-memory chunk; every ``FLUSH_S`` the chunks go to
a writer thread that only writes and flushes them (the GIL is released
during the system call), so the loop never waits on the disk.  A disk
that cannot keep up or is full loses rows, counted and said once.
"""

import os
import queue
import shutil
import tempfile
import threading
from pathlib import Path

from robstiff_drake.io import RUN_ID_FILE, json_text, new_run_id

FLUSH_S = 0.5  # hand the rows to the writer at least this often (s)
MAX_PENDING = 64  # chunks waiting for the writer (32 s of rows) before rows are dropped
WRENCH = ("fx_N", "fy_N", "fz_N", "mx_Nm", "my_Nm", "mz_Nm")
FILES = {
    "joint_log.csv": ["t_s"] + [f"q{j}_deg" for j in range(1, 7)] + [f"corr{j}_deg" for j in range(1, 7)],
    "wrench_log.csv": ["t_s", *WRENCH],
    "timeseries_compensated.csv": (["t_s"] + [f"raw_{x}" for x in WRENCH] + [f"filtered_{x}" for x in WRENCH]
                                   + [f"tool_wrench_{x}" for x in WRENCH] + [f"dq_q{j}_rad" for j in range(1, 7)]
                                   + [f"correction_q{j}_rad" for j in range(1, 7)]
                                   + [f"q{j}_deg" for j in range(1, 7)]),
    "cycles.csv": (["t_s", "seqno"] + [f"measured_q{j}_deg" for j in range(1, 7)]
                   + ["compute_ms", "age_ms", "fault", "sent", "queued_ms", "late", "t_ref_s"]),
    "events.csv": ["t_s", "t_controller_s", "event"],
}
NOTES = {
    "joint_log.csv": "joint_log: once per answered controller message, q*_deg: the joint angles sent to the "
                     "controller (the reference plus the compensator's correction, controller degrees); corr*_deg: "
                     "the correction included in them; t_s: the controller's clock from its first message.",
    "wrench_log.csv": "wrench_log: the wrist sensor's raw readings as the Net F/T delivered them (bias and payload "
                      "weight included), converted from its calibration's units: force (N) and moment (N*m, about "
                      "the sensor origin) in the sensor frame; t_s: the controller's clock (the joint log's) at the "
                      "record's arrival; an empty row is an invalid or clipped record.",
    "timeseries_compensated.csv": "robstiff compensate: one row per answered message (t_s: the controller's clock). "
                                  "Wrenches: raw/filtered in the sensor frame, tool_wrench = the gravity-free "
                                  "estimate at the tool point in the base frame. q*_deg: the joint angles sent. The "
                                  "simulation-only columns of `robstiff simulate` (tool_*, commanded_*) are not "
                                  "measured by a cell.",
    "cycles.csv": "cycles: per answered message: the controller's sequence number, the measured joints (deg, "
                  "controller), the computation time from the message's arrival to the answer (ms), the "
                  "correction's age (ms since the newest sensor record it used arrived), whether a fault held the "
                  "correction at a ramp to zero (1), whether its own target was sent (0: the last safe one), and "
                  "how long the message had waited at this PC before it was read (ms, from the kernel's receive "
                  "time stamp: the loop's wake-up; empty where the system gives no stamp; compute_ms + queued_ms: "
                  "from its arrival to the answer), and whether the answer was late (1: the controller's next cycle "
                  "came without it: the next message was already waiting when it left, or it left more than the "
                  "controller's cycle after the message's arrival), and the reference's played time (t_ref_s, s: "
                  "t_s but for a stalled clock's stop and restart within the robot's accelerations).",
    "events.csv": "events: every fault's start and end and every event of the run, with its time (t_s: s since "
                  "the first message, this PC's clock; t_controller_s: the controller's clock, the other logs' t_s).",
}


def _num(v):
    return "" if v != v or v in (float("inf"), float("-inf")) else format(v, ".7g")


class _Writer(threading.Thread):
    def __init__(self, files):
        super().__init__(daemon=True)
        self.files = files
        self.q = queue.Queue(maxsize=MAX_PENDING)
        self.error = None

    def run(self):
        while True:
            item = self.q.get()
            if item is None:
                return
            if self.error is not None:
                continue
            try:
                for name, text in item.items():
                    f = self.files[name]
                    f.write(text)
                    f.flush()
            except OSError as e:
                self.error = e.strerror or str(e)


class StreamLog:
    """The run folder ``path``, written as the run goes (see the module
    docstring).  ``settings_text``: compensator.yaml's text without its
    run id line (written at the start)."""

    def __init__(self, path, settings_text, note, inputs=None):
        self.path = Path(path)
        self.inputs = dict(inputs or {})  # {name in the folder (inputs/...): bytes}
        self.run_id = new_run_id()
        self.settings_text = settings_text
        self.note = note
        self.chunks = {name: [] for name in FILES}
        self.t_flush = None
        self.dropped_rows = 0
        self.writer = None
        self.model = None

    # ------------------------------------------------------------ start and end

    def start(self, loop):
        """``bind`` and ``open`` at once."""
        self.bind(loop)
        self.open()

    def bind(self, loop):
        """The loop's model and start (the rows are formatted and kept in
        memory from now on; ``tick`` hands them over once the folder is open)."""
        self.model = loop.comp.model
        self.t_flush = loop.t_start

    def open(self):
        """Replace an earlier run folder at ``path`` (check_outputs refused
        anything else) and open the files: called once the loop's start has
        passed (cell/start_gate.py, off the real-time thread), so that a
        refused start leaves the earlier run as it was."""
        target = Path(os.path.realpath(self.path))
        if target.exists():
            old = Path(tempfile.mkdtemp(prefix=f".{target.name}.", suffix=".old", dir=target.parent))
            os.rmdir(old)
            os.replace(target, old)
            shutil.rmtree(old, ignore_errors=True)
        target.mkdir(parents=True)
        (target / RUN_ID_FILE).write_text(self.run_id + "\n")
        (target / "compensator.yaml").write_text(f"# run_id: {self.run_id}\n" + self.settings_text)
        for name, data in self.inputs.items():
            (target / name).parent.mkdir(parents=True, exist_ok=True)
            (target / name).write_bytes(data)
        files = {}
        for name, header in FILES.items():
            f = open(target / name, "w", encoding="utf-8")
            f.write(f"# run_id: {self.run_id}\n# {NOTES[name]} {self.note}\n" + ",".join(header) + "\n")
            f.flush()
            files[name] = f
        writer = _Writer(files)
        writer.start()
        self.writer = writer  # (last: the loop's tick hands rows over once it is set)

    def close(self, summary):
        """Hand the last rows over, close the files and write summary.json."""
        if self.writer is None:
            return []
        self.tick(None)
        self.writer.q.put(None)
        self.writer.join(30)
        for f in self.writer.files.values():
            try:
                f.close()
            except OSError:
                pass
        summary = dict(summary, run_id=self.run_id, log_rows_dropped=self.dropped_rows,
                       log_error=self.writer.error)
        target = Path(os.path.realpath(self.path))
        tmp = target / ".summary.json.tmp"
        tmp.write_text(json_text(summary))
        os.replace(tmp, target / "summary.json")
        kept = f"inputs/ ({', '.join(Path(n).name for n in self.inputs)})" if self.inputs else None
        return [RUN_ID_FILE, "compensator.yaml", *FILES, "summary.json"] + ([kept] if kept else [])

    # ------------------------------------------------------------ rows

    def tick(self, now):
        """Hand the rows to the writer when ``FLUSH_S`` has passed (``now``
        None: at once)."""
        if self.writer is None or (now is not None and now - self.t_flush < FLUSH_S):
            return  # (not open yet: the rows wait in memory)
        self.t_flush = now if now is not None else self.t_flush
        item = {name: "".join(rows) for name, rows in self.chunks.items() if rows}
        n = sum(len(rows) for rows in self.chunks.values())
        for rows in self.chunks.values():
            rows.clear()
        if not item:
            return
        try:
            self.writer.q.put_nowait(item)
        except queue.Full:
            self.dropped_rows += n

    def event(self, t, t_controller, text):
        self.chunks["events.csv"].append(f"{t:.4f},{t_controller:.4f},\"{text.replace(chr(34), chr(39))}\"\n")

    def wrench(self, t, w):
        self.chunks["wrench_log.csv"].append(",".join([format(t, ".6f")] + [_num(v) for v in w]) + "\n")

    def cycle(self, loop, msg, t_arr, ref_deg, corr_rad, corr_deg, target_deg, compute_s, age_s, late=False):
        t = format(loop.t_session, ".6f")
        comp = loop.comp
        sent = target_deg is not None
        q_cmd = target_deg if sent else loop.last_sent or ref_deg
        c = self.chunks
        c["joint_log.csv"].append(",".join([t] + [format(v, ".10g") for v in q_cmd]
                                           + [format(v, ".10g") for v in corr_deg]) + "\n")
        tool = self.model.tool_wrench(comp.process_wrench, loop.q)
        c["timeseries_compensated.csv"].append(",".join(
            [t] + [_num(v) for v in loop.last_raw] + [_num(v) for v in comp.filtered] + [_num(v) for v in tool]
            + [_num(v) for v in comp.dq] + [_num(v) for v in corr_rad] + [format(v, ".10g") for v in q_cmd]) + "\n")
        c["cycles.csv"].append(",".join([t, str(msg.seq)] + [format(v, ".7g") for v in loop.q_deg]
                                        + [_num(compute_s * 1e3), _num(age_s * 1e3), "1" if loop.faults else "0",
                                           "1" if sent else "0", _num(msg.queued_s * 1e3),
                                           "1" if late else "0", format(loop.t_ref, ".6f")]) + "\n")
