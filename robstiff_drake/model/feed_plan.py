"""Feed-rate adaptation's arithmetic (as CAM feed-rate optimisation does it:
lower the feed where the predicted error is too large, keep it elsewhere).
Plain numpy; the predictions come from diagrams/feed_plan.py.

* ``deepest_pass``: which moment of a run cut each surface point deepest
  (the cutter's lowest face over it), so an error is charged to the part of
  the path that made it;
* ``cause``: why the error is there: a plunge, a corner, an entry or exit
  (the force rising or falling), a pass over an earlier one (overlap);
* ``slow_windows``: the stretches of path to slow and the feed for each;
* ``advice_rows``: the program lines those stretches lie on.

Units: lengths m, speeds m/s, times s (feeds in mm/min only in the advice).
"""

import math
import re
from dataclasses import dataclass

import numpy as np

from robstiff_drake.model.surface import faces_over_points

CAUSES = ("plunge", "corner", "entry", "exit", "overlap", "steady")
VERTICAL_TANGENT = 0.5  # |t_z| above this: a plunge or a retract (30 deg from vertical)
CORNER_TURN_RAD = math.radians(20.0)  # the feed direction turns more than this within half a cutter: a corner
FORCE_CHANGE = 0.2  # the force changes by more than this fraction over a cutter's radius: an entry or exit
SAFETY = 0.85  # the new feed aims at this fraction of the tolerance
MAX_STEP_DOWN = 0.5  # one iteration lowers a feed at most to this fraction


def deepest_pass(x_m, y_m, p_m, n_up, radius_m):
    """For each point (x, y): the index of the sample (of tool points p (N, 3)
    and spindle axes n (N, 3)) whose cutter face was lowest over it, and the
    index of the first sample that covered it (-1: never covered)."""
    low = np.full(np.shape(x_m), np.inf)
    deepest = np.full(np.shape(x_m), -1)
    first = np.full(np.shape(x_m), -1)
    for i, idx, z in faces_over_points(x_m, y_m, p_m, n_up, radius_m):
        lower = z < low[idx]
        low[idx[lower]] = z[lower]
        deepest[idx[lower]] = i
        new = first[idx] < 0
        first[idx[new]] = i
    return deepest, first


def cause(path, s_m, t_s, t_first_s, force_at, radius_m):
    """Why the error charged to path arc length ``s_m`` (cut at time ``t_s``,
    first covered at ``t_first_s``) is there: one of CAUSES.
    ``force_at(t)``: the cut's force magnitude (N) at time t."""
    back = np.linspace(max(0.0, s_m - radius_m), s_m, 8)
    if any(abs(path.tangent_at(s)[2]) > VERTICAL_TANGENT for s in back):
        return "plunge"
    around = np.linspace(max(0.0, s_m - 0.5 * radius_m), min(path.total_length, s_m + 0.5 * radius_m), 9)
    dirs = [path.tangent_at(s)[:2] for s in around]
    dirs = [d / np.linalg.norm(d) for d in dirs if np.linalg.norm(d) > 1e-6]
    if len(dirs) > 1 and max(math.acos(float(np.clip(a @ b, -1, 1))) for a in dirs for b in dirs) > CORNER_TURN_RAD:
        return "corner"
    v = max(path.speed(t_s), 1e-6)
    dt = 0.5 * radius_m / v
    f0, f1, fm = force_at(t_s - dt), force_at(t_s + dt), max(force_at(t_s), 1e-9)
    if f1 - f0 > FORCE_CHANGE * fm:
        return "entry"
    if f0 - f1 > FORCE_CHANGE * fm:
        return "exit"
    if t_first_s < t_s - 2.0 * radius_m / v:
        return "overlap"
    return "steady"


@dataclass
class Window:
    """A stretch of path [s0, s1] (m) to run at ``speed`` (m/s), for errors
    up to ``error_mm`` of ``cause``."""

    s0: float
    s1: float
    speed: float
    error_mm: float
    cause: str


def new_speed(v, error_mm, tolerance_mm, floor):
    """The feed for a stretch whose predicted error is ``error_mm`` at feed
    ``v``: an arm's inertial and the force's rate errors grow at least as
    the feed, the corner's as its square: v sqrt(SAFETY tol / error), at
    least MAX_STEP_DOWN v per step and never below ``floor``."""
    ratio = math.sqrt(SAFETY * tolerance_mm / error_mm) if error_mm > 0 else 1.0
    v_new = max(floor, v * min(1.0, max(MAX_STEP_DOWN, ratio)))
    return math.floor(v_new * 60e3) / 60e3  # a whole mm/min, as the advised program writes it


def merge_windows(spans, margin_m, length_m):
    """Merge [(s0, s1, error_mm, cause)] widened by ``margin_m`` on each
    side (the arm must be slow before the event); the worst cause of each."""
    spans = sorted((max(0.0, a - margin_m), min(length_m, b + margin_m), e, c) for a, b, e, c in spans)
    out = []
    for a, b, e, c in spans:
        if out and a <= out[-1][1]:
            pa, pb, pe, pc = out[-1]
            out[-1] = (pa, max(pb, b), max(pe, e), pc if pe >= e else c)
        else:
            out.append((a, b, e, c))
    return out


def path_part_lines(path, s0, s1):
    """The program lines (or waypoint segments, 1-based) of path elements
    overlapping [s0, s1], in order, each once."""
    out = []
    knots = np.r_[0.0, np.cumsum(path.lengths)]
    for k, tag in enumerate(path.origins):
        if knots[k + 1] <= s0 or knots[k] >= s1:
            continue
        kind, i = tag[0], tag[1]
        idx = [i] if kind == "move" else [i, i + 1]
        for j in idx:
            line = path.program_lines[j] if path.program_lines is not None else j + 1
            if line not in out:
                out.append(line)
    return out


def advice_rows(path, windows, programmed_speed_at):
    """[{line, error_mm, cause, feed_mm_per_min}] of the program lines the
    slowed stretches lie on (the worst stretch's numbers for each line)."""
    rows = {}
    for w in windows:
        for line in path_part_lines(path, w.s0, w.s1):
            row = rows.get(line)
            if row is None or w.error_mm > row["error_mm"]:
                rows[line] = {"line": int(line), "error_mm": float(w.error_mm), "cause": w.cause,
                              "feed_mm_per_min": float(round(w.speed * 60e3, 1)),
                              "programmed_feed_mm_per_min": float(round(programmed_speed_at(w) * 60e3, 1))}
    return [rows[k] for k in sorted(rows)]


# ---------------------------------------------------------------- the program with the advised feeds

MOTION_LETTERS = set("GXYZIJKRFN")  # what a split line may hold (anything else: the whole line is slowed)


def line_ranges(path, windows):
    """{element index of the program path: [(a_m, b_m, speed m/s)]}: the
    slowed stretches in each programmed move's own arc length (a corner's
    share split between the moves it joins)."""
    knots = np.r_[0.0, np.cumsum(path.lengths)]
    originals = path.programmed_elements
    out = {}

    def add(i, a, b, v):
        if b - a > 1e-9:
            out.setdefault(i, []).append((max(0.0, a), min(originals[i].length, b), v))

    for w in windows:
        for k, (kind, i, t0, _t1) in enumerate(path.origins):
            lo, hi = max(w.s0, knots[k]), min(w.s1, knots[k + 1])
            if hi <= lo:
                continue
            if kind == "move":
                add(i, t0 + lo - knots[k], t0 + hi - knots[k], w.speed)
            else:  # a corner: the last r of move i, the first r of move i + 1
                L, r = knots[k + 1] - knots[k], t0
                fa, fb = (lo - knots[k]) / L, (hi - knots[k]) / L
                if fa < 0.5:
                    add(i, originals[i].length - r + 2 * r * fa, originals[i].length - r + 2 * r * min(fb, 0.5), w.speed)
                if fb > 0.5:
                    add(i + 1, 2 * r * (max(fa, 0.5) - 0.5), 2 * r * (fb - 0.5), w.speed)
    merged = {}
    for i, spans in out.items():
        spans.sort()
        m = []
        for a, b, v in spans:
            if m and a <= m[-1][1] + 1e-9:
                m[-1] = (m[-1][0], max(m[-1][1], b), min(m[-1][2], v))
            else:
                m.append((a, b, v))
        merged[i] = m
    return merged


def _fmt(v):
    return f"{v:.4f}".rstrip("0") if abs(v) >= 1e-9 else "0."


def _move_length_mm(move):
    return math.dist(move.start_mm, move.end_mm) if move.kind == "line" else \
        math.hypot(move.radius_mm * move.sweep_rad(), move.end_mm[2] - move.start_mm[2])


def _split_blocks(move, parts, unit):
    """Blocks (text) that run ``move`` (gcode.Move, mm) in ``parts``
    [(a, b, feed mm/min)] (mm of its own length, covering it), all absolute
    (G90) and in ``unit`` (mm per program unit)."""
    length = _move_length_mm(move)
    blocks = []
    for c0, c1, f in parts:
        if c1 - c0 < 1e-6:
            continue
        p = _point(move, min(1.0, c1 / length))
        words = [("G1" if move.kind == "line" else ("G2" if move.clockwise else "G3"))]
        words += [f"{ax}{_fmt(v / unit)}" for ax, v in zip("XYZ", p)]
        if move.kind == "arc":
            s = _point(move, c0 / length)
            words += [f"I{_fmt((move.center_mm[0] - s[0]) / unit)}", f"J{_fmt((move.center_mm[1] - s[1]) / unit)}"]
        words.append(f"F{_fmt(f / unit)}")
        blocks.append(" ".join(words))
    return blocks


def _point(move, frac):
    """The point (mm) a fraction ``frac`` of its length along a move."""
    s, e = np.asarray(move.start_mm, dtype=float), np.asarray(move.end_mm, dtype=float)
    if move.kind == "line":
        return s + (e - s) * frac
    cx, cy = move.center_mm
    a = math.atan2(s[1] - cy, s[0] - cx) + move.sweep_rad() * frac
    r = move.radius_mm
    return np.array([cx + r * math.cos(a), cy + r * math.sin(a), s[2] + (e[2] - s[2]) * frac])


def _code_words(text):
    """The words of a program line without its comments: [(letter, value text)]."""
    body = text.split(";", 1)[0]
    body = _strip_parens(body)
    return [(m.group(1).upper(), m.group(2)) for m in WORD.finditer(body)]


def _strip_parens(text):
    out, depth = [], 0
    for ch in text:
        if ch == "(":
            depth += 1
        elif ch == ")":
            depth = max(0, depth - 1)
        elif depth == 0:
            out.append(ch)
    return "".join(out)


WORD = re.compile(r"([A-Za-z])\s*([-+]?[0-9]*\.?[0-9]*)")


def _distance_modes(text):
    """[(line, words, absolute)] of each program line: its words without
    comments and whether the distance mode after it is absolute (G90) or
    incremental (G91).  A posted program's ``G28 G91 Z0.`` sets G91 until
    the next G90, as on the control."""
    out, absolute = [], True
    for n, raw in enumerate(text.splitlines(), start=1):
        words = _code_words(raw)
        for letter, value in words:
            if letter == "G" and value.replace(".", "", 1).isdigit() and float(value) in (90.0, 91.0):
                absolute = float(value) == 90.0
        out.append((n, words, absolute))
    return out


def block_numbers(text):
    """{program line: 'N70'} of the lines that carry a block (sequence) number."""
    out = {}
    for n, words, _ in _distance_modes(text):
        number = next((v for letter, v in words if letter == "N" and v), None)
        if number is not None:
            out[n] = f"N{number}"
    return out


def rewrite_program(text, moves, ranges_by_line):
    """The program ``text`` with the advised feeds: each line of
    ``ranges_by_line`` ({line: [(a_mm, b_mm, feed mm/min)]}: its move's
    parts, covering it) replaced by the same move in those parts at their
    feeds (absolute coordinates, the program's units), the modal feed
    restored after; a line with other words than motion ones (M, S, T...)
    keeps them and is slowed whole.  Every other line is written as it is
    (a posted program's G28 G91 Z0., G43 H, M6, M8/M9, M01).  A rewritten
    line in incremental mode (G91) cannot be split in absolute words:
    ValueError naming it.  Returns the new text."""
    by_line = {m.line: m for m in moves}
    lines = text.splitlines()
    out = []
    unit = 1.0  # mm per program unit (G20: 25.4)
    for (n, words, absolute), raw in zip(_distance_modes(text), lines):
        for letter, value in words:
            if letter == "G" and value.replace(".", "", 1).isdigit():
                g = float(value)
                if g == 20:
                    unit = 25.4
                elif g == 21:
                    unit = 1.0
        if n not in ranges_by_line or n not in by_line or by_line[n].kind == "rapid":
            out.append(raw)
            continue
        if not absolute:
            raise ValueError(f"line {n}: a cutting move in incremental coordinates (G91) to slow: the advised "
                             "program splits moves in absolute (G90) coordinates only")
        move = by_line[n]
        spans = ranges_by_line[n]
        feed = move.feed_mm_per_min
        letters = {letter for letter, _ in words}
        number = next((f"N{v} " for letter, v in words if letter == "N"), "")
        out.append(f"({_strip_parens(raw).strip()} : feeds adapted by robstiff simulate --advise-out)")
        if letters <= MOTION_LETTERS:
            blocks = _split_blocks(move, spans, unit)
            out.append(number + blocks[0])
            out.extend(blocks[1:])
        else:
            slow = min(v for _, _, v in spans)
            body = re.sub(r"F\s*[-+]?[0-9]*\.?[0-9]*", "", raw.split("(")[0].split(";")[0]).rstrip()
            out.append(f"{body} F{_fmt(slow / unit)}")
        out.append(f"F{_fmt(feed / unit)}")  # the programmed feed again for what follows
    return "\n".join(out) + ("\n" if text.endswith("\n") else "")


def check_rewritable(text, moves=None):
    """ValueError (naming the line) for a program rewrite_program may not be
    able to write: a cutting move (G1, G2, G3 line of ``moves``, the
    program as read) in incremental coordinates (G91).  A G91 that only a
    G28 return uses (a posted program's ``G28 G91 Z0.``, then G90) is fine."""
    cutting = None if moves is None else {m.line for m in moves if m.kind != "rapid"}
    for n, words, absolute in _distance_modes(text):
        if absolute or not any(letter in "XYZIJKR" for letter, _ in words):
            continue
        if any(letter == "G" and value.replace(".", "", 1).isdigit() and float(value) == 28 for letter, value in words):
            continue  # G28's intermediate point: the robot's program leaves the return out
        if cutting is None or n in cutting:
            raise ValueError(f"line {n}: a cutting move in incremental coordinates (G91): the advised program "
                             "splits moves in absolute (G90) coordinates only")
