"""G-code programs from CAM: the subset a 3-axis face or contour milling
program uses, read into moves.  Plain Python; no Drake.

Supported (anything else is refused with the file, line and word):

* motion: G0 (rapid), G1 (linear), G2 / G3 (arcs clockwise / counter-
  clockwise seen from +Z, in the XY plane, with I/J centre offsets from the
  start point or a radius R: R > 0 the arc of at most 180 degrees, R < 0 the
  longer one; a Z word makes a helix); modal: a line of coordinates alone
  repeats the last motion word, as a CAM post writes them;
* G17 (XY plane), G90 / G91 (absolute / incremental), G20 / G21 (inch / mm),
  G94 (feed per minute); G40, G49, G80 (cancel cutter compensation, tool
  length offset and canned cycle: nothing to cancel here, so accepted),
  G54 (the scenario's work offset);
* F (feed, mm/min or in/min), S (spindle speed, rpm), M3 (spindle on,
  clockwise: the force model's right-hand cutter), M5, M8, M9, M30, M2;
* comments in parentheses and after ';', line numbers N, a program number
  O, block-skip-free lines and the '%' tape marks.

Refused, with one line naming the word: tool changes (T, M6), canned
cycles (G73-G89), cutter compensation (G41 / G42), tool length offsets
(G43 / G44), other planes (G18 / G19), 5-axis words (A, B, C, U, V, W),
dwell (G4), reference returns (G28 / G30), other work offsets (G55-G59),
and anything not listed above.

The reader was written here because no package on PyPI fits (see
docs/toolpaths.md): gcodeparser reads 3D-printer G-code (it fails on
``X0.``, skips modal lines and parenthesised comments without a word);
pygcode parses this subset but is GPLv3 (this project is MIT) and has not
been released since 2017.

Units: every coordinate of a ``Move`` is in mm, in the program's (work)
frame; feeds in mm/min.
"""

import math
import re
from dataclasses import dataclass
from pathlib import Path

from robstiff_drake.errors import InputError

MM_PER_INCH = 25.4
# An arc whose end is farther than this from its circle is a programming
# error (CNC controls use 0.002-0.01 mm; LinuxCNC 0.002 mm absolute).
ARC_END_TOLERANCE_MM = 0.01
# The longest program line or file this reader takes (a CAM program of a
# few hundred thousand lines is a few MB).
MAX_PROGRAM_BYTES = 50_000_000
MAX_MOVES = 500_000

_WORD = re.compile(r"([A-Za-z])\s*([+-]?(?:\d+\.?\d*|\.\d+))")
_COMMENT = re.compile(r"\([^()]*\)")

# Refused words, with the reason given to the user.
_REFUSED_G = {
    **{g: "canned cycles are not supported; post the program with the cycles expanded into G0/G1 moves"
       for g in (73, 74, 76, 81, 82, 83, 84, 85, 86, 87, 88, 89)},
    41: "cutter radius compensation is not supported; post the program with the cutter centre path (G40)",
    42: "cutter radius compensation is not supported; post the program with the cutter centre path (G40)",
    43: "tool length offsets are not supported; the tool point comes from the robot file",
    44: "tool length offsets are not supported; the tool point comes from the robot file",
    18: "arcs only in the XY plane (G17) are supported",
    19: "arcs only in the XY plane (G17) are supported",
    4: "dwell is not supported",
    28: "reference-point returns are not supported",
    30: "reference-point returns are not supported",
    **{g: "only one work offset (G54: the scenario's toolpath.work_offset_mm) is supported"
       for g in (55, 56, 57, 58, 59)},
}
_ACCEPTED_G = {0, 1, 2, 3, 17, 20, 21, 40, 49, 54, 80, 90, 91, 94}
_ACCEPTED_M = {2, 3, 5, 8, 9, 30}
_REFUSED_M = {6: "tool changes are not supported; one program, one tool",
              4: "counter-clockwise spindle (M4) is not supported; the force model is a right-hand cutter (M3)"}
_REFUSED_LETTERS = {
    "T": "tool selection / tool changes are not supported; one program, one tool",
    **{a: "5-axis (rotary and secondary linear) words are not supported; a 3-axis program only"
       for a in "ABCUVW"},
    "H": "tool length / radius offset numbers are not supported",
    "D": "tool length / radius offset numbers are not supported",
    "P": "P words (dwell, subprograms, cycles) are not supported",
    "Q": "Q words (peck cycles) are not supported",
    "L": "L words (repeats, subprograms) are not supported",
    "E": "E words (extruders) are not supported: this is a milling program reader",
}


@dataclass(frozen=True)
class Move:
    """One motion of the program (mm, work frame; feed mm/min).

    kind: "rapid" (G0), "line" (G1) or "arc" (G2 / G3); for an arc,
    ``center_mm`` (x, y) and ``clockwise``; ``feed_mm_per_min`` is None for
    a rapid; ``spindle_rpm`` the S in effect (None before any S);
    ``line``: the program line it comes from."""

    kind: str
    start_mm: tuple
    end_mm: tuple
    feed_mm_per_min: float = None
    spindle_rpm: float = None
    line: int = 0
    center_mm: tuple = None
    clockwise: bool = False

    @property
    def radius_mm(self):
        cx, cy = self.center_mm
        return math.hypot(self.start_mm[0] - cx, self.start_mm[1] - cy)

    def sweep_rad(self):
        """Signed angle of an arc (counter-clockwise positive); a full
        circle when the end is the start."""
        cx, cy = self.center_mm
        a0 = math.atan2(self.start_mm[1] - cy, self.start_mm[0] - cx)
        a1 = math.atan2(self.end_mm[1] - cy, self.end_mm[0] - cx)
        d = a1 - a0
        if self.clockwise:
            while d >= -1e-12:
                d -= 2 * math.pi
        else:
            while d <= 1e-12:
                d += 2 * math.pi
        return d


@dataclass
class Program:
    """A read program: its moves, the file, and the start point (mm, work
    frame: the first point where X, Y and Z are all set)."""

    moves: list
    path: str
    start_mm: tuple

    def feeds_mm_per_min(self):
        """The distinct feeds of the cutting moves (G1/G2/G3), in order of first use."""
        out = []
        for m in self.moves:
            if m.kind != "rapid" and m.feed_mm_per_min not in out:
                out.append(m.feed_mm_per_min)
        return out

    def spindle_speeds_rpm(self):
        out = []
        for m in self.moves:
            if m.kind != "rapid" and m.spindle_rpm is not None and m.spindle_rpm not in out:
                out.append(m.spindle_rpm)
        return out


class _Reader:
    def __init__(self, path):
        self.path = str(path)
        self.pos = [None, None, None]  # unknown until the program sets each axis
        self.absolute = True
        self.scale = 1.0  # program units -> mm
        self.motion = None
        self.feed = None  # mm/min
        self.spindle = None
        self.moves = []
        self.ended = False

    def fail(self, line, what):
        raise InputError(f"{self.path}:{line}: {what}")

    def words(self, line_no, text):
        """[(letter, value text, value)] of one line, comments removed."""
        body = text
        if "(" in body or ")" in body:  # (a ';' inside parentheses is part of that comment)
            body = _COMMENT.sub(" ", body.split(";", 1)[0] if body.find(";") < body.find("(") else body)
        body = body.split(";", 1)[0]
        if "(" in body or ")" in body:
            self.fail(line_no, "unbalanced or nested parenthesis in a comment")
        body = body.strip()
        if body in ("", "%"):
            return []
        if body.startswith("/"):
            self.fail(line_no, "block delete ('/') is not supported")
        out = []
        pos = 0
        for m in _WORD.finditer(body):
            gap = body[pos:m.start()].strip()
            if gap:
                self.fail(line_no, f"cannot read {gap.split()[0]!r} (expected words such as G1, X10.5)")
            out.append((m.group(1).upper(), m.group(2), float(m.group(2))))
            pos = m.end()
        rest = body[pos:].strip()
        if rest:
            self.fail(line_no, f"cannot read {rest.split()[0]!r} (expected words such as G1, X10.5)")
        return out

    def line(self, line_no, text):
        if self.ended:
            return
        words = self.words(line_no, text)
        if not words:
            return
        axes = {}
        motion = None
        arc = {}
        for letter, raw, value in words:
            word = f"{letter}{raw}"
            if letter in ("N", "O"):
                continue
            if not math.isfinite(value):
                self.fail(line_no, f"{word}: not a finite number")
            if letter == "G":
                if value != int(value):
                    self.fail(line_no, f"{word}: decimal G-codes are not supported")
                g = int(value)
                if g in _REFUSED_G:
                    self.fail(line_no, f"{word}: {_REFUSED_G[g]}")
                if g not in _ACCEPTED_G:
                    self.fail(line_no, f"{word}: unsupported G-code (supported: G0-G3, G17, G20, G21, G40, G49, "
                                       "G54, G80, G90, G91, G94)")
                if g in (0, 1, 2, 3):
                    if motion is not None:
                        self.fail(line_no, f"{word}: two motion words on one line")
                    motion = g
                elif g == 90:
                    self.absolute = True
                elif g == 91:
                    self.absolute = False
                elif g == 20:
                    self.scale = MM_PER_INCH
                elif g == 21:
                    self.scale = 1.0
            elif letter == "M":
                m = int(value) if value == int(value) else None
                if m in _REFUSED_M:
                    self.fail(line_no, f"{word}: {_REFUSED_M[m]}")
                if m not in _ACCEPTED_M:
                    self.fail(line_no, f"{word}: unsupported M-code (supported: M2, M3, M5, M8, M9, M30)")
                if m in (2, 30):
                    self.ended = True
            elif letter in _REFUSED_LETTERS:
                self.fail(line_no, f"{word}: {_REFUSED_LETTERS[letter]}")
            elif letter in "XYZ":
                axes[letter] = value
            elif letter in "IJR":
                arc[letter] = value
            elif letter == "K":
                self.fail(line_no, f"{word}: K is an arc offset along Z, used only outside the XY plane (G17)")
            elif letter == "F":
                if not value > 0:
                    self.fail(line_no, f"{word}: the feed must be > 0")
                self.feed = value * self.scale  # mm/min
            elif letter == "S":
                if not value > 0:
                    self.fail(line_no, f"{word}: the spindle speed must be > 0 rpm")
                self.spindle = value
            else:  # pragma: no cover (every letter is handled above)
                self.fail(line_no, f"{word}: unsupported word")
        if motion is None and (axes or arc):
            if self.motion is None:
                self.fail(line_no, "coordinates without a motion word (G0, G1, G2 or G3) in effect")
            motion = self.motion
        if motion is None:
            return
        self.motion = motion
        if arc and motion in (0, 1):
            self.fail(line_no, f"{'/'.join(sorted(arc))} given with G{motion}: arc words belong to G2 / G3")
        end = list(self.pos)
        for i, a in enumerate("XYZ"):
            if a in axes:
                v = axes[a] * self.scale
                if not self.absolute and self.pos[i] is None:
                    self.fail(line_no, f"{a}: an incremental (G91) move before the program has set {a} "
                                       "absolutely")
                end[i] = v if self.absolute else self.pos[i] + v
        if not axes and motion in (0, 1):
            return  # a motion word alone: modal state only
        if None in self.pos:
            # the robot starts at the first point the program fixes in X, Y and Z
            if motion not in (0, 1):
                self.fail(line_no, f"G{motion}: an arc before the program has set X, Y and Z")
            self.pos = end
            return
        if motion != 0 and self.feed is None:
            self.fail(line_no, f"G{motion} without a feed: no F word before this line")
        if len(self.moves) >= MAX_MOVES:
            self.fail(line_no, f"more than {MAX_MOVES} moves; split the program")
        start = tuple(self.pos)
        end_t = tuple(end)
        if motion in (0, 1):
            if math.dist(start, end_t) > 1e-9:
                self.moves.append(Move("rapid" if motion == 0 else "line", start, end_t,
                                       None if motion == 0 else self.feed, self.spindle, line_no))
        else:
            center = self.arc_center(line_no, motion, start, end_t, arc)
            self.moves.append(Move("arc", start, end_t, self.feed, self.spindle, line_no, center, motion == 2))
        self.pos = end

    def arc_center(self, line_no, motion, start, end, arc):
        word = f"G{motion}"
        if "R" in arc and ("I" in arc or "J" in arc):
            self.fail(line_no, f"{word}: give I/J or R, not both")
        chord = math.hypot(end[0] - start[0], end[1] - start[1])
        if "R" in arc:
            r = arc["R"] * self.scale
            if chord < 1e-9:
                self.fail(line_no, f"{word}: a full circle needs I/J, not R")
            if abs(r) < chord / 2 - ARC_END_TOLERANCE_MM:
                self.fail(line_no, f"{word} R{arc['R']:g}: radius shorter than half the chord ({chord / 2:.4f} mm)")
            h = math.sqrt(max(r * r - chord * chord / 4, 0.0))
            mx, my = (start[0] + end[0]) / 2, (start[1] + end[1]) / 2
            ux, uy = (end[0] - start[0]) / chord, (end[1] - start[1]) / chord
            # centre to the left of the chord for a counter-clockwise arc of at most 180 degrees
            side = 1.0 if (motion == 3) == (r > 0) else -1.0
            return (mx - side * h * uy, my + side * h * ux)
        if "I" not in arc and "J" not in arc:
            self.fail(line_no, f"{word}: an arc needs I/J (centre offsets) or R (radius)")
        c = (start[0] + arc.get("I", 0.0) * self.scale, start[1] + arc.get("J", 0.0) * self.scale)
        r0 = math.hypot(start[0] - c[0], start[1] - c[1])
        r1 = math.hypot(end[0] - c[0], end[1] - c[1])
        if r0 < 1e-6:
            self.fail(line_no, f"{word}: the centre (I/J) is the start point")
        if abs(r1 - r0) > ARC_END_TOLERANCE_MM:
            self.fail(line_no, f"{word}: the end point is not on the arc (radius {r0:.4f} mm at the start, "
                               f"{r1:.4f} mm at the end; tolerance {ARC_END_TOLERANCE_MM:g} mm)")
        return c


def read_program(text, path="program"):
    """Read G-code ``text`` (of file ``path``, for messages) into a Program.
    The tool starts at the first point where the program has set X, Y and
    Z (the moves that lead there from an unknown position are skipped: the
    robot is brought there before the program runs).  Raises InputError
    naming the file, line and word."""
    r = _Reader(path)
    for n, line in enumerate(text.splitlines(), 1):
        r.line(n, line)
    if not r.moves:
        raise InputError(f"{path}: no motion from a known point (G0, G1, G2 or G3 after X, Y and Z are set) in "
                         "the program")
    return Program(r.moves, str(path), r.moves[0].start_mm)


def read_program_file(path):
    """Read a G-code file (InputError on anything wrong)."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: no such G-code program" if not path.exists() else f"{path}: not a file")
    try:
        raw = path.read_bytes()
    except OSError as e:
        raise InputError(f"{path}: cannot read ({e.strerror})") from None
    if len(raw) > MAX_PROGRAM_BYTES:
        raise InputError(f"{path}: {len(raw)} bytes, more than the {MAX_PROGRAM_BYTES} this reader takes")
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError:
        try:
            text = raw.decode("latin-1")  # old controls' ISO files
        except UnicodeDecodeError:  # pragma: no cover (latin-1 decodes every byte)
            raise InputError(f"{path}: not a text file") from None
    if "\x00" in text:
        raise InputError(f"{path}: not a text file (NUL bytes)")
    return read_program(text, path)
