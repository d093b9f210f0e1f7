"""What a user's own job needs said before and after it runs: a path with
corners run by the plain compensator (which corrects the force deflection
it measures, not the path's own dynamics), a program that lies only partly
over the workpiece, a program placed by the scenario's work offset rather
than the user's, and why compensation made a cut worse.  One line each
(io.Warnings).  Plain numpy on the scenario's path; no Drake."""

import math

import numpy as np

from robstiff_drake.errors import InputError
from robstiff_drake.model.feed_plan import _move_length_mm as move_length_mm
from robstiff_drake.model.feed_plan import _point as point_along

# A junction of two cutting moves turning more than this is a corner: the
# path's acceleration jumps there (zone blending rounds it but the arm's
# modes and the servo's lag still see it).  20 deg: a CAM post's polyline of
# a smooth curve turns a few degrees per block; a designed corner 45-90.
CORNER_TURN_DEG = 20.0
# A line meeting an arc (or an arc of another radius) tangentially is a step
# in the path's curvature, so in its acceleration (v^2 / r): counted as well
# when the arc is tighter than this (mm; at 20 mm/s, r = 100 mm is 4 mm/s^2).
CURVATURE_STEP_RADIUS_MM = 100.0
# A program whose cutting length lies less than this share over the
# workpiece (tool centre within its outline) is likely placed wrong.
MIN_SHARE_OVER_WORKPIECE = 0.5
SAMPLE_MM = 2.0


def _cutting_moves(prog):
    return [m for m in prog.moves if m.kind != "rapid" and m.spindle_on]


def corners(prog):
    """[(line, what)] of the junctions between consecutive cutting moves
    that are corners (turn > CORNER_TURN_DEG) or curvature steps (a line
    meeting a tight arc), in program lines."""
    out = []
    moves = prog.moves
    for a, b in zip(moves, moves[1:]):
        if a.kind == "rapid" or b.kind == "rapid" or not (a.spindle_on and b.spindle_on):
            continue
        ta, tb = _tangent(a, 1.0), _tangent(b, 0.0)
        if ta is None or tb is None:
            continue
        turn = math.degrees(math.acos(float(np.clip(np.dot(ta, tb), -1.0, 1.0))))
        radii = [m.radius_mm for m in (a, b) if m.kind == "arc"]
        if turn > CORNER_TURN_DEG:
            out.append((b.line, f"a {turn:.0f} deg corner"))
        elif radii and (a.kind != b.kind or abs(radii[0] - radii[-1]) > 1e-6) and min(radii) < CURVATURE_STEP_RADIUS_MM:
            out.append((b.line, f"a line/arc junction (R{min(radii):g})"))
    return out


def _tangent(m, frac):
    """The unit direction (work frame) of a move at a fraction of it; None for a zero-length move."""
    p0 = np.asarray(_point(m, max(0.0, frac - 1e-3)))
    p1 = np.asarray(_point(m, min(1.0, frac + 1e-3)))
    d = p1 - p0
    n = np.linalg.norm(d)
    return d / n if n > 1e-12 else None


def _point(m, frac):
    """The point (mm, work frame) a fraction of a move's length along it (model/feed_plan's)."""
    return point_along(m, frac)


def _length(m):
    return move_length_mm(m)


def _block_numbers(sc):
    """{line: 'N70'} of the scenario's program (model/feed_plan.block_numbers)."""
    from robstiff_drake.diagrams.scenario import resolve
    from robstiff_drake.model.feed_plan import block_numbers
    from robstiff_drake.user_files import read_user_text

    try:
        return block_numbers(read_user_text(resolve(sc, sc.toolpath.program), "G-code program"))
    except (OSError, InputError):  # the reader has read it already; a label is not worth a failure
        return {}


def corner_warning(sc, prog):
    """The one line for a path with corners run by the plain compensator; None otherwise."""
    if sc.controller.mode != "plain":
        return None
    found = corners(prog)
    if not found:
        return None
    numbers = _block_numbers(sc)
    lines = ", ".join(f"{numbers[line]} (line {line})" if line in numbers else f"line {line}"
                      for line, _ in found[:6]) + (", ..." if len(found) > 6 else "")
    return (f"{prog.path}: {len(found)} corner(s) and line/arc junction(s) in the cut ({lines}) with "
            "controller.mode: plain, which corrects the force deflection it measures but not the path's own dynamics "
            "and the servo's lag there; controller.mode: preview anticipates them")


def coverage_warning(sc, prog, transform_mm):
    """The one line for a program whose cutting length lies mostly off the
    workpiece (tool centre outside every box's outline, below the top):
    both extents in the base frame; None otherwise.  ``transform_mm``: the
    work frame to the base frame (mm, diagrams/toolpath.work_transform_mm)."""
    boxes = np.asarray(sc.workpiece.boxes_mm, dtype=float).reshape(-1, 5)
    moves = _cutting_moves(prog)
    if not len(boxes) or not moves:
        return None
    pts, weights = [], []
    for m in moves:
        n = max(1, int(math.ceil(_length(m) / SAMPLE_MM)))
        fr = (np.arange(n) + 0.5) / n
        pts.append(np.array([_point(m, f) for f in fr]))
        weights.append(np.full(n, _length(m) / n))
    p = transform_mm(np.vstack(pts))
    w = np.concatenate(weights)
    below = np.zeros(len(p), dtype=bool)
    over = np.zeros(len(p), dtype=bool)
    for x0, x1, y0, y1, top in boxes:
        inside = (p[:, 0] >= x0) & (p[:, 0] <= x1) & (p[:, 1] >= y0) & (p[:, 1] <= y1)
        below |= p[:, 2] < top
        over |= inside & (p[:, 2] < top)
    cut = below  # the cutting length at depth (below some box's top)
    if not np.any(cut) or w[cut].sum() <= 0:
        return None
    share = float(w[over].sum() / w[cut].sum())
    if share >= MIN_SHARE_OVER_WORKPIECE:
        return None
    ends = transform_mm(np.array([e for m in moves for e in (m.start_mm, m.end_mm)], dtype=float))
    ends = ends[ends[:, 2] < boxes[:, 4].max()]  # the moves' ends at depth, for the extent (samples are midpoints)
    pts = np.vstack([p[cut], ends]) if len(ends) else p[cut]
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    bx0, bx1, by0, by1 = boxes[:, 0].min(), boxes[:, 1].max(), boxes[:, 2].min(), boxes[:, 3].max()
    return (f"{prog.path}: only {100 * share:.0f} % of the program's cutting length lies over the workpiece: its cuts "
            f"span X {lo[0]:.6g}..{hi[0]:.6g}, Y {lo[1]:.6g}..{hi[1]:.6g} mm, the workpiece X {bx0:g}..{bx1:g}, "
            f"Y {by0:g}..{by1:g} mm (base frame, work offset "
            f"{', '.join(f'{v:g}' for v in sc.toolpath.work_offset_mm)} mm): check --work-offset (where the "
            "program's zero is) and the workpiece (--stock or workpiece.boxes_mm)")


def offset_note(sc, work_offset_given):
    """The line that says a --toolpath program is placed with the scenario's
    own work offset (no --work-offset given); None otherwise."""
    if work_offset_given or not getattr(sc, "_program_label", None):
        return None
    tp = sc.toolpath
    rot = f", turned {tp.work_rotation_deg:g} deg" if tp.work_rotation_deg else ""
    return (f"--toolpath {sc._program_label}: placed with {sc.source}'s own work offset "
            f"({', '.join(f'{v:g}' for v in tp.work_offset_mm)} mm{rot}, toolpath.work_offset_mm): give "
            "--work-offset X,Y,Z where your program's zero is in the robot's base frame")


def worse_reason(sc, prog):
    """Why a compensated cut came out worse, and what would help: the
    sentence appended to run_checks' warning, or "" when nothing is known."""
    found = corners(prog) if prog is not None else []
    if not found:
        return ""
    if sc.controller.mode == "plain":
        return (f"; the path has {len(found)} corner(s) and line/arc junction(s): there the error is the path's own "
                "dynamics and the servo's lag, not force deflection, and the plain compensator's correction "
                "(filtered, delayed) arrives when the force has changed; controller.mode: preview anticipates them "
                "(or a larger path.zone_mm, a lower feed at the corners)")
    return (f"; the path has {len(found)} corner(s) and line/arc junction(s): the error there is the path's own "
            "dynamics and the servo's lag, not force deflection (a larger path.zone_mm or a lower feed at the "
            "corners; --advise shows where)")


def job_warnings(sc):
    """The lines about a user's job before it runs (a G-code program only): its
    placement by the scenario's own offset, its coverage of the workpiece,
    its corners under the plain compensator."""
    from robstiff_drake.diagrams.toolpath import work_transform_mm

    prog = getattr(sc, "_program", None)
    if prog is None:
        return []
    out = [offset_note(sc, getattr(sc, "_work_offset_given", True)),
           coverage_warning(sc, prog, work_transform_mm(sc.toolpath)), corner_warning(sc, prog)]
    return [w for w in out if w]
