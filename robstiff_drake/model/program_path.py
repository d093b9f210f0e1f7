"""A G-code program's moves (model/gcode/program.py) as the planned path's
elements (model/path_elements.py): lines and arcs in the robot's base
frame, with the program's feeds, exact stops and dwells.  Plain numpy; no Drake."""

import math

import numpy as np

from robstiff_drake.model.gcode.moves import PLANES
from robstiff_drake.model.path_elements import Arc, Line

def program_pieces(moves, rapid_m_per_s, transform):
    """Elements (m, base frame), speeds (m/s), exact stops and dwells (s)
    after each element, and the Move each comes from, of G-code moves
    (model/gcode/program.py Move, mm in the work frame).  ``transform(p_mm)``
    maps a work-frame point (mm) to the base frame (m), a rotation about z
    and a shift; ``rapid_m_per_s``: the speed of G0 moves."""
    origin = np.asarray(transform((0.0, 0.0, 0.0)), dtype=float)
    axes = [(np.asarray(transform(e), dtype=float) - origin) * 1e3 for e in np.eye(3)]  # base-frame unit vectors
    elements, speeds, stops, dwells, sources = [], [], [], [], []
    for m in moves:
        p0, p1 = np.asarray(transform(m.start_mm), dtype=float), np.asarray(transform(m.end_mm), dtype=float)
        if elements:  # (an arc may end up to gcode.ARC_END_TOLERANCE_MM off its programmed end point)
            p0 = elements[-1].point(elements[-1].length)
        if math.dist(p0, p1) < 1e-9 and m.kind != "arc":
            if elements and (m.stop_after or m.dwell_after_s):  # its stop and dwell stay where the path is
                stops[-1] = True
                dwells[-1] += m.dwell_after_s
            continue
        if m.kind == "arc":
            a, b, n = PLANES[m.plane]
            centre = [0.0, 0.0, 0.0]
            centre[a], centre[b], centre[n] = m.center_mm[0], m.center_mm[1], m.start_mm[n]
            c = np.asarray(transform(centre), dtype=float)
            u, v, nb = axes[a], axes[b], axes[n]
            d = p0 - c
            a0 = math.atan2(float(d @ v), float(d @ u))
            r = math.hypot(float(d @ u), float(d @ v))
            elements.append(Arc(c, r, a0, m.sweep_rad(), float(p0 @ nb), float(p1 @ nb), u, v))
        else:
            elements.append(Line(p0, p1))
        speeds.append(rapid_m_per_s if m.kind == "rapid" else m.feed_mm_per_min / 60e3)
        stops.append(bool(m.stop_after or m.dwell_after_s))
        dwells.append(float(m.dwell_after_s))
        sources.append(m)
    return elements, speeds, stops, dwells, sources


def program_elements(moves, rapid_m_per_s, transform):
    """Elements (m, base frame) and speeds (m/s) of G-code moves: see program_pieces."""
    elements, speeds, *_ = program_pieces(moves, rapid_m_per_s, transform)
    return elements, speeds
