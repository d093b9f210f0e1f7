"""The moves a G-code program is read into (model/gcode.py): lines and
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


