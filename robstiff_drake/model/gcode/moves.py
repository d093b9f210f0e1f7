"""The moves a G-code program is read into (model/gcode/program.py): lines and
arcs in any of the three planes, in mm in the program's (work) frame.
Plain Python; no Drake."""

import math
from dataclasses import dataclass

MM_PER_INCH = 25.4
# An arc whose end is farther than this from its circle is a programming
# error (CNC controls use 0.002-0.01 mm; LinuxCNC 0.002 mm absolute).
ARC_END_TOLERANCE_MM = 0.01
MAX_MOVES = 500_000
# plane: (first axis, second axis, normal) indices; counter-clockwise is seen from +normal
PLANES = {"XY": (0, 1, 2), "ZX": (2, 0, 1), "YZ": (1, 2, 0)}


@dataclass(frozen=True)
class Move:
    """One motion of the program (mm, work frame; feed mm/min).

    kind: "rapid" (G0), "line" (G1) or "arc" (G2 / G3); for an arc,
    ``plane`` ("XY", "ZX" or "YZ"), ``center_mm`` (the centre in the
    plane's two coordinates: (x, y), (z, x) or (y, z)) and ``clockwise``
    (seen from the plane's normal, +Z, +Y or +X); ``feed_mm_per_min`` None
    for a rapid; ``spindle_rpm`` the S in effect (None before any S) and
    ``spindle_on`` False after M5 (or with S0); ``line``: the program line;
    ``stop_after``: the path comes to rest at the end (G61, G9, M0, a
    dwell); ``dwell_after_s``: the rest there (G4)."""

    kind: str
    start_mm: tuple
    end_mm: tuple
    feed_mm_per_min: float = None
    spindle_rpm: float = None
    line: int = 0
    center_mm: tuple = None
    clockwise: bool = False
    plane: str = "XY"
    spindle_on: bool = True
    stop_after: bool = False
    dwell_after_s: float = 0.0

    def _ab(self, p):
        a, b, _ = PLANES[self.plane]
        return p[a], p[b]

    @property
    def radius_mm(self):
        ca, cb = self.center_mm
        sa, sb = self._ab(self.start_mm)
        return math.hypot(sa - ca, sb - cb)

    def sweep_rad(self):
        """Signed angle of an arc (counter-clockwise positive, seen from
        the plane's normal); a full circle when the end is the start."""
        ca, cb = self.center_mm
        sa, sb = self._ab(self.start_mm)
        ea, eb = self._ab(self.end_mm)
        d = math.atan2(eb - cb, ea - ca) - math.atan2(sb - cb, sa - ca)
        if self.clockwise:
            while d >= -1e-12:
                d -= 2 * math.pi
        else:
            while d <= 1e-12:
                d += 2 * math.pi
        return d

    def length_mm(self):
        if self.kind != "arc":
            return math.dist(self.start_mm, self.end_mm)
        n = PLANES[self.plane][2]
        return math.hypot(self.radius_mm * self.sweep_rad(), self.end_mm[n] - self.start_mm[n])


_PLANE_WORD = {"XY": "G17", "ZX": "G18", "YZ": "G19"}


def arc_center(plane, g, start, end, arc, absolute, fail):
    """The centre (in the plane's two coordinates) of a G2 / G3 (``g``)
    from ``start`` to ``end`` (mm) given its words ``arc`` ({letter: (mm,
    word)}: I/J/K or R); ``absolute``: G90.1.  ``fail(what, word=None)``
    raises the reader's error (at the motion word, or at ``word``)."""
    word = f"G{g}"
    a, b, _ = PLANES[plane]
    offsets = {"IJK"[a], "IJK"[b]}
    for letter, (_, w) in arc.items():
        if letter != "R" and letter not in offsets:
            fail(f"{w}: {letter} (an arc centre along {'XYZ'['IJK'.index(letter)]}) in the {plane} plane "
                 f"({_PLANE_WORD[plane]}), whose centre words are {'/'.join(sorted(offsets))}", w)
    sa, sb, ea, eb = start[a], start[b], end[a], end[b]
    chord = math.hypot(ea - sa, eb - sb)
    if "R" in arc:
        if len(arc) > 1:
            fail(f"{word}: give the centre or R, not both")
        r, rw = arc["R"]
        if chord < 1e-9:
            fail(f"{word}: a full circle needs its centre ({'/'.join(sorted(offsets))}), not R", rw)
        if abs(r) < chord / 2 - ARC_END_TOLERANCE_MM:
            fail(f"{rw}: radius shorter than half the chord ({chord / 2:.4f} mm)", rw)
        h = math.sqrt(max(r * r - chord * chord / 4, 0.0))
        ma, mb = (sa + ea) / 2, (sb + eb) / 2
        ua, ub = (ea - sa) / chord, (eb - sb) / chord
        # centre to the left of the chord for a counter-clockwise arc of at most 180 degrees
        side = 1.0 if (g == 3) == (r > 0) else -1.0
        return (ma - side * h * ub, mb + side * h * ua)
    if not arc:
        fail(f"{word}: an arc needs its centre ({'/'.join(sorted(offsets))}) or R (radius)")
    la, lb = "IJK"[a], "IJK"[b]
    if absolute:
        if la not in arc or lb not in arc:
            fail(f"{word}: with G90.1 (absolute centres) give both {la} and {lb}")
        c = (arc[la][0], arc[lb][0])
    else:
        c = (sa + arc.get(la, (0.0,))[0], sb + arc.get(lb, (0.0,))[0])
    r0 = math.hypot(sa - c[0], sb - c[1])
    r1 = math.hypot(ea - c[0], eb - c[1])
    if r0 < 1e-6:
        fail(f"{word}: the centre is the start point")
    if abs(r1 - r0) > ARC_END_TOLERANCE_MM:
        names = "XYZ"[a], "XYZ"[b]
        fail(f"{word}: the end point is not on the arc (radius {r0:.4f} mm at the start, {r1:.4f} mm at the end, "
             f"about ({names[0]}, {names[1]}) = ({c[0]:.4f}, {c[1]:.4f}) mm; tolerance {ARC_END_TOLERANCE_MM:g} mm)")
    return c
