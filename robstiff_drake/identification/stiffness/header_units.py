"""A stiffness campaign's header as measurement software and other
projects write it: a unit named in the header (``q1 [rad]``, ``dx (m)``,
``dx_mm``, ``fx [kN]``) is converted to the campaign's own (deg, mm, N,
N*m, mrad, s), and the joints' common names (``J1``, ``A1``, ``joint_1``,
``axis1``, ``theta1``) are read as ``q1``.  A header without units reads
as before: the campaign's units.  Plain Python; no Drake.

Why: a campaign exported in SI units (joint angles in rad, displacements
in m, as a FANUC R-2000iC campaign from a published study is) was refused
with "missing column 'q1'" though its header said ``q1 [rad]``."""

import math
import re

from robstiff_drake.errors import InputError

ANGLE = {"deg": 1.0, "degree": 1.0, "degrees": 1.0, "rad": 180.0 / math.pi}
LENGTH = {"mm": 1.0, "m": 1000.0, "cm": 10.0, "um": 1e-3, "in": 25.4, "inch": 25.4}
FORCE = {"n": 1.0, "kn": 1000.0}
MOMENT = {"nm": 1.0, "n*m": 1.0, "n.m": 1.0, "n_m": 1.0, "knm": 1000.0}
ROTATION = {"mrad": 1.0, "rad": 1000.0, "urad": 1e-3, "deg": 1000.0 * math.pi / 180.0}
TIME = {"s": 1.0, "ms": 1e-3, "min": 60.0}
# (pattern of a header name without its unit, the column it is, the units it takes)
_NAMES = [
    (re.compile(r"^(?:q|j|a|joint|axis|theta)_?([1-6])$"), "q{}", ANGLE),
    (re.compile(r"^(?:f|force)_?([xyz])$"), "f{}", FORCE),
    (re.compile(r"^(?:m|moment)_?([xyz])$"), "m{}", MOMENT),
    (re.compile(r"^(?:d|delta)_?([xyz])$"), "d{}", LENGTH),
    (re.compile(r"^(?:r|rot)_?([xyz])$"), "r{}", ROTATION),
    (re.compile(r"^(?:t|time)()$"), "t_s", TIME),
]
_BRACKET = re.compile(r"^(.*?)\s*[\[(]\s*([^\])]*?)\s*[\])]\s*$")
_SUFFIX_UNITS = set(ANGLE) | set(LENGTH) | set(FORCE) | {"nm", "knm"} | set(ROTATION) | set(TIME)


def split_unit(cell):
    """'q1 [rad]' -> ('q1', 'rad'); 'dx_mm' -> ('dx', 'mm'); 'q1' -> ('q1', None)."""
    text = cell.strip().lower().replace("µ", "u").replace("°", "deg")
    m = _BRACKET.match(text)
    if m and m.group(1):
        return re.sub(r"[\s\-]+", "_", m.group(1).strip()), m.group(2).replace(" ", "")
    text = re.sub(r"[\s\-]+", "_", text)
    head, sep, tail = text.rpartition("_")
    if sep and head and tail in _SUFFIX_UNITS and any(p.match(head) for p, _, _ in _NAMES):
        return head, tail
    return text, None


class HeaderUnits:
    """The ``rename`` of measurement_table.read_table for a stiffness
    campaign; records the unit each column's header names, and gives each
    column's factor to the campaign's unit (``scale``)."""

    def __init__(self, path):
        self.path = path
        self.units = {}  # column -> (factor to the campaign's unit, the unit as the header wrote it)

    def __call__(self, cell):
        name, unit = split_unit(cell)
        for pattern, canon, kinds in _NAMES:
            m = pattern.match(name)
            if not m:
                continue
            if kinds is TIME and unit is None:
                break  # a bare 't' or 'time' (a clock's '10:32:15', say) stays an extra column, ignored
            column = canon.format(m.group(1))
            # (read_table calls this for each delimiter it tries, then for the header it keeps: the last call wins)
            self.units.pop(column, None)
            if unit is not None:
                self.units[column] = (kinds.get(unit), unit, cell.strip(), kinds)
            return column
        return cell.strip().lower()

    def scale(self, column):
        """(factor, the header's unit) of ``column``; (1.0, None) without a
        unit in the header; InputError for a unit the column does not take."""
        if column not in self.units:
            return 1.0, None
        factor, unit, cell, kinds = self.units[column]
        if factor is None:
            raise InputError(f"{self.path}: header column {cell!r}: unit '{unit}' of {column} not understood "
                             f"(known: {', '.join(sorted(kinds))})")
        return factor, unit
