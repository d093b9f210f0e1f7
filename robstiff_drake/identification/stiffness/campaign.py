"""Measurement campaigns, read from measurement tables
(identification/stiffness/measurement_table.py: CSV with a header row, ``#`` comment
lines, free column order, extra columns kept and ignored).  Plain numpy;
no Drake.

Stiffness campaigns (one row per loaded measurement):
  q1..q6      joint angles, deg, controller convention (Table 1)
  fx,fy,fz    force applied at the tool point, N, robot base frame
  mx,my,mz    optional moment applied about the tool point, N*m, base frame
  dx,dy,dz    measured tool-point displacement, mm, base frame (loaded minus unloaded)
  rx,ry,rz    optional measured tool rotation (small-angle vector), mrad, base frame
  pose        optional id shared by rows measured at the same pose
  seq         optional measurement order
  t_s         optional time of the measurement, s
A unit named in the header ('q1 [rad]', 'dx (m)') is converted to these,
and 'J1', 'A1', 'theta1' are read as q1 (header_units.py).

A stiffness campaign records its tool point in a comment line before the
header row, ``# tool_mm: x, y, z`` (mm, flange frame = DH frame 6; see
read_tool_header); the commands that read the file use it.

Payload campaigns (one row per static configuration):
  q1..q6      deg; fx,fy,fz (N) and mx,my,mz (N*m): the wrench the payload
  exerts on the sensor, in the sensor frame.

Every error is an InputError naming the file, line and column.
"""

from dataclasses import dataclass, field

import numpy as np

from robstiff_drake.errors import InputError, excerpt
from robstiff_drake.identification.stiffness.header_units import HeaderUnits
from robstiff_drake.identification.stiffness.measurement_table import header_line, read_table

Q_COLS = tuple(f"q{i}" for i in range(1, 7))
F_COLS = ("fx", "fy", "fz")
M_COLS = ("mx", "my", "mz")
D_COLS = ("dx", "dy", "dz")
R_COLS = ("rx", "ry", "rz")


@dataclass
class StiffnessCampaign:
    """A stiffness campaign in the model's units (see module docstring)."""

    path: str
    q_deg: np.ndarray  # (N, 6)
    force_N: np.ndarray  # (N, 3)
    moment_Nm: np.ndarray  # (N, 3), zeros when the file has none
    disp_mm: np.ndarray  # (N, 3)
    rot_mrad: np.ndarray | None  # (N, 3) or None
    pose: list | None
    seq: np.ndarray | None
    lines: np.ndarray
    comments: list
    has_moments: bool
    copies: list = field(default_factory=list)  # [(file line, line of the row it repeats)], set aside
    tool_mm: np.ndarray | None = None  # the file's '# tool_mm:' line (flange frame, mm), None without one
    t_s: np.ndarray | None = None  # optional time of each measurement (s)

    def __len__(self):
        return len(self.lines)

    @property
    def wrench(self):
        """(N, 6) wrench at the tool point, base frame (N, N*m)."""
        return np.hstack([self.force_N, self.moment_Nm])


def _optional_block(table, names, what):
    present = [n for n in names if n in table.numeric]
    if present and len(present) != len(names):
        missing = [n for n in names if n not in table.numeric]
        raise InputError(f"{table.path}:{table.header_line}: {what} columns need all of "
                         f"{','.join(names)}; missing {','.join(missing)}")
    return np.column_stack([table.numeric[n] for n in names]) if present else None


def check_joint_limits(table, robot):
    """Every row's q inside the robot's joint limits (error names line/column)."""
    lo, hi = np.rad2deg(robot.q_lower_rad), np.rad2deg(robot.q_upper_rad)
    largest = max(float(np.max(np.abs(table.numeric[name]), initial=0.0)) for name in Q_COLS)
    for j, name in enumerate(Q_COLS):
        v = table.numeric[name]
        bad = np.flatnonzero((v < lo[j] - 1e-9) | (v > hi[j] + 1e-9))
        if bad.size:
            r = bad[0]
            radians = (" Or angles in radians? Every angle of the file is within +-2 pi; write degrees, or name "
                       "the unit in the header: q1 [rad]") if 0 < largest <= 2.0 * np.pi + 1e-9 else ""
            raise InputError(f"{table.where(r, name)}: {v[r]:g} deg is outside the joint limit "
                             f"[{lo[j]:g}, {hi[j]:g}] deg of the robot {robot.name} ({robot.source}); another "
                             f"robot's campaign? (give its robot file with --robot).{radians}")


# Plausible sizes of a measured value; beyond these the file is in other
# units or corrupt.  100 kN and 100 kN*m are far beyond any robot's load
# test; a loaded robot's tool moves by a few mm, so 100 mm is a unit slip;
# 1 rad of tool rotation is not a small-deflection measurement.
RANGES = {**{c: (-1e5, 1e5, "N") for c in F_COLS}, **{c: (-1e5, 1e5, "N*m") for c in M_COLS},
          **{c: (-100.0, 100.0, "mm") for c in D_COLS}, **{c: (-1000.0, 1000.0, "mrad") for c in R_COLS},
          "seq": (-1e12, 1e12, ""), "t_s": (-1e12, 1e12, "s")}


def _copies(table, names):
    """Rows that repeat an earlier row in every measured value: [(row, first row)]."""
    cols = [table.numeric[n] for n in names if n in table.numeric]
    first, out = {}, []
    for i, key in enumerate(zip(*cols)):
        if key in first:
            out.append((i, first[key]))
        else:
            first[key] = i
    return out


def read_stiffness_campaign(path, robot, *, min_rows=6):
    header = HeaderUnits(path)  # units named in the header converted (identification/stiffness/header_units.py)
    table = read_table(path, required=Q_COLS + F_COLS + D_COLS, optional=M_COLS + R_COLS + ("seq", "t_s"),
                       text_columns=("pose",), ranges=RANGES, rename=header, units=header.scale)
    check_joint_limits(table, robot)
    disp_all = np.column_stack([table.numeric[n] for n in D_COLS])
    if np.all(disp_all == 0):
        raise InputError(f"{table.path}: all displacements dx,dy,dz are zero: nothing was measured")
    # a row that repeats another in every measured value is a copy, not a
    # second measurement (two real measurements differ by their noise)
    copies = _copies(table, Q_COLS + F_COLS + M_COLS + D_COLS + R_COLS + ("seq", "t_s"))
    if copies:
        drop = {i for i, _ in copies}
        keep = np.array([i for i in range(len(table)) if i not in drop])
        table.numeric = {k: v[keep] for k, v in table.numeric.items()}
        table.text = {k: [v[i] for i in keep] for k, v in table.text.items()}
        copy_lines = [(int(table.lines[i]), int(table.lines[j])) for i, j in copies]
        table.lines = table.lines[keep]
    else:
        copy_lines = []
    force = np.column_stack([table.numeric[n] for n in F_COLS])
    moments = _optional_block(table, M_COLS, "moment")
    rot = _optional_block(table, R_COLS, "rotation")
    n = len(table)
    if n < min_rows:
        dup = f" once {len(copy_lines)} copies of other rows are set aside" if copy_lines else ""
        raise InputError(f"{table.path}: {n} measurement rows{dup}, fewer than the {min_rows} unknowns "
                         f"(one compliance per joint); measure at least {min_rows}")
    load = np.abs(force).sum(axis=1) + (0 if moments is None else np.abs(moments).sum(axis=1))
    if np.all(load == 0):
        raise InputError(f"{table.path}: all forces{' and moments' if moments is not None else ''} are zero: "
                         "nothing loads the robot, so nothing can be identified")
    return StiffnessCampaign(
        path=table.path,
        q_deg=np.column_stack([table.numeric[n] for n in Q_COLS]),
        force_N=force,
        moment_Nm=np.zeros_like(force) if moments is None else moments,
        disp_mm=np.column_stack([table.numeric[n] for n in D_COLS]),
        rot_mrad=rot,
        pose=table.text.get("pose"),
        seq=table.numeric.get("seq"),
        lines=table.lines,
        comments=table.comments,
        has_moments=moments is not None,
        copies=copy_lines,
        tool_mm=read_tool_header(path),
        t_s=table.numeric.get("t_s"),
    )


@dataclass
class PayloadCampaign:
    path: str
    q_deg: np.ndarray  # (N, 6)
    force_N: np.ndarray  # (N, 3), sensor frame
    torque_Nm: np.ndarray  # (N, 3), sensor frame
    lines: np.ndarray
    comments: list

    def __len__(self):
        return len(self.lines)


def read_payload_campaign(path, robot):
    table = read_table(path, required=Q_COLS + F_COLS + M_COLS, ranges=RANGES)
    check_joint_limits(table, robot)
    force = np.column_stack([table.numeric[n] for n in F_COLS])
    torque = np.column_stack([table.numeric[n] for n in M_COLS])
    if np.all(force == 0) and np.all(torque == 0):
        raise InputError(f"{table.path}: all forces and torques are zero: the sensor saw no payload")
    return PayloadCampaign(table.path, np.column_stack([table.numeric[n] for n in Q_COLS]),
                           force, torque, table.lines, table.comments)


TOOL_KEY = "tool_mm"


def tool_header_line(tool_m):
    """The comment line that records a tool point (m) in a measurement file."""
    return "# " + TOOL_KEY + ": " + ", ".join(f"{v * 1e3:.6g}" for v in np.asarray(tool_m, dtype=float))


def read_tool_header(path):
    """The tool point (mm, flange frame) of a measurement file's
    ``# tool_mm: x, y, z`` line before its header row, or None without one.
    InputError (file and line) for a malformed or repeated line."""
    found = header_line(path, TOOL_KEY)
    if found is None:
        return None
    lineno, value = found
    try:
        tool = np.array([float(v.strip()) for v in value.split(",")])
    except ValueError:
        tool = np.array([])
    if tool.shape != (3,) or not np.all(np.isfinite(tool)) or np.any(np.abs(tool) > 5000.0):
        raise InputError(f"{path}:{lineno}: '# {TOOL_KEY}:' expects three numbers x, y, z within +-5000 mm (flange "
                         f"frame), got {excerpt(value)}")
    return tool


def campaign_tool_m(campaign, robot, tool_m=None, warnings=None):
    """The tool point (m) the measurements of ``campaign`` refer to: the
    file's ``# tool_mm:`` line; else ``tool_m`` (--tool); else the robot
    file's tool point (payload.tool_point_mm), with a warning.  A --tool
    that disagrees with the file's line is an InputError naming both."""
    fmt = lambda t: ", ".join(f"{v:g}" for v in np.round(np.asarray(t) * 1e3, 6))  # noqa: E731
    if campaign.tool_mm is not None:
        file_m = np.asarray(campaign.tool_mm, dtype=float) / 1e3
        if tool_m is not None and np.max(np.abs(np.asarray(tool_m) - file_m)) > 1e-9:
            raise InputError(f"--tool {fmt(tool_m)} mm disagrees with the tool point ({fmt(file_m)}) mm that "
                             f"{campaign.path} records in its '# {TOOL_KEY}:' line; drop --tool or correct the file")
        return _tool_in_mm(file_m, f"{campaign.path}'s '# {TOOL_KEY}:' line", warnings)
    if tool_m is not None:
        return _tool_in_mm(np.asarray(tool_m, dtype=float), "--tool", warnings)
    tool = robot.tool_point(where=f"{campaign.path} (it has no '# {TOOL_KEY}:' line and no --tool was given)")
    if warnings is not None:
        warnings.add(f"{campaign.path} has no '# {TOOL_KEY}:' line: its measurements are taken to be at the robot "
                     f"file's tool point ({fmt(tool)}) mm; record the tool point in the file or pass --tool")
    return tool


def _tool_in_mm(tool_m, where, warnings):
    """``tool_m``, with a warning when it sits within a few mm of the flange
    but not at it (a tool point written in metres)."""
    from robstiff_drake.identification.stiffness.interval_support import tool_looks_like_metres

    if warnings is not None and tool_looks_like_metres(tool_m):
        warnings.add(f"{where}: the tool point ({', '.join(f'{v * 1e3:g}' for v in tool_m)}) mm is "
                     f"{np.linalg.norm(tool_m) * 1e3:g} mm from the flange: a length in metres? (write mm)")
    return tool_m
