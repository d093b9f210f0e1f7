"""The text of a run folder's files (identification/runs/files.py): their
names, the CSV table with its leading ``# key: value`` lines that the logs
and the scan are written in, and the one-line InputError (file, line,
column) of anything wrong in them.  Plain numpy; no Drake.
"""

import math
import os
from pathlib import Path

import numpy as np

from robstiff_drake.command import inside
from robstiff_drake.errors import InputError, excerpt
from robstiff_drake.user_files import read_user_text

WRENCH_LOG = "wrench_log.csv"
JOINT_LOG = "joint_log.csv"
SETTINGS = "compensator.yaml"
SCAN = "scan.csv"
CELL_FILES = (WRENCH_LOG, JOINT_LOG, SETTINGS, SCAN)
SIM_PREFIX = "sim_"  # the simulation's truth: never read by the diagnosis
MIN_ROWS = {WRENCH_LOG: 10, JOINT_LOG: 10, SCAN: 20}


def fail(path, line=None, column=None, what=""):
    where = str(path)
    if line is not None:
        where += f", line {line}"
    if column is not None:
        where += f", column {column}"
    raise InputError(f"{where}: {what}")


def read_text(path):
    """A run file's text (user_files.read_user_text: a regular file, UTF-8,
    noted as an input of the command; no size bound, a long run's logs are large)."""
    return read_user_text(path, "run file", max_bytes=None)


def run_file(folder, name):
    """``folder/name``, refused (InputError) when it resolves outside the
    folder (a symbolic link out of it): a run folder's files are its own."""
    p = Path(folder) / name
    if os.path.lexists(p) and not inside(p, folder):
        fail(p, what=f"a symbolic link to a file outside the run folder {folder}; every file of a run folder must "
                     "be inside it (copy the file in)")
    return p


def header_meta(path, lines):
    """``# key: value`` lines before the first other line -> {key: (value, line)}."""
    meta = {}
    for n, line in enumerate(lines, 1):
        s = line.strip()
        if not s:
            continue
        if not s.startswith("#"):
            break
        key, sep, value = s[1:].partition(":")
        key = key.strip()
        if sep and key and " " not in key:
            if key in meta:
                fail(path, n, what=f"'{key}' is given twice (first on line {meta[key][1]})")
            meta[key] = (value.strip(), n)
    return meta


def read_table(path, columns, *, empty_ok=()):
    """A CSV table with a header line: ({key: (value, line)} of its leading
    ``# key: value`` lines, {column: array}, line numbers of the rows).
    Every column of ``columns`` is required and no other is allowed; an
    empty field is NaN in ``empty_ok`` columns and an error elsewhere."""
    lines = read_text(path).splitlines()
    meta = header_meta(path, lines)
    header, header_line, rows, row_lines = None, 0, [], []
    for n, line in enumerate(lines, 1):
        s = line.strip()
        if not s or s.startswith("#"):
            continue
        cells = [c.strip() for c in s.split(",")]
        if header is None:
            header, header_line = cells, n
            for j, h in enumerate(header, 1):
                if h not in columns:
                    fail(path, n, j, f"unknown column {excerpt(h)} (expected {', '.join(columns)})")
                if header.index(h) != j - 1:
                    fail(path, n, j, f"column {excerpt(h)} is given twice")
            missing = [c for c in columns if c not in header]
            if missing:
                fail(path, n, what=f"missing column {missing[0]} (expected {', '.join(columns)})")
            continue
        if len(cells) != len(header):
            fail(path, n, what=f"{len(cells)} fields, but the header (line {header_line}) has {len(header)}")
        vals = []
        for j, (h, c) in enumerate(zip(header, cells), 1):
            if c == "":
                if h in empty_ok:
                    vals.append(math.nan)
                    continue
                fail(path, n, j, f"{h} is empty")
            try:
                v = float(c)
            except ValueError:
                fail(path, n, j, f"{h}: {excerpt(c)} is not a number")
            if not math.isfinite(v):
                fail(path, n, j, f"{h}: {excerpt(c)} is not a finite number")
            vals.append(v)
        rows.append(vals)
        row_lines.append(n)
    if header is None:
        fail(path, what=f"no header line (expected the columns {', '.join(columns)})")
    need = MIN_ROWS.get(Path(path).name, 1)
    if len(rows) < need:
        fail(path, what=f"{len(rows)} data rows; at least {need} are needed")
    data = np.array(rows, dtype=float).reshape(len(rows), len(header))
    return meta, {h: data[:, header.index(h)] for h in columns}, np.array(row_lines)


def check_times(path, t, row_lines):
    bad = np.flatnonzero(np.diff(t) <= 0)
    if bad.size:
        i = bad[0] + 1
        fail(path, row_lines[i], 1, f"t_s {t[i]:g} is not after the previous row's {t[i - 1]:g} "
                                    "(times must increase)")


def number_text(v):
    """A float as text that reads back exactly (and as a float in YAML 1.1)."""
    s = repr(float(v))
    if "e" in s and "." not in s:
        s = s.replace("e", ".0e")
    return s


def meta_lines(run_id, notes):
    out = [] if run_id is None else [f"# run_id: {run_id}"]
    for note in notes:
        out.extend(f"# {ln}" if ln else "#" for ln in note.splitlines())
    return "\n".join(out) + "\n"


def table_text(run_id, notes, columns, data, fmt):
    lines = [meta_lines(run_id, notes), ",".join(columns) + "\n"]
    for row in np.asarray(data, dtype=float):
        lines.append(",".join("" if not math.isfinite(v) else format(v, fmt) for v in row) + "\n")
    return "".join(lines)



def meta_number(path, meta, key, *, low=0.0):
    if key not in meta:
        return None
    text, line = meta[key]
    try:
        v = float(text)
    except ValueError:
        fail(path, line, what=f"{key}: {excerpt(text)} is not a number")
    if not (math.isfinite(v) and v >= low):
        fail(path, line, what=f"{key}: must be a number >= {low:g}, got {text}")
    return v

