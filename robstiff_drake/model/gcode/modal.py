"""The modal interpreter of model/gcode/program.py: a controller's state (position,
units, distance and arc-centre modes, plane, feed, spindle, tool, path
mode) block by block, and the moves it makes.  Plain Python; no Drake.

Which words it acts on, ignores or refuses: model/gcode/words.py; the
order of work within a block: model/gcode/program.py's docstring."""

import math
import re
from dataclasses import replace

from robstiff_drake.errors import InputError
from robstiff_drake.model.gcode import words as W
from robstiff_drake.model.gcode.moves import MAX_MOVES, MM_PER_INCH, Move, arc_center

# Ranges a value of a program may take (the file:line:column of the word
# is named when it is outside; the scenario's own ranges, for the values
# that replace the scenario's).
MAX_COORD_MM = 10000.0  # a cell: 10 m from the robot base (scenario.MAX_COORD_MM)
FEED_RANGE_MM_PER_MIN = (6.0, 120000.0)  # path.feed_mm_per_s: 0.1-2000 mm/s
SPINDLE_RANGE_RPM = (10.0, 60000.0)  # cutter.spindle_rpm
MAX_DWELL_S = 600.0  # ten minutes: longer is no machining dwell
# A tool comment: Fusion 360 / HSMWorks "(T1 D=75. CR=0. - ZMIN=-3. - FACE MILL)",
# Mastercam "(TOOL - 1 DIA. OFF. - 1 LEN. - 1 DIA. - 75.)"
_NUM = r"([+-]?(?:[0-9]+\.?[0-9]*|\.[0-9]+))"
_TOOL_COMMENTS = (re.compile(r"^\s*T\s*([0-9]+)\b.*?\bD\s*=\s*" + _NUM, re.IGNORECASE),
                  re.compile(r"^\s*TOOL\s*-\s*([0-9]+)\b.*\bDIA\.\s*-\s*" + _NUM + r"\s*$", re.IGNORECASE))
_AXIS = {"X": 0, "Y": 1, "Z": 2, "I": 0, "J": 1, "K": 2}
_PLANE_OF = {"G17": "XY", "G18": "ZX", "G19": "YZ"}


class ProgramState:
    def __init__(self, path, increments, skip_block_delete):
        self.path = path
        self.increments = increments  # numbers without a decimal point in least input increments
        self.skip_block_delete = skip_block_delete
        self.pos = [None, None, None]  # unknown until the program sets each axis
        self.absolute = True
        self.arc_absolute = False
        self.scale = 1.0  # program units -> mm
        self.plane = "XY"
        self.motion = None
        self.feed = None  # mm/min
        self.spindle_rpm = None
        self.spindle_on = None  # None: never set (the scenario's spindle turns)
        self.exact_stop = False  # G61
        self.work_offset = None  # the first G54-G59 word and its line
        self.tool_loaded = False
        self.tool_number = None
        self.tool_line = None
        self.tool_scale = None  # program units at the tool change (for its comment's D)
        self.selected_tool = None  # the last T word
        self.tool_comments = {}  # T -> (D in program units, line)
        self.tool_diameter_mm = None
        self.first_cut_line = None
        self.start_line = None  # the line whose move fixed the last of X, Y and Z (the program's start)
        self.program_number = None
        self.content = False  # a block with words has been read
        self.moves = []
        self.units_before_first_move = False  # a G20 / G21 came before the first move
        self.warnings = []
        self.dwell_before_s = 0.0
        self.ended = False
        self.end_what = None
        self.left_out = []
        self.skipped = []

    # ------------------------------------------------------------ helpers

    def fail(self, line, what, word=None):
        where = f"{self.path}:{line}:{word.column}" if word is not None else f"{self.path}:{line}"
        raise InputError(f"{where}: {what}")

    def length_mm(self, line, w):
        """A length word (X Y Z I J K R) in mm, with the decimal-point rule."""
        v = w.value
        if self.increments and not w.dot:
            v *= 0.001 if self.scale == 1.0 else 0.0001
        mm = v * self.scale
        if abs(mm) > MAX_COORD_MM:
            self.fail(line, f"{w}: {mm:g} mm, more than {MAX_COORD_MM:g} mm from the program's zero (a cell is no "
                            "larger)", w)
        return mm

    def add_move(self, move):
        if len(self.moves) >= MAX_MOVES:
            self.fail(move.line, f"more than {MAX_MOVES} moves; split the program")
        self.moves.append(move)

    def rest_here(self, dwell_s=0.0):
        """The path rests at the current point (after the last move)."""
        if self.moves:
            last = self.moves[-1]
            self.moves[-1] = replace(last, stop_after=True, dwell_after_s=last.dwell_after_s + dwell_s)
        else:
            self.dwell_before_s += dwell_s

    # ------------------------------------------------------------ blocks

    def block(self, b):
        for col, text in b.comments:
            for rx in _TOOL_COMMENTS:
                m = rx.match(text)
                if m:
                    self.tool_comments.setdefault(int(m.group(1)), (float(m.group(2)), b.line, text.strip()))
                    break
        if b.tape_mark:
            if self.content:
                self.end(b.line, f"the closing % (line {b.line})")
            return
        if not b.words:
            return
        if b.block_delete and self.skip_block_delete:
            self.skipped.append(b.line)
            return
        self.content = True
        self.words(b)

    def end(self, line, what):
        self.ended = True
        self.end_what = what

    def after_end(self, line_no, text):
        """A line after the program's end: not read; kept for the warning if it has words."""
        body = re.sub(r"\([^()]*\)", "", text.split(";", 1)[0]).replace("%", "").strip()
        if body:
            self.left_out.append((line_no, text.strip()))

    def coded(self, line, w, groups):
        """The table key of a G or M word, checked against the table and
        against the words of its group already on the line (``groups``)."""
        key = W.canonical_g(w.value) if w.letter == "G" else W.canonical_m(w.value)
        entry = (W.G_CODES if w.letter == "G" else W.M_CODES).get(key)
        if entry is None:
            self.fail(line, f"{w}: unsupported {w.letter}-code (docs/toolpaths.md lists the words this reader takes)",
                      w)
        status, group, note = entry
        if status == W.REFUSED:
            self.fail(line, f"{w}: {note}", w)
        if group in groups:
            o = groups[group]
            self.fail(line, f"{w}: a second {group} {w.letter}-code on the line (with {o} at column {o.column}); a "
                            "controller would keep one of them silently, or stop", w)
        groups[group] = w
        return key

    def classify(self, b):
        """The block's G and M words (checked against the table and for
        repeats) and its other words by letter."""
        line = b.line
        g_words, m_words, others = [], [], {}
        g_groups, m_groups = {}, {}
        for w in b.words:
            if w.letter == "G":
                g_words.append((self.coded(line, w, g_groups), w))
            elif w.letter == "M":
                if len(m_words) == W.MAX_M_PER_BLOCK:
                    self.fail(line, f"{w}: more than {W.MAX_M_PER_BLOCK} M-codes on the line", w)
                m_words.append((self.coded(line, w, m_groups), w))
            else:
                if w.letter in others:
                    o = others[w.letter]
                    self.fail(line, f"{w}: {w.letter} twice on the line (also {o} at column {o.column}); a "
                                    "controller would use one of them silently", w)
                status, note = W.LETTERS[w.letter]
                if status == W.REFUSED:
                    self.fail(line, f"{w}: {note}", w)
                others[w.letter] = w
        return g_words, dict(m_words), others

    def words(self, b):
        line = b.line
        g_words, m_codes, others = self.classify(b)
        # the block's G words first: their modes apply to every word of the block
        motion, one_shot, g43 = None, None, None
        for key, w in g_words:
            group = W.G_CODES[key][1]
            if group == "motion":
                motion = (int(w.value), w)
            elif group == "one-shot":
                one_shot = (key, w)
            elif key in _PLANE_OF:
                self.plane = _PLANE_OF[key]
            elif key in ("G20", "G21"):
                self.scale = MM_PER_INCH if key == "G20" else 1.0
                self.units_before_first_move = self.units_before_first_move or not self.moves
            elif key in ("G90", "G91"):
                self.absolute = key == "G90"
            elif key in ("G90.1", "G91.1"):
                self.arc_absolute = key == "G90.1"
            elif key in ("G61", "G64"):
                self.exact_stop = key == "G61"
            elif key == "G43":
                g43 = w
            elif group == "work offset":
                if self.work_offset is not None and self.work_offset[0] != key:
                    self.fail(line, f"{w}: a second work offset ({self.work_offset[0]} since line "
                                    f"{self.work_offset[1]}); one work offset per program (toolpath.work_offset_mm)",
                              w)
                self.work_offset = self.work_offset or (key, line)
        one_shot_key = one_shot[0] if one_shot else None
        axes, arc, dwell = {}, {}, {}
        for letter, w in others.items():
            if letter == "O":
                if self.program_number is not None or any(p is not None for p in self.pos):
                    self.fail(line, f"{w}: a second program (or a program number after the first move): "
                                    "subprograms are not supported", w)
                self.program_number = w.text
            elif letter == "X" and one_shot_key == "G4":
                dwell["X"] = w
            elif letter in "XYZ":
                axes[letter] = (self.length_mm(line, w), w)
            elif letter in "IJKR":
                arc[letter] = (self.length_mm(line, w), w)
            elif letter == "F":
                self.set_feed(line, w)
            elif letter == "S":
                if w.value != 0 and not SPINDLE_RANGE_RPM[0] <= w.value <= SPINDLE_RANGE_RPM[1]:
                    self.fail(line, f"{w}: outside the spindle speeds a run takes, 0 or [{SPINDLE_RANGE_RPM[0]:g}, "
                                    f"{SPINDLE_RANGE_RPM[1]:g}] rpm", w)
                self.spindle_rpm = w.value
            elif letter == "T":
                if w.value != int(w.value) or w.value < 0:
                    self.fail(line, f"{w}: a tool number is a whole number", w)
                self.selected_tool = int(w.value)
            elif letter == "H":
                if g43 is None:
                    self.fail(line, f"{w}: H (a tool length offset number) without G43 on the line", w)
            elif letter == "P":
                if one_shot_key != "G4":
                    self.fail(line, f"{w}: P is read with G4 (a dwell) only", w)
                dwell["P"] = w
            elif letter == "Q":
                if one_shot_key != "G5.1":
                    self.fail(line, f"{w}: Q is read with G5.1 only (peck depths and subprogram options are not "
                                    "supported)", w)
        # tool change, spindle, dwell, then the move, then stop / end (LinuxCNC's order)
        if "M6" in m_codes:
            self.tool_change(line, m_codes["M6"])
        if "M3" in m_codes:
            self.spindle_on = True
        if "M5" in m_codes:
            self.spindle_on = False
        if g43 is not None and "H" in others and self.tool_loaded and self.tool_number is not None \
                and int(others["H"].value) != self.tool_number:
            h = others["H"]
            self.warnings.append(f"{self.path}:{line}: G43 {h} with T{self.tool_number} in the spindle: here the "
                                 "tool length is the robot file's tool point, but the machine this program was "
                                 f"posted for would take offset {h.text}'s length")
        if one_shot_key == "G4":
            self.dwell(line, one_shot[1], dwell, axes)
        elif one_shot_key in ("G28", "G30"):
            self.reference_return(line, axes)
        elif one_shot_key != "G53":  # (G53: a move in machine coordinates, left out)
            self.motion_block(line, motion, axes, arc, exact_stop=self.exact_stop or one_shot_key == "G9")
        if "M0" in m_codes:
            self.rest_here()
        if "M2" in m_codes or "M30" in m_codes:
            key = "M2" if "M2" in m_codes else "M30"
            self.end(line, f"{key} (line {line})")

    def set_feed(self, line, w):
        if self.increments and self.scale != 1.0 and not w.dot:
            self.fail(line, f"{w}: a feed without a decimal point under G20 with toolpath.decimal_point: increment "
                            "(controls read it in in/min or in 0.01 in/min); write it with a decimal point", w)
        f = w.value * self.scale
        lo, hi = FEED_RANGE_MM_PER_MIN
        if not lo <= f <= hi:
            self.fail(line, f"{w}: {f:g} mm/min is outside the feeds a run takes, [{lo:g}, {hi:g}] mm/min "
                            f"({lo / 60:g}-{hi / 60:g} mm/s)", w)
        self.feed = f

    def tool_change(self, line, w):
        t = self.selected_tool
        if not self.tool_loaded:
            if self.first_cut_line is not None:
                self.fail(line, f"{w}: a tool change after the program has cut (line {self.first_cut_line}): a "
                                "second tool; one program, one tool", w)
            self.tool_loaded, self.tool_number, self.tool_line, self.tool_scale = True, t, line, self.scale
        elif t != self.tool_number:
            self.fail(line, f"{w}: a change to T{t} (T{self.tool_number} since line {self.tool_line}): one program, "
                            "one tool; post each tool's operations as a program of their own", w)

    def dwell(self, line, g4, dwell, axes):
        if axes:
            self.fail(line, f"{g4}: a dwell with a move on the line ({', '.join(str(w) for _, w in axes.values())})",
                      g4)
        if len(dwell) != 1:
            self.fail(line, f"{g4}: a dwell needs P (ms) or X (s), one of them", g4)
        (letter, w), = dwell.items()
        if letter == "P":
            if w.dot:
                self.fail(line, f"{w}: a Fanuc reads G4 P as whole ms (P1500 = 1.5 s) and refuses a decimal point "
                                "(Haas and LinuxCNC read seconds); write P1500 or X1.5", w)
            t = w.value / 1000.0
        else:
            t = w.value * (0.001 if self.increments and not w.dot else 1.0)
        if not 0.0 <= t <= MAX_DWELL_S:
            self.fail(line, f"{w}: a dwell of {t:g} s (allowed: 0 to {MAX_DWELL_S:g} s)", w)
        self.rest_here(t)

    def reference_return(self, line, axes):
        """G28 / G30: the rapid move to the intermediate point; the return
        to the machine's reference point is left out."""
        target = list(self.pos)
        for letter, (v, _) in axes.items():
            i = _AXIS[letter]
            if self.absolute:
                target[i] = v
            elif self.pos[i] is not None:
                target[i] = self.pos[i] + v
        if None in self.pos:
            self.pos = target
            return
        if math.dist(self.pos, target) > 1e-9:
            self.add_move(Move("rapid", tuple(self.pos), tuple(target), None, self.spindle_rpm, line,
                               spindle_on=self.spindle_is_on()))
        self.pos = target

    def spindle_is_on(self):
        return self.spindle_on is not False and self.spindle_rpm != 0

    def motion_block(self, line, motion, axes, arc, exact_stop):
        if motion is None and (axes or arc):
            if self.motion is None:
                w = next(iter((axes or arc).values()))[1]
                self.fail(line, "coordinates without a motion word (G0, G1, G2 or G3) in effect", w)
            motion = (self.motion, None)
        if motion is None:
            return
        g, g_word = motion
        self.motion = g
        word = f"G{g}"
        if arc and g in (0, 1):
            self.fail(line, f"{'/'.join(sorted(arc))} given with {word}: arc words belong to G2 / G3",
                      next(iter(arc.values()))[1])
        end = list(self.pos)
        for letter, (v, w) in axes.items():
            i = _AXIS[letter]
            if not self.absolute and self.pos[i] is None:
                self.fail(line, f"{w}: an incremental (G91) move before the program has set {letter} absolutely", w)
            end[i] = v if self.absolute else self.pos[i] + v
        if not axes and g in (0, 1):
            return  # a motion word alone: modal state only
        if None in self.pos:
            # the robot starts at the first point the program fixes in X, Y and Z
            if g not in (0, 1):
                self.fail(line, f"{word}: an arc before the program has set X, Y and Z", g_word)
            self.pos = end
            if None not in end:
                self.start_line = line  # (the line that fixed the start: the tool was brought there somehow)
            return
        if g != 0 and self.feed is None:
            self.fail(line, f"{word} without a feed: no F word before this line", g_word)
        start, end_t = tuple(self.pos), tuple(end)
        common = dict(spindle_rpm=self.spindle_rpm, line=line, spindle_on=self.spindle_is_on(), stop_after=exact_stop)
        feed = None if g == 0 else self.feed
        if g in (0, 1):
            if math.dist(start, end_t) > 1e-9:
                self.add_move(Move("rapid" if g == 0 else "line", start, end_t, feed, **common))
        else:
            center = arc_center(self.plane, g, start, end_t, arc, self.arc_absolute,
                                lambda what, w=None: self.fail(line, what, w if w is not None else g_word))
            self.add_move(Move("arc", start, end_t, feed, center_mm=center, clockwise=g == 2, plane=self.plane,
                               **common))
        if g != 0 and self.first_cut_line is None:
            self.first_cut_line = line
        self.pos = end

    # ------------------------------------------------------------ the end

    def finish(self):
        if self.left_out:
            first, text = self.left_out[0]
            last = self.left_out[-1][0]
            span = f"line {first}" if first == last else f"lines {first}-{last}"
            self.warnings.append(f"{self.path}:{first}: {len(self.left_out)} block(s) after {self.end_what} are not "
                                 f"run ({span}; the first: {ascii(text[:40])})")
        if self.skipped:
            first, last = self.skipped[0], self.skipped[-1]
            span = f"line {first}" if first == last else f"lines {first}-{last}"
            self.warnings.append(f"{self.path}:{first}: {len(self.skipped)} block(s) skipped by block delete ('/', "
                                 f"toolpath.block_delete: skip; {span})")
        t = self.tool_number if self.tool_loaded else None
        if t is None and not self.tool_loaded and len(self.tool_comments) == 1:
            t = next(iter(self.tool_comments))
        if t in self.tool_comments:
            d, line, _ = self.tool_comments[t]
            self.tool_diameter_mm = d * (self.tool_scale or self.scale)
            self.tool_line = line
        self.tool_number = t
