"""The scenario's toolpath section: its G-code program read (with the
section's decimal-point and block-delete settings), placed on the
workpiece by the work offset (toolpath.work_offset_mm, or ``simulate
--work-offset X,Y,Z[,ROT_DEG]``), its feed and spindle speed given to the
force model, and checked against the scenario before anything runs: the
tool its comment names against the cutter, a program whose cuts miss the
workpiece (one line with both extents and the offset that would place
it), a rapid move into uncut stock.  docs/toolpaths.md describes it."""

import math
from dataclasses import fields

import numpy as np

from robstiff_drake.errors import InputError
from robstiff_drake.model.gcode.program import read_program_file
from robstiff_drake.model.program_checks import StockCheck, cut_extent

# The program's tool comment and the scenario's cutter may differ by
# rounding (a post writes 0.001 mm, or 0.0001 in = 0.00254 mm); more is
# another tool.
TOOL_DIAMETER_TOLERANCE_MM = 0.05


def _field_meta(cls, name):
    return next(f for f in fields(cls) if f.name == name).metadata["schema"]


def parse_work_offset(text, toolpath_cls):
    """``--work-offset X,Y,Z[,ROT_DEG]`` -> (offset_mm [3], rotation_deg
    or None), each within the scenario's ranges for
    toolpath.work_offset_mm and toolpath.work_rotation_deg (InputError)."""
    parts = [p.strip() for p in str(text).split(",")]
    if len(parts) not in (3, 4):
        raise InputError(f"--work-offset: expected X,Y,Z (mm) or X,Y,Z,ROT_DEG, got {text!r}")
    ranges = [_field_meta(toolpath_cls, "work_offset_mm")] * 3 + [_field_meta(toolpath_cls, "work_rotation_deg")]
    values = []
    for i, (p, m) in enumerate(zip(parts, ranges)):
        try:
            v = float(p)
        except ValueError:
            raise InputError(f"--work-offset: component {i + 1} {p!r} is not a number") from None
        if not (math.isfinite(v) and m["lo"] <= v <= m["hi"]):
            raise InputError(f"--work-offset: component {i + 1} {p!r} is outside the allowed range "
                             f"[{m['lo']:g}, {m['hi']:g}] {m['unit']}")
        values.append(v)
    return values[:3], (values[3] if len(values) == 4 else None)


def parse_stock(text, max_coord_mm):
    """``--stock X0,X1,Y0,Y1,TOP`` (mm, base frame) -> one workpiece box
    [x0, x1, y0, y1, top] (InputError naming the bad part)."""
    parts = [p.strip() for p in str(text).split(",")]
    names = ("X0", "X1", "Y0", "Y1", "TOP")
    if len(parts) != 5:
        raise InputError(f"--stock: expected X0,X1,Y0,Y1,TOP (mm, the robot's base frame), got {text!r}")
    values = []
    for name, p in zip(names, parts):
        try:
            v = float(p)
        except ValueError:
            raise InputError(f"--stock: {name} {p!r} is not a number") from None
        if not (math.isfinite(v) and abs(v) <= max_coord_mm):
            raise InputError(f"--stock: {name} {p!r} is outside the allowed range [{-max_coord_mm:g}, "
                             f"{max_coord_mm:g}] mm")
        values.append(v)
    if not (values[0] < values[1] and values[2] < values[3]):
        raise InputError(f"--stock: X0 < X1 and Y0 < Y1 are needed (the block's corners), got {text!r}")
    return values


def work_transform(tp):
    """program point (mm, work frame) -> base frame (m): the work offset
    and a rotation about z (toolpath section ``tp``)."""
    to_mm = work_transform_mm(tp)

    def transform(p_mm):
        return to_mm(np.asarray(p_mm, dtype=float)) / 1e3

    return transform


def work_transform_mm(tp):
    """As work_transform, mm to mm, for points (..., 3)."""
    c, s = math.cos(math.radians(tp.work_rotation_deg)), math.sin(math.radians(tp.work_rotation_deg))
    R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    offset = np.asarray(tp.work_offset_mm, dtype=float)

    def transform(p_mm):
        return np.asarray(p_mm, dtype=float) @ R.T + offset

    return transform


def read_program(sc, path):
    """The program of the scenario's toolpath section (model/gcode.Program), read once."""
    prog = getattr(sc, "_program", None)
    tp = sc.toolpath
    key = (str(path), tp.decimal_point, tp.block_delete)
    if prog is None or getattr(sc, "_program_key", None) != key:
        label = getattr(sc, "_program_label", None) or path  # (--toolpath: as the user wrote it)
        prog = sc._program = read_program_file(path, label, decimal_point=tp.decimal_point,
                                               block_delete=tp.block_delete)
        sc._program_key = key
    return prog


def feeds_and_speeds(prog):
    """({feed mm/min: cutting length mm}, {spindle rpm: cutting length mm})."""
    feeds, speeds = {}, {}
    for m in prog.moves:
        if m.kind == "rapid":
            continue
        length = m.length_mm()
        feeds[m.feed_mm_per_min] = feeds.get(m.feed_mm_per_min, 0.0) + length
        if m.spindle_rpm:
            speeds[m.spindle_rpm] = speeds.get(m.spindle_rpm, 0.0) + length
    return feeds, speeds


def check_tool(sc, prog, fail):
    """The diameter the program's tool comment gives against cutter.diameter_mm."""
    d = prog.tool_diameter_mm
    if d is None or abs(d - sc.cutter.diameter_mm) <= TOOL_DIAMETER_TOLERANCE_MM:
        return
    fail("cutter.diameter_mm", f"{sc.cutter.diameter_mm:g} mm, but the program's tool (T{prog.tool_number}, "
                               f"{prog.path}:{prog.tool_line}) is {d:.4g} mm: the program was posted for another "
                               "cutter; set cutter.diameter_mm to the program's tool")


def placement_message(sc, prog):
    """The one line for a program whose cuts never come below a box's top
    while over it: both extents, and the work offset that would place it."""
    tp = sc.toolpath
    ext = cut_extent(prog.moves)
    boxes = np.asarray(sc.workpiece.boxes_mm, dtype=float)
    bx0, bx1, by0, by1 = boxes[:, 0].min(), boxes[:, 1].max(), boxes[:, 2].min(), boxes[:, 3].max()
    top = boxes[:, 4].max()
    wp = (f"the workpiece spans X {bx0:g}..{bx1:g}, Y {by0:g}..{by1:g} mm, top at Z {top:g} mm (base frame)")
    if ext is None:
        return f"{prog.path}: no cutting move (G1, G2, G3) in the program; {wp}"
    lo, hi = ext
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    base = work_transform_mm(tp)(corners)
    blo, bhi = base.min(axis=0), base.max(axis=0)
    # the offset that puts the middle of the cuts over the workpiece's middle and Z0 on its top
    c, s = math.cos(math.radians(tp.work_rotation_deg)), math.sin(math.radians(tp.work_rotation_deg))
    mx, my = (lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2
    ox, oy = (bx0 + bx1) / 2 - (c * mx - s * my), (by0 + by1) / 2 - (s * mx + c * my)
    rot = f",{tp.work_rotation_deg:g}" if tp.work_rotation_deg else ""
    deeper = "" if lo[2] < 0 else f" (its cuts are at Z {lo[2]:g} and above: lower Z by the depth of cut)"
    return (f"{prog.path}: the program's cuts span X {lo[0]:g}..{hi[0]:g}, Y {lo[1]:g}..{hi[1]:g}, Z {lo[2]:g}.."
            f"{hi[2]:g} mm (its frame), at X {blo[0]:.6g}..{bhi[0]:.6g}, Y {blo[1]:.6g}..{bhi[1]:.6g}, Z "
            f"{blo[2]:.6g}..{bhi[2]:.6g} mm in the base frame with the work offset "
            f"{', '.join(f'{v:g}' for v in tp.work_offset_mm)} mm; {wp}: the cutter never comes below the top while "
            f"over it. Place the program with --work-offset X,Y,Z[,ROT_DEG] or toolpath.work_offset_mm: "
            f"--work-offset {ox:.6g},{oy:.6g},{top:g}{rot} puts the middle of its cuts over the workpiece's middle "
            f"and its Z0 on the top{deeper}")


def check_stock(sc, prog):
    """InputError at the first move that runs the cutter into uncut stock
    (a rapid, or a feed with the spindle stopped)."""
    check = StockCheck(sc.workpiece.boxes_mm, sc.cutter.diameter_mm / 2, work_transform_mm(sc.toolpath))
    hit = check.start_offence(prog.start_mm)
    if hit is not None:
        p, k, depth = hit
        start = ", ".join(f"{v:g}" for v in prog.start_mm)
        where = f"{prog.path}:{prog.start_line}" if prog.start_line else prog.path
        raise InputError(f"{where}: the program starts at ({start}) (the first point it fixes in X, Y and Z, by "
                         f"whatever motion word is modal), {depth:.3g} mm below the top of workpiece box {k + 1} "
                         f"where nothing has been cut (at base-frame X {p[0]:.6g}, Y {p[1]:.6g}, Z {p[2]:.6g} mm): the "
                         "cutter would be brought there through the stock, a crash on a machine; start above the "
                         "workpiece (a G0 to a safe Z first)")
    hit = check.first_offence(prog.moves)
    if hit is None:
        return
    m, p, k, depth = hit
    what = "a rapid move (G0)" if m.kind == "rapid" else "a feed move with the spindle stopped (M5 or S0)"
    end = ", ".join(f"{v:g}" for v in m.end_mm)
    raise InputError(f"{prog.path}:{m.line}: {what} to ({end}) runs the {sc.cutter.diameter_mm:g} mm cutter "
                     f"{depth:.3g} mm below the top of workpiece box {k + 1} where no earlier cut has removed the "
                     f"material (at base-frame X {p[0]:.6g}, Y {p[1]:.6g}, Z {p[2]:.6g} mm): a crash on a machine; "
                     "feed it in with G1 and the spindle on, or retract first")


def program_warnings(sc):
    """The program's own warnings, and its feeds and speeds if several."""
    prog = getattr(sc, "_program", None)
    if prog is None:
        return []
    out = list(prog.warnings)
    if not prog.units_stated:
        # a controller starts in the units its parameters set (mm in most shops, inches in some): a program that
        # does not say is read as mm here; an inch program would then cut 25.4 x too small and feed as slowly
        out.append(f"{prog.path}: no G20 or G21 before the first move: read in millimetres (an inch program would "
                   "come out 25.4 x too small); put G21 (or G20) in the program's first lines")
    feeds, speeds = feeds_and_speeds(prog)
    if len(feeds) > 1:
        out.append(f"toolpath.program: {len(feeds)} cutting feeds ({', '.join(f'F{f:g}' for f in sorted(feeds))} "
                   f"mm/min); the force model takes the one over most of the cut ({sc.path.feed_mm_per_s * 60:g} "
                   "mm/min) for the chip thickness everywhere")
    if len(speeds) > 1:
        out.append(f"toolpath.program: {len(speeds)} spindle speeds; the force model takes "
                   f"S{sc.cutter.spindle_rpm:g} everywhere")
    return out
