"""Reading a joint reference CSV (columns t_s, q1_deg .. q6_deg in any
order, extra columns ignored, '#' lines are comments) in one pass and in
bounded memory: the file is read in blocks of lines into a preallocated
float array that grows by doubling; a block of plain numbers is parsed by
numpy.loadtxt (in C), a block that it refuses (text in an extra column, a
comment or blank line, a bad cell) is walked row by row, and a bad cell
is an InputError naming the file, line and column.  A 67-minute path at
the 4 ms period (a million rows, 84 MB) holds about 70 MB here, where
reading it whole as text and Python lists held gigabytes."""

import os
from pathlib import Path

import numpy as np

from robstiff_drake.errors import InputError, excerpt
from robstiff_drake.identification.stiffness.measurement_table import parse_number

COLUMNS = ["t_s"] + [f"q{j}_deg" for j in range(1, 7)]
BLOCK_BYTES = 1 << 22  # lines read at a time (about 50,000 rows of a reference)


def _decode(raw, path, line_no):
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError as e:
        raise InputError(f"{path}:{line_no}, column {e.start + 1}: not UTF-8 text") from None


def _header(path, f):
    """(header cells, the header's line number, lines read) after the
    comments and blank lines before it."""
    n = 0
    for raw in f:
        n += 1
        if n == 1 and raw.startswith(b"\xef\xbb\xbf"):
            raw = raw[3:]
        s = _decode(raw, path, n).strip()
        if not s or s.startswith("#"):
            continue
        cells = [c.strip() for c in s.split(",")]
        seen = {}
        for i, c in enumerate(cells):
            if c in seen and c in COLUMNS:
                raise InputError(f"{path}:{n}: duplicated column {excerpt(c)} (columns {seen[c] + 1} and {i + 1})")
            seen.setdefault(c, i)
        missing = [c for c in COLUMNS if c not in seen]
        if missing:
            raise InputError(f"{path}:{n}: missing column {missing[0]} (expected {', '.join(COLUMNS)})")
        return cells, n
    raise InputError(f"--reference {path}: no rows")


class _Rows:
    """Growing arrays of the rows' times (n,), angles (n, 6) and line numbers."""

    def __init__(self):
        self.expected = 0  # rows the file's size suggests (the first growth's size)
        self.t, self.q, self.lines = np.empty(1024), np.empty((1024, 6)), np.empty(1024, dtype=np.int64)
        self.n = 0

    def add(self, values, line_numbers):
        m, n = len(values), self.n
        if n + m > len(self.t):
            size = max(2 * len(self.t), n + m, self.expected)
            t, q, lines = np.empty(size), np.empty((size, 6)), np.empty(size, dtype=np.int64)
            t[:n], q[:n], lines[:n] = self.t[:n], self.q[:n], self.lines[:n]
            self.t, self.q, self.lines = t, q, lines
        self.t[n:n + m], self.q[n:n + m], self.lines[n:n + m] = values[:, 0], values[:, 1:], line_numbers
        self.n += m

    def arrays(self):
        """(t, q, lines) of the rows read (copies when over 5 % of the space is unused)."""
        n = self.n
        if n < 0.95 * len(self.t):
            return self.t[:n].copy(), self.q[:n].copy(), self.lines[:n].copy()
        return self.t[:n], self.q[:n], self.lines[:n]


def _slow_block(path, texts, first_line, header, idx, rows):
    """A block walked row by row: comments and blank lines skipped, each
    cell of the seven columns parsed, the first bad one named."""
    values, numbers = [], []
    for k, s in enumerate(texts):
        n = first_line + k
        s = s.strip()
        if not s or s.startswith("#"):
            continue
        cells = s.split(",")
        if len(cells) != len(header):
            raise InputError(f"{path}:{n}: {len(cells)} fields, the header has {len(header)}")
        v = [parse_number(cells[i].strip(), f"{path}:{n}, column {i + 1} ({header[i]})") for i in idx]
        values.append(v)
        numbers.append(n)
    if values:
        rows.add(np.array(values), numbers)


def _fast_block(texts, header, idx):
    """The block's (m, 7) values by numpy.loadtxt when every line is a row
    of finite numbers with the header's field count; else None."""
    try:
        a = np.loadtxt(texts, delimiter=",", comments=None, ndmin=2, dtype=float)
    except ValueError:
        return None
    if a.shape != (len(texts), len(header)):  # a blank line skipped, or another field count
        return None
    a = a[:, idx]
    return a if np.isfinite(a).all() else None


def corrected_mark(path):
    """(line number, the line) of the corrected reference's mark among the
    comments before the header (identification/runs/logs.CORRECTED_MARK:
    `robstiff compensate-program` writes it), or None: none there, or a
    file not read here (its reader says why)."""
    from robstiff_drake.identification.runs.logs import is_corrected_mark

    try:
        with open(path, "rb") as f:
            for n, raw in enumerate(f, 1):
                s = raw.decode("utf-8", "replace").lstrip("\ufeff").strip()
                if s and not s.startswith("#"):
                    return None  # (the header: the mark comes before it)
                if is_corrected_mark(s):
                    return n, s
    except OSError:
        return None
    return None


def read_reference_rows(path):
    """(times s, q (N, 6) deg, line numbers (N,)) of a joint reference CSV
    as in the file (checks of the values against a robot: cell/safety.py's
    check_reference)."""
    path = Path(path)
    try:
        f = open(path, "rb")
    except OSError as e:
        raise InputError(f"--reference {path}: cannot read ({e.strerror})") from None
    with f:
        try:
            header, line = _header(path, f)
            idx = [header.index(c) for c in COLUMNS]
            rows = _Rows()
            while True:
                block = f.readlines(BLOCK_BYTES)
                if not block:
                    break
                if not rows.expected:  # the rows the file holds at the first block's bytes per line, and 2 % more
                    per_line = sum(map(len, block)) / len(block)
                    rows.expected = int(1.02 * os.fstat(f.fileno()).st_size / per_line) + 16
                try:
                    texts = b"".join(block).decode("utf-8").splitlines()
                except UnicodeDecodeError:
                    texts = None
                if texts is None or len(texts) != len(block):  # line by line: the bad byte's line, or a line
                    # break of another kind ('\r', form feed) inside a line
                    texts = [_decode(b, path, line + 1 + k).rstrip("\r\n") for k, b in enumerate(block)]
                a = _fast_block(texts, header, idx)
                if a is not None:
                    rows.add(a, np.arange(line + 1, line + 1 + len(texts)))
                else:
                    _slow_block(path, texts, line + 1, header, idx, rows)
                line += len(block)
        except OSError as e:
            raise InputError(f"--reference {path}: cannot read ({e.strerror})") from None
    if rows.n == 0:
        raise InputError(f"--reference {path}: no rows")
    return rows.arrays()
