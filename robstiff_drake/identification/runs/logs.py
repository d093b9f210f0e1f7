"""The logs and the scan of a run folder (docs/run_files.md): the wrist
sensor's wrench_log.csv, the controller's joint_log.csv, the scanned face's
scan.csv, and the joint_reference.csv that `robstiff compensate
--reference` streams: a reader (an InputError of one line naming the
file, line and column) and a writer (text) for each.  Plain numpy; no
Drake.  Units are in the column names; angles at the interface are the
controller's degrees.
"""

from dataclasses import dataclass

import numpy as np

from robstiff_drake.identification.runs.tables import (MIN_ROWS, SCAN, check_times, fail, meta_number, number_text,
                                                      read_table, table_text)

WRENCH_COLUMNS = ("t_s", "fx_N", "fy_N", "fz_N", "mx_Nm", "my_Nm", "mz_Nm")
JOINT_COLUMNS = ("t_s",) + tuple(f"q{j}_deg" for j in range(1, 7)) + tuple(f"corr{j}_deg" for j in range(1, 7))
SCAN_COLUMNS = ("x_mm", "y_mm", "nominal_mm", "height_mm")
REFERENCE_COLUMNS = ("t_s",) + tuple(f"q{j}_deg" for j in range(1, 7))


@dataclass
class WrenchLog:
    """The sensor's raw readings: (force N, moment N*m about the sensor
    origin) that the payload exerts on the sensor, in the sensor frame;
    NaN rows are samples the sensor did not deliver (dropouts)."""

    t_s: np.ndarray
    wrench: np.ndarray  # (N, 6)
    path: str = ""


@dataclass
class JointLog:
    """The controller's joint angles (deg, motor side: what the servos are
    sent and the encoders report) and the compensator's correction that
    they include (deg), once per controller period."""

    t_s: np.ndarray
    q_deg: np.ndarray  # (N, 6)
    correction_deg: np.ndarray  # (N, 6)
    path: str = ""


@dataclass
class Scan:
    """The measured face: positions (mm, robot base frame), the nominal
    height the program should leave and the measured height (mm).
    ``noise_mm``: the instrument's 1-sigma height noise as its file states
    it (None: not stated)."""

    x_mm: np.ndarray
    y_mm: np.ndarray
    nominal_mm: np.ndarray
    height_mm: np.ndarray
    noise_mm: float = None
    path: str = ""

    @property
    def error_mm(self):
        """Surface error (mm): nominal - measured, positive where more was cut."""
        return self.nominal_mm - self.height_mm



# ---------------------------------------------------------------- wrench log


def read_wrench_log(path):
    """The wrist sensor's log: ({key: (value, line)}, WrenchLog).  An empty
    row of all six wrench fields is a dropout (NaN); a partly empty row is an error."""
    meta, cols, row_lines = read_table(path, WRENCH_COLUMNS, empty_ok=WRENCH_COLUMNS[1:])
    w = np.column_stack([cols[c] for c in WRENCH_COLUMNS[1:]])
    partial = np.flatnonzero(np.isnan(w).any(axis=1) & ~np.isnan(w).all(axis=1))
    if partial.size:
        i = partial[0]
        j = int(np.flatnonzero(np.isnan(w[i]))[0])
        fail(path, row_lines[i], j + 2, f"{WRENCH_COLUMNS[j + 1]} is empty while other components are not "
                                        "(a dropout leaves all six empty)")
    check_times(path, cols["t_s"], row_lines)
    return meta, WrenchLog(cols["t_s"], w, str(path))


def wrench_log_text(log, run_id, notes=()):
    """wrench_log.csv: time (s) and the six raw components, sensor frame."""
    notes = ["wrench_log: the wrist sensor's raw readings, as it delivered them (bias and payload weight "
             "included): force (N) and moment (N*m, about the sensor origin) that the payload exerts on the "
             "sensor, in the sensor frame; t_s: seconds on the controller's clock; an empty row is a dropout.",
             *notes]
    return table_text(run_id, notes, WRENCH_COLUMNS, np.column_stack([log.t_s, log.wrench]), ".7g")


# ---------------------------------------------------------------- joint log


def read_joint_log(path):
    """The controller's joint log: ({key: (value, line)}, JointLog)."""
    meta, cols, row_lines = read_table(path, JOINT_COLUMNS)
    check_times(path, cols["t_s"], row_lines)
    q = np.column_stack([cols[f"q{j}_deg"] for j in range(1, 7)])
    c = np.column_stack([cols[f"corr{j}_deg"] for j in range(1, 7)])
    return meta, JointLog(cols["t_s"], q, c, str(path))


def joint_log_text(log, run_id, notes=()):
    """joint_log.csv: time (s), the six joint angles and the six corrections (deg)."""
    notes = ["joint_log: once per controller period, q*_deg: the joint angles the controller sends to the "
             "servos (motor side, controller degrees: the program's path plus the compensator's correction); "
             "corr*_deg: the compensator's correction included in them.",
             *notes]
    return table_text(run_id, notes, JOINT_COLUMNS, np.column_stack([log.t_s, log.q_deg, log.correction_deg]),
                      ".10g")


# ---------------------------------------------------------------- joint reference


def on_controller_period(t_s, q, period_s):
    """(t_s, q): a joint reference whose rows are finer than the
    controller's cycle ``period_s`` (s) resampled on that cycle (linear
    between rows, as `robstiff compensate` plays a reference:
    cell/reference.py), its last row the reference's last pose held to the
    next cycle; a reference at the cycle or coarser as it is.  `compensate
    --period-ms` refuses rows closer than its period (cell/safety.py
    check_reference): a path planned every 4 ms (path.reference_period_ms)
    for an 8 ms FANUC Stream Motion controller was refused before."""
    t = np.asarray(t_s, dtype=float)
    q = np.asarray(q, dtype=float)
    if len(t) < 2 or np.min(np.diff(t)) >= period_s - 1e-9:
        return t, q
    n = int(np.ceil((t[-1] - t[0]) / period_s - 1e-9))
    grid = t[0] + period_s * np.arange(n + 1)
    return grid, np.column_stack([np.interp(grid, t, q[:, j]) for j in range(q.shape[1])])


def joint_reference_text(robot, t_s, q_rad, run_id=None, notes=(), *, period_s):
    """joint_reference.csv, what `robstiff compensate --reference` streams:
    time (s) and the path's joint references in the controller's degrees
    (``q_rad``: the model's joint angles, (N, 6) rad, mapped through the
    robot file's joint map), on the controller's cycle ``period_s`` (s) or
    coarser (``on_controller_period``).  ``run_id`` None: a file outside a
    run folder."""
    n = len(t_s)
    t_s, q_rad = on_controller_period(t_s, q_rad, float(period_s))
    q_deg = robot.controller_deg(np.asarray(q_rad, dtype=float))
    if len(t_s) != n:
        notes = [*notes, f"resampled on the controller's cycle, {1e3 * float(period_s):g} ms (`robstiff compensate "
                         f"--period-ms {1e3 * float(period_s):g}`), linear between the path's {n} rows"]
    return table_text(run_id, notes, REFERENCE_COLUMNS, np.column_stack([t_s, q_deg]), ".12g")


# The mark of a corrected joint reference: a comment line before the header whose text starts with this
# (``corrected_mark_line``), written by `robstiff compensate-program` (its joint references carry the model's
# deflection correction) and read by `robstiff compensate --reference` (cell/reference_file.corrected_mark),
# which refuses to stream such a file with online compensation (the deflection corrected twice).
CORRECTED_MARK = "corrected_reference:"


def corrected_mark_line(by, model):
    """The corrected reference's mark (one '#' line, with its newline):
    written ``by`` (a command), the deflection correction of ``model``."""
    return (f"# {CORRECTED_MARK} these joint references already carry the deflection correction of the "
            f"compensator's {model} (written by {by}); stream them with `robstiff compensate "
            "--reference-is-corrected` (the online correction held at zero), never with online compensation on "
            "top (that corrects the deflection twice)\n")


def is_corrected_mark(comment):
    """Whether a comment line ('#' and its text) is the corrected reference's mark."""
    return comment.lstrip("#").strip().lower().startswith(CORRECTED_MARK)


# ---------------------------------------------------------------- scan



def read_scan(path):
    """The measured face: ({key: (value, line)}, Scan).  Rows with an empty
    height (no reading) are left out; the header may state the
    instrument's noise as ``# noise_mm: SIGMA`` (1 sigma, mm)."""
    meta, cols, row_lines = read_table(path, SCAN_COLUMNS, empty_ok=("height_mm",))
    ok = np.isfinite(cols["height_mm"])
    if ok.sum() < MIN_ROWS[SCAN]:
        fail(path, what=f"{int(ok.sum())} measured points; at least {MIN_ROWS[SCAN]} are needed")
    noise = meta_number(path, meta, "noise_mm")
    return meta, Scan(cols["x_mm"][ok], cols["y_mm"][ok], cols["nominal_mm"][ok], cols["height_mm"][ok],
                      noise, str(path))


def scan_text(scan, run_id, notes=()):
    """scan.csv: positions, nominal and measured heights (mm); the stated noise in the header."""
    head = []
    if scan.noise_mm is not None:
        head.append(f"noise_mm: {number_text(scan.noise_mm)}")
    notes = head + ["scan: the machined face as the scanner measures it; x_mm, y_mm: position in the robot "
                    "base frame; nominal_mm: the height the program should leave there; height_mm: the measured "
                    "height (empty: no reading). noise_mm: the instrument's 1-sigma height noise.", *notes]
    data = np.column_stack([scan.x_mm, scan.y_mm, scan.nominal_mm, scan.height_mm])
    return table_text(run_id, notes, SCAN_COLUMNS, data, ".6f")

