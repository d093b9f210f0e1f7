"""Absolute-position campaigns: a laser tracker's (or CMM's) accuracy
campaign, one row per measured pose.  Plain numpy; no Drake.

Columns (free order, extra columns kept and ignored, '#' comment lines):
  q1..q6      joint angles, the controller's degrees (as the pendant shows)
  x, y, z     the measured point, mm, in the instrument's own frame
  fx, fy, fz  optional: a force applied at the tool point, N, robot base frame
  t_s         optional: time of the measurement, s
  temp_c      optional: temperature, deg C (only its changes matter)
  seq, pose   optional: measurement order; rows measured at one pose

What real tracker exports hold is read as it comes: units in the header
('x [mm]', 'X (m)', 'x_mm', 'q1 [deg]', 'time (min)'), common names
('J1', 'A1', 'joint_1', 'axis1', 'meas_x', 'measurement_x', 'temperature',
'time'), a ';' or tab separator with decimal commas.  A unit named in the
header is converted; positions without one are in mm unless the arm's reach
says otherwise (``position_scale``: metres and inches are told from the
spread of the points against the nominal arm's), which is an error naming
what was found.  Angles named as radians are converted to degrees.
"""

import re
from dataclasses import dataclass, field

import numpy as np

from robstiff_drake.errors import InputError
from robstiff_drake.identification.stiffness.campaign import Q_COLS, check_joint_limits, read_tool_header
from robstiff_drake.identification.stiffness.measurement_table import read_table

XYZ = ("x", "y", "z")
F_COLS = ("fx", "fy", "fz")
POS_UNITS = {"mm": 1.0, "m": 1000.0, "cm": 10.0, "in": 25.4, "inch": 25.4, "inches": 25.4, "um": 1e-3}
ANGLE_UNITS = {"deg": 1.0, "degree": 1.0, "degrees": 1.0, "rad": 180.0 / np.pi}
TIME_UNITS = {"s": 1.0, "sec": 1.0, "ms": 1e-3, "min": 60.0, "h": 3600.0}
TEMP_UNITS = {"c": 1.0, "degc": 1.0, "k": 1.0}  # only changes of temperature are used
FORCE_UNITS = {"n": 1.0, "kn": 1000.0}
UNIT_WORDS = set(POS_UNITS) | set(ANGLE_UNITS) | set(TIME_UNITS) | set(TEMP_UNITS) | set(FORCE_UNITS)

_BRACKET = re.compile(r"^(.*?)\s*[\[(]\s*([^\])]*)\s*[\])]\s*$")
_NAMES = [
    (re.compile(r"^(?:q|j|a|joint|axis|theta)_?([1-6])$"), lambda m: f"q{m.group(1)}"),
    (re.compile(r"^(?:(?:meas(?:ured|urement)?|tracker|pos(?:ition)?|actual|tcp|point|p)_?)?([xyz])$"),
     lambda m: m.group(1)),
    (re.compile(r"^(?:f|force)_?([xyz])$"), lambda m: f"f{m.group(1)}"),
    (re.compile(r"^(?:t|time|elapsed|elapsed_time)$"), lambda m: "t_s"),
    (re.compile(r"^(?:(?:meas(?:ured|urement)?|air|ambient)_)?(?:temp|temperature)$"), lambda m: "temp_c"),
    (re.compile(r"^(?:seq|sequence|order)$"), lambda m: "seq"),
    (re.compile(r"^(?:pose|pose_id)$"), lambda m: "pose"),
]
# the kind of unit each column takes
UNIT_KIND = {**{q: ANGLE_UNITS for q in Q_COLS}, **{c: POS_UNITS for c in XYZ}, **{c: FORCE_UNITS for c in F_COLS},
             "t_s": TIME_UNITS, "temp_c": TEMP_UNITS}
MIN_POSES = 4  # fewer distinct poses cannot register the instrument's frame (6 unknowns) and test it
# A pose id names one pose: its rows (measured there again, or under a load)
# have the same commanded joint angles, their encoders within a few
# hundredths of a degree.  Rows of one id further apart than this are two
# poses under one name (the folds would hold them out together).
POSE_SPREAD_DEG = 1.0


def split_unit(cell):
    """'x [mm]' -> ('x', 'mm'); 'x_mm' -> ('x', 'mm'); 'q1' -> ('q1', None)."""
    text = cell.strip().lower().replace("°", "deg").replace("µ", "u")
    m = _BRACKET.match(text)
    if m and m.group(1):
        return re.sub(r"[\s\-]+", "_", m.group(1).strip()), m.group(2).strip().replace(" ", "")
    text = re.sub(r"[\s\-]+", "_", text)
    head, sep, tail = text.rpartition("_")
    if sep and head and tail in UNIT_WORDS:
        return head, tail
    return text, None


class _Renamer:
    """Header cell -> column name, recording the unit each column states."""

    def __init__(self):
        self.units = {}
        self.raw = {}

    def __call__(self, cell):
        name, unit = split_unit(cell)
        for pattern, make in _NAMES:
            m = pattern.match(name)
            if m:
                canon = make(m)
                if unit is not None:
                    self.units[canon] = unit
                self.raw[canon] = cell
                return canon
        return cell.strip().lower()


@dataclass
class TrackerCampaign:
    """An absolute-position campaign (see the module docstring)."""

    path: str
    q_deg: np.ndarray  # (N, 6) controller degrees
    pos: np.ndarray  # (N, 3) the measured point, in pos_unit_mm * mm, instrument frame
    pos_unit_mm: float | None  # mm per file unit when the header names it; None: decided from the reach
    force_N: np.ndarray | None  # (N, 3) base frame, None without the columns
    t_s: np.ndarray | None
    temp_c: np.ndarray | None
    seq: np.ndarray | None
    pose: list | None
    lines: np.ndarray
    comments: list
    units: dict = field(default_factory=dict)  # column -> unit as the header states it
    tool_mm: np.ndarray | None = None  # the file's '# tool_mm:' line (a first guess of the measured point)

    def __len__(self):
        return len(self.lines)

    @property
    def pos_mm(self):
        if self.pos_unit_mm is None:
            raise ValueError("the position unit is not decided yet (position_scale)")
        return self.pos * self.pos_unit_mm


def _scale(table, name, units, kinds):
    unit = units.get(name)
    if unit is None:
        return 1.0
    if unit not in kinds:
        raise InputError(f"{table.path}:{table.header_line}, column {table.columns.index(name) + 1}: unit "
                         f"'{unit}' of {name} not understood (known: {', '.join(sorted(kinds))})")
    return kinds[unit]


def is_tracker_file(path):
    """Whether a measurement file is an absolute-position campaign (x, y, z
    columns and no dx, dy, dz): from its header row only."""
    from robstiff_drake.identification.stiffness.measurement_table import decode_text

    raw, _ = decode_text(path)
    for line in raw.splitlines():
        s = line.strip()
        if not s or s.startswith("#"):
            continue
        cells = [c for c in re.split(r"[,;\t]", s)]
        ren = _Renamer()
        names = {ren(c) for c in cells}
        return set(XYZ) <= names and not {"dx", "dy", "dz"} & names
    return False


def read_tracker_campaign(path, robot):
    """Read an absolute-position campaign (see the module docstring)."""
    ren = _Renamer()
    table = read_table(path, required=Q_COLS + XYZ, optional=F_COLS + ("t_s", "temp_c", "seq"),
                       text_columns=("pose",), ranges={**{c: (-1e6, 1e6, "") for c in XYZ}},
                       rename=ren)
    for q in Q_COLS:
        table.numeric[q] = table.numeric[q] * _scale(table, q, ren.units, ANGLE_UNITS)
    check_joint_limits(table, robot)
    forces = None
    present = [c for c in F_COLS if c in table.numeric]
    if present:
        if len(present) != 3:
            raise InputError(f"{table.path}:{table.header_line}: force columns need all of fx,fy,fz")
        forces = np.column_stack([table.numeric[c] * _scale(table, c, ren.units, FORCE_UNITS) for c in F_COLS])
        if not np.any(forces):
            forces = None
    pos_units = {ren.units.get(c) for c in XYZ}
    if len(pos_units) > 1:
        raise InputError(f"{table.path}:{table.header_line}: x, y, z name different units ({pos_units})")
    unit = pos_units.pop()
    pos_unit_mm = None if unit is None else _scale(table, "x", ren.units, POS_UNITS)
    pos = np.column_stack([table.numeric[c] for c in XYZ])
    t = table.numeric.get("t_s")
    if t is not None:
        t = t * _scale(table, "t_s", ren.units, TIME_UNITS)
    temp = table.numeric.get("temp_c")
    if temp is not None:
        _scale(table, "temp_c", ren.units, TEMP_UNITS)
    q = np.column_stack([table.numeric[c] for c in Q_COLS])
    distinct = len(np.unique(np.round(q, 6), axis=0))
    if distinct < MIN_POSES:
        raise InputError(f"{table.path}: {distinct} distinct pose(s); registering the instrument's frame to the "
                         f"robot (6 unknowns) and testing it needs at least {MIN_POSES}")
    _check_pose_ids(table, q)
    return TrackerCampaign(path=table.path, q_deg=q, pos=pos, pos_unit_mm=pos_unit_mm, force_N=forces, t_s=t,
                           temp_c=temp, seq=table.numeric.get("seq"), pose=table.text.get("pose"),
                           lines=table.lines, comments=table.comments, units=dict(ren.units),
                           tool_mm=read_tool_header(path))


def _check_pose_ids(table, q):
    """InputError when the ``pose`` column names fewer than MIN_POSES poses,
    or one id covers rows whose joint angles differ by more than
    POSE_SPREAD_DEG (naming the row's line and the id's first line)."""
    labels = table.text.get("pose")
    if labels is None:
        return
    labels = [str(v) for v in labels]
    first = {}
    for i, name in enumerate(labels):
        j = first.setdefault(name, i)
        d = np.abs(q[i] - q[j])
        if d.max() > POSE_SPREAD_DEG:
            k = int(np.argmax(d))
            raise InputError(f"{table.path}:{table.lines[i]}: pose {name!r} has q{k + 1} = {q[i, k]:g} deg here, "
                             f"{d[k]:.3g} deg from its first row (line {table.lines[j]}): a pose id names one pose "
                             "(rows measured there again); give each pose its own id, or leave the pose column out")
    if len(first) < MIN_POSES:
        raise InputError(f"{table.path}: the pose column names {len(first)} pose(s); registering the instrument's "
                         f"frame and holding poses out to test it needs at least {MIN_POSES}")


def spread(points):
    """RMS distance of points (N, 3) from their centroid."""
    p = np.asarray(points, dtype=float)
    return float(np.sqrt(np.mean(np.sum((p - p.mean(axis=0)) ** 2, axis=1))))


class UnmatchedSpread(InputError):
    """The measured points' spread matches the nominal arm's in no length
    unit (another arm, or joint angles read another way: the diagnosis then
    tries the angles' readings before it refuses)."""


def position_scale(campaign, nominal_mm):
    """Decide the unit of positions the header does not name, from the
    spread of the measured points against that of the nominal arm's tool
    points at the same angles (``nominal_mm``, (N, 3)): registration moves
    the points, it does not change their spread.  Sets and returns
    ``campaign.pos_unit_mm``; InputError for metres, inches or a spread that
    matches no length unit (another arm?)."""
    if campaign.pos_unit_mm is not None:
        return campaign.pos_unit_mm
    s_meas, s_nom = spread(campaign.pos), spread(nominal_mm)
    ratio = s_meas / s_nom if s_nom > 0 else np.inf
    what = (f"{campaign.path}: x, y, z spread by {s_meas:.4g} (RMS about their centroid) where the nominal arm's "
            f"tool points at these angles spread by {s_nom:.4g} mm")
    if 0.5 <= ratio <= 2.0:
        campaign.pos_unit_mm = 1.0
        return 1.0
    for unit, factor in (("metres", 1000.0), ("inches", 25.4), ("cm", 10.0)):
        if 0.5 <= ratio * factor <= 2.0:
            tag = {"metres": "x_m or 'x [m]'", "inches": "x_in or 'x [in]'", "cm": "x_cm or 'x [cm]'"}[unit]
            raise InputError(f"{what}: the positions look like {unit}, not mm; write mm or name the unit in the "
                             f"header ({tag})")
    raise UnmatchedSpread(f"{what} ({ratio:.3g}x): no length unit makes them match; is the robot file for this arm, and "
                     "are q1..q6 its controller's angles?")
