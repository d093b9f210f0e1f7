"""Offline compensation's geometry: a predicted correction along a G-code
program's path turned into corrected end points of its cutting moves,
each move split where the correction varies along it so that the written
pieces stay within a chord tolerance of the corrected path.  Plain numpy;
no Drake.

The correction is a function of arc length along the planned path
(model/path.py: corners blended within the zone); each programmed move
is mapped onto that arc length through the path's element origins.  A
line's pieces are straight; an arc's pieces are arcs (G2 / G3 again) whose
centre is the programmed centre shifted by the mean correction of the
piece's two ends, moved onto the perpendicular bisector of the two
written ends (so both lie on its circle exactly), with the move along the
plane's normal (a helix) linear in angle.  The chord test samples the
corrected path every ``sample_mm`` and asks every sample to lie within
``chord_mm`` of the written piece; pieces are grown greedily (doubling,
then bisection).

Units: mm in the program's (work) frame unless named otherwise."""

import math
from dataclasses import dataclass

import numpy as np

from robstiff_drake.model.gcode.moves import PLANES

SAMPLE_MM = 0.1  # spacing of the corrected path's samples along a move (mm)
MAX_SAMPLES_PER_MOVE = 20000


class CorrectionError(ValueError):
    """A correction that cannot be written: ``line`` the program line."""

    def __init__(self, message, line=None):
        super().__init__(message)
        self.line = line


@dataclass
class Piece:
    """One written block: its end (mm, work frame) and, for an arc, its
    centre in the plane's two coordinates (absolute, mm)."""

    end_mm: np.ndarray
    center_mm: tuple = None
    frac: float = 1.0  # where along the move it ends (fraction of its length)


@dataclass
class MoveCorrection:
    """A cutting move's written pieces (covering it, in order) and the
    largest correction along it (mm)."""

    line: int
    pieces: list
    max_correction_mm: float


def element_arc_maps(path):
    """{programmed element index: (a knots m, s knots m)}: where a point a
    metres along programmed element i lies along the planned path (its arc
    length s), through the path's element origins (moves and blended
    corners)."""
    knots = {}
    s0 = np.r_[0.0, np.cumsum(path.lengths)]
    for k, origin in enumerate(path.origins):
        kind, i, a, b = origin
        L = path.lengths[k]
        if kind == "move":
            knots.setdefault(i, []).append((a, b, s0[k], s0[k] + L))
        else:  # a corner between element i and the next: r_in = a before i's end, r_out = b after the next's start
            r_in, r_out = a, b
            split = s0[k] + L * r_in / max(r_in + r_out, 1e-15)
            Li = path.programmed_elements[i].length
            knots.setdefault(i, []).append((Li - r_in, Li, s0[k], split))
            knots.setdefault(i + 1, []).append((0.0, r_out, split, s0[k] + L))
    out = {}
    for i, spans in knots.items():
        spans.sort()
        A, S = [], []
        for a, b, sa, sb in spans:
            A += [a, b]
            S += [sa, sb]
        out[i] = (np.asarray(A), np.asarray(S))
    return out


def correction_along(s_table_m, delta_table_mm):
    """A function s (m, array) -> correction (mm, (n, 3)) interpolated in the
    table of the correction against arc length (times where the path rests
    give several rows at one s: the last is kept)."""
    s = np.asarray(s_table_m, dtype=float)
    d = np.asarray(delta_table_mm, dtype=float)
    keep = np.flatnonzero(np.r_[np.diff(s) > 1e-12, True])
    s, d = s[keep], d[keep]

    def at(x):
        x = np.atleast_1d(np.asarray(x, dtype=float))
        return np.column_stack([np.interp(x, s, d[:, j]) for j in range(3)])

    return at


def move_points(move, frac):
    """Points (n, 3, mm) at fractions ``frac`` of a move's length."""
    s = np.asarray(move.start_mm, dtype=float)
    e = np.asarray(move.end_mm, dtype=float)
    frac = np.asarray(frac, dtype=float)
    if move.kind != "arc":
        return s + np.outer(frac, e - s)
    a, b, n = PLANES[move.plane]
    ca, cb = move.center_mm
    ang = math.atan2(s[b] - cb, s[a] - ca) + move.sweep_rad() * frac
    r = move.radius_mm
    out = np.empty((len(frac), 3))
    out[:, a] = ca + r * np.cos(ang)
    out[:, b] = cb + r * np.sin(ang)
    out[:, n] = s[n] + (e[n] - s[n]) * frac
    return out


def _line_deviation(P, p0, p1):
    """Distances (mm) of points P (n, 3) from the segment p0-p1."""
    d = p1 - p0
    L2 = float(d @ d)
    if L2 < 1e-18:
        return np.linalg.norm(P - p0, axis=1)
    t = np.clip((P - p0) @ d / L2, 0.0, 1.0)
    return np.linalg.norm(P - (p0 + np.outer(t, d)), axis=1)


def arc_piece_center(move, p0, p1, shift_mm):
    """The centre (plane coordinates) of an arc piece from p0 to p1 (mm):
    the programmed centre shifted by ``shift_mm`` (3,), moved onto the
    perpendicular bisector of p0-p1."""
    a, b, _ = PLANES[move.plane]
    c = np.array([move.center_mm[0] + shift_mm[a], move.center_mm[1] + shift_mm[b]])
    q0, q1 = np.array([p0[a], p0[b]]), np.array([p1[a], p1[b]])
    m, d = 0.5 * (q0 + q1), q1 - q0
    L = float(np.hypot(*d))
    if L < 1e-12:  # a full circle: the shifted centre
        return c
    nrm = np.array([-d[1], d[0]]) / L
    return m + nrm * float((c - m) @ nrm)


def _arc_deviation(move, P, p0, p1, center):
    """Distances (mm) of points P (n, 3) from the arc piece p0 -> p1 about
    ``center`` (the programmed sense), its normal coordinate linear in angle."""
    a, b, n = PLANES[move.plane]
    r = math.hypot(p0[a] - center[0], p0[b] - center[1])
    da, db = P[:, a] - center[0], P[:, b] - center[1]
    radial = np.abs(np.hypot(da, db) - r)
    a0 = math.atan2(p0[b] - center[1], p0[a] - center[0])
    a1 = math.atan2(p1[b] - center[1], p1[a] - center[0])
    sign = -1.0 if move.clockwise else 1.0
    sweep = (sign * (a1 - a0)) % (2 * math.pi)
    if sweep < 1e-12:
        sweep = 2 * math.pi if abs(move.sweep_rad()) > math.pi else 0.0
    ang = (sign * (np.arctan2(db, da) - a0)) % (2 * math.pi)
    frac = np.clip(ang / sweep, 0.0, 1.0) if sweep > 0 else np.zeros(len(P))
    normal = np.abs(P[:, n] - (p0[n] + (p1[n] - p0[n]) * frac))
    return np.hypot(radial, normal)


def _fits(move, P, i, j, start, Q, shifts, chord_mm):
    """Whether the piece from ``start`` to Q[j] holds samples i+1..j-1 within chord_mm."""
    inner = P[i + 1:j]
    if move.kind != "arc":
        return inner.size == 0 or float(np.max(_line_deviation(inner, start, Q[j]))) <= chord_mm, None
    c = arc_piece_center(move, start, Q[j], 0.5 * (shifts[i] + shifts[j]))
    if inner.size == 0:
        return True, c
    return float(np.max(_arc_deviation(move, inner, start, Q[j], c))) <= chord_mm, c


def split_move(move, start_mm, base_mm, delta_mm, chord_mm, round_mm):
    """The pieces (Piece list) of ``move``: the points ``base_mm`` (n + 1,
    3: the path the controller runs, at n + 1 evenly spaced samples along
    the move) corrected by ``delta_mm`` (n + 1, 3), from ``start_mm`` (the
    end written before it), each piece within ``chord_mm`` of the corrected
    samples; ends rounded to ``round_mm`` (the written precision)."""
    n = len(delta_mm) - 1
    P = np.asarray(base_mm, dtype=float) + delta_mm
    shifts = np.asarray(delta_mm, dtype=float)
    Q = np.round(P / round_mm) * round_mm
    pieces = []
    i = 0
    start = np.asarray(start_mm, dtype=float)
    while i < n:
        good = i + 1
        ok, c = _fits(move, P, i, i + 1, start, Q, shifts, chord_mm)
        good_c = c
        while ok and good < n:  # doubling
            j = min(n, i + 2 * (good - i))
            ok, c = _fits(move, P, i, j, start, Q, shifts, chord_mm)
            if ok:
                good, good_c = j, c
            else:
                lo, hi = good, j  # bisection between the last fit and the first miss
                while hi - lo > 1:
                    mid = (lo + hi) // 2
                    okm, cm = _fits(move, P, i, mid, start, Q, shifts, chord_mm)
                    if okm:
                        lo, good_c = mid, cm
                    else:
                        hi = mid
                good = lo
                break
        end = Q[good]
        pieces.append(Piece(end, tuple(np.round(np.asarray(good_c) / round_mm) * round_mm)
                            if good_c is not None else None, good / n))
        start, i = end, good
    return pieces


def correct_moves(moves, samples_of_move, *, chord_mm, max_correction_mm, round_mm, is_cutting, label="program"):
    """{line: MoveCorrection} for the cutting moves of ``moves`` (gcode.Move
    list, ``is_cutting(move)``): ``samples_of_move(index, fractions,
    corrected_before, corrected_after)`` the path the controller runs at
    fractions of move ``index``'s length (mm, (n, 3)) and the correction
    there (mm, (n, 3)); ``corrected_before`` / ``_after``: whether the
    moves on either side are corrected too (a blended corner to a move left
    as programmed is not written out).  A correction beyond
    ``max_correction_mm`` raises CorrectionError naming the line.  Rapids
    and other moves keep their programmed ends (the next move starts from
    there)."""
    out = {}
    written_end = None
    cutting = [bool(is_cutting(m)) for m in moves]
    for idx, m in enumerate(moves):
        if not cutting[idx]:
            written_end = np.asarray(m.end_mm, dtype=float)
            continue
        L = m.length_mm()
        n = int(min(MAX_SAMPLES_PER_MOVE, max(2, math.ceil(L / SAMPLE_MM))))
        frac = np.linspace(0.0, 1.0, n + 1)
        before = idx > 0 and cutting[idx - 1]
        after = idx + 1 < len(moves) and cutting[idx + 1]
        base, delta = samples_of_move(idx, frac, before, after)
        delta = np.asarray(delta, dtype=float)
        size = np.linalg.norm(delta, axis=1)
        k = int(np.argmax(size))
        if size[k] > max_correction_mm:
            raise CorrectionError(f"{label}:{m.line}: the predicted correction is {size[k]:.3f} mm "
                                  f"at {k / n * L:.1f} mm along the move's {L:.1f} mm, more than --max-correction-mm "
                                  f"{max_correction_mm:g} (a deflection this large is no job for a corrected "
                                  "program: check the cut's depth and feed, a sharp corner taken at speed (the "
                                  "path's own acceleration: a longer move or a lead-out there) and the model)",
                                  m.line)
        start = written_end if written_end is not None else np.asarray(m.start_mm, dtype=float)
        pieces = split_move(m, start, base, delta, chord_mm, round_mm)
        out[m.line] = MoveCorrection(m.line, pieces, float(size.max()))
        written_end = pieces[-1].end_mm
    return out


def clock_on(path_from, path_to, u_s, period_s=0.002):
    """Times (s) on ``path_to``'s clock when its tool passes the points
    ``path_from`` (model/path.py) reaches at times ``u_s``: each point
    projected onto ``path_to`` (the corrected program's path, within its
    correction of the planned one) and the first time ``path_to`` reaches
    that arc length (sampled every ``period_s``, linear between); where
    ``path_from`` stands still (its dwell, a stop) the last offset is held.
    A table computed on the planned path (the preview's, the model's
    wrench) is put on the clock of the corrected program that runs instead
    (their blocks differ, so do their speed profiles: a few milliseconds
    through a cut, more where the corners differ).  Strictly increasing."""
    u_s = np.asarray(u_s, dtype=float)
    ts = np.arange(0.0, path_to.duration_s + period_s, period_s)
    ss = np.array([path_to.arc_length(t) for t in ts])
    out = np.empty(len(u_s))
    s, offset = 0.0, 0.0
    for k, u in enumerate(u_s):
        if 0.0 <= u <= path_from.duration_s and path_from.speed(u) > 1e-6:
            s = path_to.project(path_from.position(u), s, max_step_m=0.05, iterations=20)
            i = int(np.searchsorted(ss, s, side="left"))
            if 0 < i < len(ss):
                a = (s - ss[i - 1]) / (ss[i] - ss[i - 1])
                offset = ts[i - 1] + a * (ts[i] - ts[i - 1]) - u
        out[k] = u + offset
    out = np.maximum.accumulate(out)
    return out + np.arange(len(out)) * 1e-9  # strictly increasing (held stretches)


STEADY_WINDOW_S = 0.6  # the model's force must have stayed steady this long before its difference is heard (s)
STEADY_FRACTION = 0.1  # ... within this fraction of itself (or STEADY_FLOOR_N)
STEADY_FLOOR_N = 5.0
# ... and must stay so this long ahead (s): the model is a prediction, known ahead.  Without it the mask closed only
# once the model's force had already moved by STEADY_FRACTION, and the residual held from there was that change, not
# the law's difference: on face_contour_fanuc at the contour's end (model 148 N, falling from 165 N) measured less
# model was (-20, -11, -15) N against the steady cut's (-13, -2, -13) N; 0.1 s ahead it is (-14, 6, -12) N, 0.2 and
# 0.3 s alike (sensor frame, the air's taken off; on the corrected program's run, studies/plain_on_top_residual.py)
STEADY_AHEAD_S = 0.1


def steady_mask(t_s, force_N, *, window_s=STEADY_WINDOW_S, fraction=STEADY_FRACTION, floor_N=STEADY_FLOOR_N,
                ahead_s=STEADY_AHEAD_S):
    """(N,) bool: where the model's force (N, k) at times ``t_s`` (s) has
    stayed within ``fraction`` of itself (at least ``floor_N``) over the
    last ``window_s`` and stays so over the next ``ahead_s``.  The window:
    at face_and_contour's entry the plant's force, its chip turning with
    the tool's real motion, reached the model's ~0.5 s after the model's
    had (measured: measured less model above 20 N from 2.95 to 3.6 s).
    Ahead: STEADY_AHEAD_S."""
    t = np.asarray(t_s, dtype=float)
    F = np.asarray(force_N, dtype=float).reshape(len(t), -1)
    out = np.empty(len(t), dtype=bool)
    j = k = 0
    for i in range(len(t)):
        while t[j] < t[i] - window_s:
            j += 1
        k = max(k, i)
        while k + 1 < len(t) and t[k + 1] <= t[i] + ahead_s:
            k += 1
        dev = np.linalg.norm(F[j:k + 1] - F[i], axis=1).max()
        out[i] = dev <= max(fraction * np.linalg.norm(F[i]), floor_N)
    return out
