"""Measurement tables: CSV (comma, semicolon or tab) with a header row,
``#`` comment lines, free column order, extra columns kept and ignored,
whatever encoding a spreadsheet saved it in; numbers as measurement
programs write them.  Every error is an InputError naming the file, line
and column.  Plain numpy; no Drake.  The campaigns built on them are
identification/stiffness/campaign.py's and tracker_campaign.py's.

Decimal commas.  A spreadsheet or a CMM's software in a locale with a
decimal comma (German, French, ...) saves ';'-separated cells with '12,345'
for 12.345.  Such a file (';' or tab between the cells, and every number
with a fraction written with a comma, none with a point: ``_comma_column``)
is read as pandas reads it with ``decimal=","``, and said in a note
(``DECIMAL_COMMA_NOTE``).  Python's csv module splits the cells but converts
no number, and locale.atof follows the process's locale, not the file's; so
the conversion is here: the one comma becomes the point.  Refused in one
line: a '.' in a number of such a file (a thousands separator, '1.234,5', or
numbers written both ways), and a ','-separated file with decimal commas
(the comma both separates and marks the decimals: it cannot be told apart)."""

import csv
import difflib
import math
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from robstiff_drake.command import input_note, note_input
from robstiff_drake.errors import InputError, excerpt


@dataclass
class Table:
    """A parsed CSV: numeric columns as float arrays, text columns as lists."""

    path: str
    header_line: int
    columns: list  # names in file order (lower case)
    numeric: dict  # name -> float array
    text: dict  # name -> list of str (columns not parsed as numbers)
    lines: np.ndarray  # file line number of each row (1-based)
    comments: list = field(default_factory=list)
    encoding: str = "UTF-8"
    delimiter: str = "comma"
    decimal_comma: bool = False  # the numbers were read with decimal commas (a ';'- or tab-separated file)

    def __len__(self):
        return len(self.lines)

    def where(self, row, col=None):
        """'FILE:LINE' or 'FILE:LINE, column N (name)' for error messages."""
        s = f"{self.path}:{self.lines[row]}"
        if col is not None:
            s += f", column {self.columns.index(col) + 1} ({col})"
        return s


# A number as the files write it: ASCII digits, '.' for the decimal point,
# an optional exponent.  Python's float() also takes '1_000', '١٢' (Arabic-
# Indic digits) and '１２' (full-width), which no measurement program writes;
# they are refused rather than read as 1000 or 12.
NUMBER = re.compile(r"[+-]?(\d+(\.\d*)?|\.\d+)([eE][+-]?\d+)?", re.ASCII)
NON_FINITE = re.compile(r"[+-]?(nan|inf|infinity)", re.IGNORECASE)
DELIMITERS = {",": "comma", ";": "semicolon", "\t": "tab"}
MAX_FILE_BYTES = 200 * 1024 * 1024  # a campaign of a million rows is about 100 MB


def decode_text(path):
    """The text of a measurement file, whatever a spreadsheet saved it as:
    UTF-8 (with or without Excel's byte-order mark), UTF-16 (with its mark),
    or a Windows/Latin-1 code page.  Returns (text, encoding)."""
    path = Path(path)
    note_input(path)  # no output of the command may overwrite it
    try:
        if path.is_dir():
            raise InputError(f"{path}: is a folder, not a measurement file")
        if path.exists() and not path.is_file():
            raise InputError(f"{path}: not a regular file (a device, FIFO or socket), not a measurement file")
        size = path.stat().st_size
        if size > MAX_FILE_BYTES:
            raise InputError(f"{path}: {size / 1e6:.0f} MB is more than a measurement file can be "
                             f"({MAX_FILE_BYTES / 1e6:.0f} MB)")
        raw = path.read_bytes()
    except OSError as e:
        raise InputError(f"{path}: cannot read ({e.strerror})") from None
    if raw.startswith((b"\xff\xfe", b"\xfe\xff")):
        try:
            return raw.decode("utf-16"), "UTF-16"
        except UnicodeDecodeError:
            raise InputError(f"{path}: starts like UTF-16 but is not valid UTF-16 text") from None
    if b"\x00" in raw:
        raise InputError(f"{path}: not a text file (it holds NUL bytes; save it as CSV, not as a spreadsheet)")
    if raw.startswith(b"PK\x03\x04"):
        raise InputError(f"{path}: a zipped file (an .xlsx workbook?); save it as CSV")
    try:
        return raw.decode("utf-8-sig"), "UTF-8"
    except UnicodeDecodeError:
        return raw.decode("cp1252", errors="replace"), "Windows-1252"


def _delimiter(path, header_line, header_text, known, rename=None):
    """The delimiter of a header line: the one of ',', ';' and tab that splits
    it into the most known column names (a spreadsheet in a locale with a
    decimal comma saves with ';')."""
    best, best_hits = ",", -1
    for d in DELIMITERS:
        names = [h.strip().lower() for h in next(csv.reader([header_text], delimiter=d))]
        if rename is not None:
            names = [rename(h) for h in names]
        hits = sum(n in known for n in names)
        if hits > best_hits:
            best, best_hits = d, hits
    if best_hits <= 1 and any(d in header_text for d in (";", "\t")) and "," not in header_text:
        best = ";" if ";" in header_text else "\t"
    return best


def parse_number(v, where):
    """A cell as a finite float, or InputError naming the cell (quoted as a
    short, escaped excerpt)."""
    if v == "":
        raise InputError(f"{where}: empty cell")
    if NUMBER.fullmatch(v):
        x = float(v)
        if math.isfinite(x):
            return x
        raise InputError(f"{where}: {excerpt(v)} is too large to be a number")
    if NON_FINITE.fullmatch(v):
        raise InputError(f"{where}: {excerpt(v)} is not a finite number")
    if re.fullmatch(r"[+-]?\d+,\d+", v):
        raise InputError(f"{where}: {excerpt(v)} has a decimal comma in a ','-separated file (the comma cannot be "
                         f"both); save the file ';'-separated (decimal commas are read then) or write '.' decimals")
    if any(ch.isdigit() for ch in v) and not v.isascii():
        raise InputError(f"{where}: {excerpt(v)} is not a number in ASCII digits")
    raise InputError(f"{where}: {excerpt(v)} is not a number")


# A whole column of numbers, one per line, as the fast path checks it (the
# same numbers as NUMBER, spaces around them allowed).
_COLUMN = re.compile(r"(?:[ \t]*[+-]?(?:\d+(?:\.\d*)?|\.\d+)(?:[eE][+-]?\d+)?[ \t]*\n)*"
                     r"[ \t]*[+-]?(?:\d+(?:\.\d*)?|\.\d+)(?:[eE][+-]?\d+)?[ \t]*", re.ASCII)
DECIMAL_COMMA_NOTE = ("{path}: read with decimal commas ({delimiter}-separated cells, '0,5' read as 0.5), as a "
                      "spreadsheet in a decimal-comma locale saves them")


def _comma_file(cells, columns, delim):
    """Whether a ';'- or tab-separated table writes its numbers with decimal
    commas: a comma in any cell of the numeric ``columns``."""
    return delim != "," and any("," in row[c] for c in columns for row in cells)


def _comma_column(path, data, col, name, values):
    """A decimal-comma column's cells with the comma made a point, or
    InputError at the first cell holding a '.' (a thousands separator, or a
    number written with a point in a file of decimal commas)."""
    joined = "\n".join(values)
    if "." in joined:
        r = next(i for i, v in enumerate(values) if "." in v)
        first = next((f"line {data[i][0]}: {excerpt(v.strip())}" for i, v in enumerate(values) if "," in v), None)
        other = f" (as on {first})" if first else " (other columns' numbers have decimal commas)"
        raise InputError(f"{path}:{data[r][0]}, column {col + 1} ({name}): {excerpt(values[r].strip())} has a '.' in "
                         f"a file of decimal commas{other}: a thousands separator, or numbers written both ways; "
                         f"save the numbers without thousands separators, every decimal with ',' (or every one with "
                         f"'.')")
    return joined.replace(",", ".").split("\n") if "," in joined else values


def _numeric_column(path, data, cells, col, name, limits, decimal_comma=False, scale=(1.0, None)):
    """Column ``col`` as finite floats within ``limits`` (lo, hi, unit), or
    InputError naming the first bad cell.  Checked as one string (linear in
    the rows, in C) and converted at once; a column that fails is walked
    cell by cell for the message.  ``decimal_comma``: the file's numbers
    have decimal commas (``_comma_file``).  ``scale``: (factor, the file's
    unit): the values times factor are in the limits' unit."""
    written = [row[col] for row in cells]
    values = _comma_column(path, data, col, name, written) if decimal_comma else written
    arr = None
    if _COLUMN.fullmatch("\n".join(values)):
        arr = np.array(values, dtype=float)
        if not np.all(np.isfinite(arr)):
            arr = None
    if arr is None:
        arr = np.array([_parse_cell(v.strip(), w.strip(), f"{path}:{data[r][0]}, column {col + 1} ({name})")
                        for r, (v, w) in enumerate(zip(values, written))])
    factor, file_unit = scale
    if factor != 1.0:
        arr = arr * factor
    if limits is not None:
        lo, hi, unit = limits
        bad = np.flatnonzero(~((arr >= lo) & (arr <= hi)))
        if bad.size:
            r = int(bad[0])
            hint = "" if unit != "mm" else ": millimetres read as metres, then written in mm, are 1000x too large"
            shown = written[r].strip()
            # (the header's unit named once when it is the range's: '-224 mm', not '-224 mm (-224 mm)')
            value = shown if file_unit is None else f"{shown} {file_unit}" if factor == 1.0 and file_unit == unit \
                else f"{shown} {file_unit} ({arr[r]:g} {unit})"
            raise InputError(f"{path}:{data[r][0]}, column {col + 1} ({name}): {value} is outside the "
                             f"plausible range [{lo:g}, {hi:g}] {unit} (other units?){hint if file_unit is None else ''}")
    return arr


def _parse_cell(value, written, where):
    """``value`` (the cell, its decimal comma made a point) as parse_number
    reads it; an error quotes the cell as ``written``."""
    if value != written and NUMBER.fullmatch(value):
        x = float(value)
        if math.isfinite(x):
            return x
        raise InputError(f"{where}: {excerpt(written)} is too large to be a number")
    return parse_number(written, where)


def _split_decimals(values, header, numeric):
    """The hint for a ','-separated row with more cells than its header:
    the first place where two cells could be one number with a decimal
    comma ('' when none could)."""
    for j in range(min(len(values), len(header)) - 1):
        if header[j] in numeric and re.fullmatch(r"[ \t]*[+-]?\d+", values[j]) \
                and re.fullmatch(r"\d+(?:[eE][+-]?\d+)?[ \t]*", values[j + 1]):
            return (f"; from column {j + 1} ({header[j]}) on, {excerpt(values[j] + ',' + values[j + 1])} may be one "
                    f"number with a decimal comma, which a ','-separated file cannot tell from two cells: save it "
                    f"';'-separated (decimal commas are read then) or write '.' decimals")
    return ""


def read_table(path, *, required, optional=(), text_columns=(), ranges=None, rename=None, units=None):
    """Read a measurement CSV.  ``required``/``optional`` columns are parsed
    as finite floats (within ``ranges``: {column: (lo, hi, unit)}, when
    given); ``text_columns`` are kept as strings; any other column is kept
    as text and ignored.  ``rename``: a function from a header cell (lower
    case, stripped) to the column's name (aliases, units in the header);
    ``units``: a function from a column's name to (factor, the file's unit)
    that converts it to the unit of ``ranges`` before the check.  A ';'- or
    tab-separated file's decimal commas are read (the module docstring)."""
    path = Path(path)
    raw, encoding = decode_text(path)
    comments, rows = [], []
    for lineno, line in enumerate(raw.splitlines(), start=1):
        stripped = line.strip()
        if not stripped:
            continue
        if stripped.startswith("#"):
            comments.append(stripped[1:].strip())
            continue
        rows.append((lineno, line))
    if not rows:
        raise InputError(f"{path}: empty file (no header row and no data)")
    header_line, header_text = rows[0]
    known = set(required) | set(optional) | set(text_columns)
    delim = _delimiter(path, header_line, header_text, known, rename)
    header = [h.strip().lower() for h in next(csv.reader([header_text], delimiter=delim))]
    if rename is not None:
        header = [rename(h) for h in header]
    seen = {}
    for i, h in enumerate(header):
        if not h:
            raise InputError(f"{path}:{header_line}, column {i + 1}: empty column name in the header")
        if h in seen:
            raise InputError(f"{path}:{header_line}: duplicated column {excerpt(h)} (columns {seen[h] + 1} and {i + 1})")
        seen[h] = i
    for name in required:
        if name not in seen:
            unknown = [h for h in header if h not in known]
            close = difflib.get_close_matches(name, unknown, n=1, cutoff=0.5)
            hint = f" (is '{close[0]}' a misspelling?)" if close else ""
            other = [DELIMITERS[d] for d in DELIMITERS if d != delim and d in header_text]
            sep = f"; the header is {DELIMITERS[delim]}-separated" + (f" and also holds {other[0]}s" if other else "")
            raise InputError(f"{path}:{header_line}: missing column '{name}'{hint}; "
                             f"required: {','.join(required)}{sep if len(header) < 3 else ''}")
    data = rows[1:]
    if not data:
        raise InputError(f"{path}: no data rows after the header (line {header_line})")
    cells = list(csv.reader([line for _, line in data], delimiter=delim))
    numeric_names = [c for c in list(required) + list(optional) if c in seen]
    for (lineno, _), values in zip(data, cells):
        if len(values) != len(header):
            more = _split_decimals(values, header, numeric_names) \
                if delim == "," and len(values) > len(header) else ""
            raise InputError(f"{path}:{lineno}: expected {len(header)} cells (as in the header), got {len(values)}"
                             f"{more}")
    comma = _comma_file(cells, [seen[n] for n in numeric_names], delim)
    numeric = {}
    for name in numeric_names:
        numeric[name] = _numeric_column(path, data, cells, seen[name], name, (ranges or {}).get(name), comma,
                                        (1.0, None) if units is None else units(name))
    if comma:
        input_note(DECIMAL_COMMA_NOTE.format(path=path, delimiter=DELIMITERS[delim]))
    text = {h: [row[seen[h]].strip() for row in cells] for h in header if h not in numeric}
    return Table(str(path), header_line, header, numeric, text,
                 np.array([ln for ln, _ in data]), comments, encoding, DELIMITERS[delim], comma)


def header_line(path, key):
    """(line number, value text) of a measurement file's ``# KEY: VALUE``
    comment line before its header row (the key matched without case), or
    None without one; InputError (file and line) for a second such line.
    The one reading of the files' header keys (``tool_mm``, ``noise_mm``)."""
    raw, _ = decode_text(path)
    found = None
    for lineno, line in enumerate(raw.splitlines(), start=1):
        stripped = line.strip()
        if not stripped:
            continue
        if not stripped.startswith("#"):
            break  # the header row: comments after it are not the file's header
        name, sep, value = stripped[1:].partition(":")
        if name.strip().lower() != key or not sep:
            continue
        if found is not None:
            raise InputError(f"{path}:{lineno}: a second '# {key}:' line (the first is line {found[0]})")
        found = (lineno, value.strip())
    return found
