"""What a machinist checks a G-code program for against the workpiece
before running it: where its cuts are, and whether a rapid move (or a feed
move with the spindle stopped) runs the cutter into stock that no earlier
cut has removed.  Plain numpy (and scipy's KD-tree); no Drake.

Units: mm.  Moves are model/gcode/program.py Moves (work frame); ``to_base`` maps
an (N, 3) array of work-frame points to the robot's base frame (mm);
boxes are the scenario's [x0, x1, y0, y1, top] (base frame)."""

import math

import numpy as np

from robstiff_drake.model.gcode.moves import PLANES

# A rapid counts as "into the stock" where the cutter's face is more than
# this below a box's top (the reader's arc tolerance: numbers of a post
# rounded to 0.001 mm or 0.0001 in never differ more).
STOCK_TOLERANCE_MM = 0.01


def move_points(m, spacing_mm):
    """Points (N, 3) along a move, at most ``spacing_mm`` apart, both ends included."""
    n = max(1, int(math.ceil(m.length_mm() / spacing_mm)))
    f = np.linspace(0.0, 1.0, n + 1)
    p0, p1 = np.asarray(m.start_mm, dtype=float), np.asarray(m.end_mm, dtype=float)
    if m.kind != "arc":
        return p0 + f[:, None] * (p1 - p0)
    a, b, k = PLANES[m.plane]
    ca, cb = m.center_mm
    a0 = math.atan2(p0[b] - cb, p0[a] - ca)
    ang = a0 + f * m.sweep_rad()
    out = np.empty((n + 1, 3))
    out[:, a] = ca + m.radius_mm * np.cos(ang)
    out[:, b] = cb + m.radius_mm * np.sin(ang)
    out[:, k] = p0[k] + f * (p1[k] - p0[k])
    return out


def cut_extent(moves, spacing_mm=1.0):
    """(lo (3,), hi (3,)) of the cutting moves' points (work frame, mm), or None."""
    pts = [move_points(m, spacing_mm) for m in moves if m.kind != "rapid"]
    if not pts:
        return None
    p = np.concatenate(pts)
    return p.min(axis=0), p.max(axis=0)


def _rect_distance(xy, box):
    x0, x1, y0, y1 = box[:4]
    dx = np.maximum(np.maximum(x0 - xy[:, 0], xy[:, 0] - x1), 0.0)
    dy = np.maximum(np.maximum(y0 - xy[:, 1], xy[:, 1] - y1), 0.0)
    return np.hypot(dx, dy)


class StockCheck:
    """Finds the first move that runs the cutter (a disc of ``radius_mm``
    at the tool point) into uncut stock: a rapid, or a feed move with the
    spindle stopped.  Stock is uncut where no earlier cutting move (spindle
    on) had its face at or below the offending point's height within the
    cutter's radius (checked on a grid of radius / 8)."""

    def __init__(self, boxes_mm, radius_mm, to_base):
        self.boxes = np.asarray(boxes_mm, dtype=float).reshape(-1, 5)
        self.R = float(radius_mm)
        self.to_base = to_base
        self.spacing = min(self.R / 4.0, 5.0)
        self.cell = self.R / 8.0
        self._cut_moves = []
        self._cut_points = np.empty((0, 3))
        self._sampled = 0

    def start_offence(self, start_mm):
        """(base-frame point (3,), box index, depth mm) when the program's
        start point (work frame, mm) is inside a box's stock (no cut before
        it), or None: the tool was brought there by moves the program does
        not show, through the stock."""
        return self._into_uncut(self.to_base(np.asarray(start_mm, dtype=float).reshape(1, 3)))

    def first_offence(self, moves):
        """(move, base-frame point (3,), box index, depth mm) of the first
        offending move, or None."""
        for m in moves:
            if m.kind == "rapid" or not m.spindle_on:
                hit = self._into_uncut(self.to_base(move_points(m, self.spacing)))
                if hit is not None:
                    return (m,) + hit
            if m.kind != "rapid" and m.spindle_on:
                self._cut_moves.append(m)
        return None

    def _earlier_cuts(self):
        if self._sampled < len(self._cut_moves):
            new = [self.to_base(move_points(m, self.spacing)) for m in self._cut_moves[self._sampled:]]
            self._cut_points = np.concatenate([self._cut_points] + new)
            self._sampled = len(self._cut_moves)
        return self._cut_points

    def _into_uncut(self, pts):
        for k, box in enumerate(self.boxes):
            low = (pts[:, 2] < box[4] - STOCK_TOLERANCE_MM) & (_rect_distance(pts[:, :2], box) < self.R - self.cell)
            for p in pts[low]:
                if self._uncut_under(p, box):
                    return p, k, float(box[4] - p[2])
        return None

    def _uncut_under(self, p, box):
        """Is there material of ``box`` above p's height under the cutter at p?"""
        from scipy.spatial import cKDTree

        g = self.cell
        r_in = self.R - g  # (the cutter's rim: within one cell of tolerance)
        xs = np.arange(max(box[0], p[0] - r_in), min(box[1], p[0] + r_in) + 1e-9, g)
        ys = np.arange(max(box[2], p[1] - r_in), min(box[3], p[1] + r_in) + 1e-9, g)
        if not len(xs) or not len(ys):
            return False
        X, Y = np.meshgrid(xs, ys)
        cells = np.column_stack([X.ravel(), Y.ravel()])
        cells = cells[np.hypot(cells[:, 0] - p[0], cells[:, 1] - p[1]) <= r_in]
        if not len(cells):
            return False
        cuts = self._earlier_cuts()
        cuts = cuts[cuts[:, 2] <= p[2] + STOCK_TOLERANCE_MM]
        if not len(cuts):
            return True
        covered = cKDTree(cuts[:, :2]).query_ball_point(cells, self.R + self.spacing, return_length=True)
        return bool(np.any(covered == 0))
