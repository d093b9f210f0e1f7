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
import stat
from pathlib import Path

import numpy as np

from robstiff_drake.errors import InputError, excerpt
from robstiff_drake.identification.stiffness.measurement_table import parse_number

COLUMNS = ["t_s"] + [f"q{j}_deg" for j in range(1, 7)]
BLOCK_BYTES = 1 << 22  # bytes read at a time (about 50,000 rows of a reference), cut at the last line's end
# The longest line read (bytes): a row is seven numbers (about 100 bytes) and perhaps a few extra columns; a
# line longer than this is no row and is refused as soon as this much of it has been read (a file of one
# endless line, /dev/zero or a sparse file's gigabyte of NUL bytes, is not read whole to find its end).
MAX_LINE_BYTES = 1 << 16


def _long_line(path, line_no):
    return InputError(f"{path}:{line_no}: a line longer than {MAX_LINE_BYTES} bytes: not a row of a joint reference "
                      f"(columns {', '.join(COLUMNS)})")


def _lines(path, f, first_line):
    """(line number, line bytes) from ``f`` one at a time, each at most
    MAX_LINE_BYTES (a longer one: InputError naming its line)."""
    n = first_line
    while True:
        raw = f.readline(MAX_LINE_BYTES + 1)
        if not raw:
            return
        n += 1
        if len(raw) > MAX_LINE_BYTES and not raw.endswith(b"\n"):
            raise _long_line(path, n)
        yield n, raw


def _blocks(path, f, first_line):
    """(bytes of whole lines, their count), about BLOCK_BYTES at a time (each
    line ends with '\\n' but perhaps the file's last); a line longer than
    MAX_LINE_BYTES is an InputError naming it, found before more of it is read."""
    carry, line = b"", first_line
    while True:
        data = f.read(BLOCK_BYTES)
        if not data:
            if carry:
                yield carry, 1
            return
        data = carry + data if carry else data
        cut = data.rfind(b"\n") + 1
        carry = data[cut:]
        n = data.count(b"\n", 0, cut)
        if len(carry) > MAX_LINE_BYTES:
            raise _long_line(path, line + n + 1)
        if cut:
            line += n
            yield (data[:cut] if carry else data), n


def _decode(raw, path, line_no):
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError as e:
        raise InputError(f"{path}:{line_no}, column {e.start + 1}: not UTF-8 text") from None


def _header(path, f):
    """(header cells, the header's line number, lines read) after the
    comments and blank lines before it."""
    for n, raw in _lines(path, f, 0):
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
    from robstiff_drake.identification.runs.logs import is_corrected_mark

    values, numbers = [], []
    for k, s in enumerate(texts):
        n = first_line + k
        s = s.strip()
        if s.startswith("#") and is_corrected_mark(s):
            raise InputError(f"{path}:{n}: a corrected-reference mark after the header (robstiff compensate-program "
                             "writes it before the header, on the first line; where it is, the file is not taken "
                             "for a corrected one and would be corrected twice): if the file is a corrected "
                             "reference, move the line before the header and give --reference-is-corrected; else "
                             "delete it")
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
        if not stat.S_ISREG(os.stat(path).st_mode):
            return None  # (a FIFO would block the open: the reader refuses it)
        with open(path, "rb") as f:
            for n, raw in _lines(path, f, 0):
                s = raw.decode("utf-8", "replace").lstrip("\ufeff").strip()
                if s and not s.startswith("#"):
                    return None  # (the header: the mark comes before it)
                if is_corrected_mark(s):
                    return n, s
    except (OSError, InputError):
        return None  # (a line too long: the reader says so)
    return None


def read_reference_rows(path):
    """(times s, q (N, 6) deg, line numbers (N,)) of a joint reference CSV
    as in the file (checks of the values against a robot: cell/safety.py's
    check_reference)."""
    path = Path(path)
    try:
        if not stat.S_ISREG(os.stat(path).st_mode):  # (before the open: a FIFO would block it)
            what = "a folder" if stat.S_ISDIR(os.stat(path).st_mode) else "a device, FIFO or socket"
            raise InputError(f"--reference {path}: {what}, not a file of joint references")
        f = open(path, "rb")
    except OSError as e:
        raise InputError(f"--reference {path}: cannot read ({e.strerror})") from None
    with f:
        try:
            header, line = _header(path, f)
            idx = [header.index(c) for c in COLUMNS]
            rows = _Rows()
            for chunk, lines in _blocks(path, f, line):
                if not rows.expected:  # the rows the file holds at the first block's bytes per line, and 2 % more
                    per_line = len(chunk) / lines
                    rows.expected = int(1.02 * os.fstat(f.fileno()).st_size / per_line) + 16
                try:
                    texts = chunk.decode("utf-8").splitlines()
                except UnicodeDecodeError:
                    texts = None
                if texts is None or len(texts) != lines:  # line by line: the bad byte's line, or a line
                    # break of another kind ('\r', form feed) inside a line
                    block = chunk.split(b"\n")[:lines]
                    texts = [_decode(b, path, line + 1 + k).rstrip("\r") for k, b in enumerate(block)]
                a = _fast_block(texts, header, idx)
                if a is not None:
                    rows.add(a, np.arange(line + 1, line + 1 + len(texts)))
                else:
                    _slow_block(path, texts, line + 1, header, idx, rows)
                line += lines
        except OSError as e:
            raise InputError(f"--reference {path}: cannot read ({e.strerror})") from None
    if rows.n == 0:
        raise InputError(f"--reference {path}: no rows")
    return rows.arrays()
