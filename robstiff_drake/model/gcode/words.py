"""Every G-code word the program reader (model/gcode/program.py) knows: accepted
(it acts on it), ignored (read, checked, and left out, with the reason) or
refused (one line naming the file, line, column and word, exit status 2).
Any word not listed here is refused as unknown.  docs/toolpaths.md shows
this table; tests/test_gcode_words_doc.py holds the two together.

The words are those of a one-tool, 3-axis milling program from a generic
Fanuc / ISO post (Fusion 360 / HSMWorks, Mastercam, NX), with Fanuc's
modal groups (Series 0i/30i-M G-code list: 00 one-shot, 01 motion, 02
plane, 03 distance, 05 feed mode, 06 units, 07 cutter compensation, 08
tool length, 09 canned cycles, 10 return level, 14 work offset, 15 path
mode); G90.1 / G91.1 (arc centre mode, not in Fanuc's list: LinuxCNC's
and Haas's) form their own group.

Repeated words on one line.  Fanuc takes several G words of different
groups on a line, and of one group keeps the last silently; here two of
one group are refused (as LinuxCNC does), since the silent last-wins is how
a program runs something other than what it shows.  M words: Fanuc allows
one per block, or up to three with parameter No. 3404#7 (M3B); here up to
three, at most one per group below (LinuxCNC's rule).  Every other address
(X, F, S, T ...) at most once per line.
"""

ACCEPTED, IGNORED, REFUSED = "accepted", "ignored", "refused"

_CYCLE = "canned cycles are not supported; post the program with the cycles expanded into G0/G1 moves"
_COMP = ("cutter radius compensation is not supported; post the program with the cutter centre path "
         "(compensation 'in computer', G40)")
_NOTHING = "a cancel with nothing to cancel here"

# "G<n>": (status, group, note); the note of a refused word is its error.
G_CODES = {
    "G0": (ACCEPTED, "motion", "rapid move, at toolpath.rapid_mm_per_s"),
    "G1": (ACCEPTED, "motion", "linear move at F"),
    "G2": (ACCEPTED, "motion", "arc clockwise (seen from the plane's normal): I/J/K centre offsets or R; a move "
                               "along the normal makes a helix"),
    "G3": (ACCEPTED, "motion", "arc counter-clockwise, as G2"),
    "G4": (ACCEPTED, "one-shot", "dwell: P in ms (whole number), or X in s; the path rests there, the spindle "
                                 "turning"),
    "G9": (ACCEPTED, "one-shot", "exact stop: the path comes to rest at the end of the block"),
    "G17": (ACCEPTED, "plane", "arcs in the XY plane (I, J)"),
    "G18": (ACCEPTED, "plane", "arcs in the ZX plane (K, I), as CAM posts write vertical lead-in arcs"),
    "G19": (ACCEPTED, "plane", "arcs in the YZ plane (J, K)"),
    "G20": (ACCEPTED, "units", "inches: coordinates, I/J/K, R and F of the whole block"),
    "G21": (ACCEPTED, "units", "millimetres"),
    "G28": (IGNORED, "one-shot", "reference return: the move to its intermediate point is made (none for "
                                 "`G28 G91 Z0.`), the return to the machine's reference point left out: a robot "
                                 "cell has none in the program's frame; the robot goes on from there"),
    "G30": (IGNORED, "one-shot", "second reference return: as G28"),
    "G40": (ACCEPTED, "cutter comp", "cutter compensation off: the program is the cutter centre path"),
    "G41": (REFUSED, "cutter comp", _COMP),
    "G42": (REFUSED, "cutter comp", _COMP),
    "G43": (ACCEPTED, "tool length", "tool length offset: the tool length is the robot file's tool point "
                                     "(payload.tool_point_mm); H is not used (a warning when it is not the tool's "
                                     "number); a Z on the line moves as usual"),
    "G44": (REFUSED, "tool length", "negative tool length offsets are not supported; the tool point is the robot "
                                    "file's"),
    "G49": (ACCEPTED, "tool length", "tool length offset off: " + _NOTHING),
    "G53": (IGNORED, "one-shot", "move in machine coordinates (`G53 G0 Z0.`, a retract to the machine's top): "
                                 "left out, a robot cell has no machine coordinates in the program's frame"),
    **{f"G{g}": (ACCEPTED, "work offset", "the scenario's work offset (toolpath.work_offset_mm, --work-offset), "
                                          "whatever its number; a program uses one (a second is refused)")
       for g in range(54, 60)},
    "G61": (ACCEPTED, "path mode", "exact stop mode: the path comes to rest at the end of every move (no zone)"),
    "G64": (ACCEPTED, "path mode", "cutting mode: corners flown by within path.zone_mm (the default)"),
    "G80": (ACCEPTED, "cycle", "canned cycle off: " + _NOTHING),
    "G73": (REFUSED, "cycle", _CYCLE),
    "G74": (REFUSED, "cycle", _CYCLE),
    "G76": (REFUSED, "cycle", _CYCLE),
    **{f"G{g}": (REFUSED, "cycle", _CYCLE) for g in range(81, 90)},
    "G90": (ACCEPTED, "distance", "absolute coordinates"),
    "G91": (ACCEPTED, "distance", "incremental coordinates"),
    "G90.1": (ACCEPTED, "arc centre", "arc centres I/J/K absolute (work frame)"),
    "G91.1": (ACCEPTED, "arc centre", "arc centres I/J/K from the arc's start (the default)"),
    "G93": (REFUSED, "feed mode", "inverse-time feed is not supported; post with G94 (per minute)"),
    "G94": (ACCEPTED, "feed mode", "feed per minute"),
    "G95": (REFUSED, "feed mode", "feed per revolution is not supported; post with G94 (per minute)"),
    "G98": (IGNORED, "return level", "canned cycles' return level: no cycle runs here (they are refused)"),
    "G99": (IGNORED, "return level", "as G98"),
    "G10": (REFUSED, "one-shot", "programmed data setting (offsets, parameters) is not supported"),
    "G52": (REFUSED, "one-shot", "local coordinate systems are not supported; one work offset per program"),
    "G65": (REFUSED, "one-shot", "macro calls are not supported; post the program expanded"),
    "G92": (REFUSED, "one-shot", "setting the work coordinate system in the program is not supported; the "
                                 "scenario's work offset places it"),
    "G15": (ACCEPTED, "polar", "polar coordinates off: " + _NOTHING),
    "G16": (REFUSED, "polar", "polar coordinates are not supported"),
    "G68": (REFUSED, "rotation", "coordinate rotation is not supported; use toolpath.work_rotation_deg"),
    "G69": (ACCEPTED, "rotation", "coordinate rotation off: " + _NOTHING),
    "G50": (ACCEPTED, "scaling", "scaling off: " + _NOTHING),
    "G51": (REFUSED, "scaling", "scaling is not supported"),
    "G50.1": (ACCEPTED, "mirror", "mirror image off: " + _NOTHING),
    "G51.1": (REFUSED, "mirror", "mirror images are not supported"),
    "G66": (REFUSED, "macro modal", "macro calls are not supported; post the program expanded"),
    "G67": (ACCEPTED, "macro modal", "modal macro call off: " + _NOTHING),
    "G96": (REFUSED, "spindle mode", "constant surface speed is a lathe's; a milling program gives S in rpm"),
    "G97": (ACCEPTED, "spindle mode", "S in rpm (the only spindle mode here)"),
    "G5.1": (IGNORED, "one-shot", "AI contour / look-ahead (`G5.1 Q1`): the robot controller plans its own "
                                  "path (corners: path.zone_mm)"),
}

# Fanuc's group of each M word (at most one per group on a line).
M_CODES = {
    "M0": (ACCEPTED, "stop", "program stop: the path comes to rest there (the operator's wait is not "
                             "simulated)"),
    "M1": (IGNORED, "stop", "optional stop: off, as in production"),
    "M2": (ACCEPTED, "stop", "end of program: nothing after it runs (a warning names what is left out)"),
    "M30": (ACCEPTED, "stop", "end of program, as M2"),
    "M3": (ACCEPTED, "spindle", "spindle on, clockwise (the force model's right-hand cutter), at S"),
    "M4": (REFUSED, "spindle", "counter-clockwise spindle (M4) is not supported; the force model is a "
                               "right-hand cutter (M3)"),
    "M5": (ACCEPTED, "spindle", "spindle off: a feed move into uncut stock after it is refused"),
    "M6": (ACCEPTED, "tool change", "the program's one tool (T); a change to a second tool is refused"),
    "M7": (IGNORED, "coolant", "mist coolant: coolant is not in the model"),
    "M8": (IGNORED, "coolant", "flood coolant: coolant is not in the model"),
    "M9": (IGNORED, "coolant", "coolant off"),
    "M31": (IGNORED, "conveyor", "chip conveyor forward (Haas): not in the model"),
    "M33": (IGNORED, "conveyor", "chip conveyor stop (Haas)"),
    "M88": (IGNORED, "coolant", "through-spindle coolant on (Haas): coolant is not in the model"),
    "M89": (IGNORED, "coolant", "through-spindle coolant off (Haas)"),
    "M19": (REFUSED, "spindle", "spindle orientation is not supported"),
    "M98": (REFUSED, "subprogram", "subprogram calls are not supported; post the program expanded"),
    "M99": (REFUSED, "subprogram", "subprograms are not supported; post the program expanded"),
}
MAX_M_PER_BLOCK = 3  # Fanuc with parameter M3B

# Addresses other than G and M.
LETTERS = {
    "N": (ACCEPTED, "line (sequence) number: read, not used"),
    "O": (ACCEPTED, "program number: before the first move only (a second program in the file is refused)"),
    "X": (ACCEPTED, "coordinate (mm, or inches under G20; a number without a decimal point: "
                    "toolpath.decimal_point); with G4: the dwell in s"),
    "Y": (ACCEPTED, "coordinate, as X"),
    "Z": (ACCEPTED, "coordinate, as X"),
    "I": (ACCEPTED, "arc centre along X (G17, G18)"),
    "J": (ACCEPTED, "arc centre along Y (G17, G19)"),
    "K": (ACCEPTED, "arc centre along Z (G18, G19)"),
    "R": (ACCEPTED, "arc radius: > 0 the arc of at most 180 degrees, < 0 the longer one"),
    "F": (ACCEPTED, "feed, mm/min (in/min under G20), 6-120000 mm/min"),
    "S": (ACCEPTED, "spindle speed, rpm (0, or 10-60000)"),
    "T": (ACCEPTED, "tool number: the program's one tool (a later `T` alone is a preselection, not a change)"),
    "H": (ACCEPTED, "tool length offset number, with G43 only: not used (the robot file's tool point)"),
    "D": (IGNORED, "cutter compensation offset number: used only by G41 / G42, which are refused"),
    "P": (ACCEPTED, "with G4 only: the dwell in ms"),
    "Q": (IGNORED, "with G5.1 only (`G5.1 Q1`), ignored with it; anywhere else refused (peck depths, "
                   "subprogram options)"),
    "L": (REFUSED, "L words (repeats, subprograms) are not supported"),
    "E": (REFUSED, "E words (extruders, threading) are not supported: this is a milling program reader"),
    **{a: (REFUSED, "5-axis (rotary and secondary linear) words are not supported; a 3-axis program only")
       for a in "ABCUVW"},
}

# Characters with a meaning of their own.
SYNTAX = {
    "%": (ACCEPTED, "tape start and end: the program runs from the first `%` to the second; nothing after the "
                    "closing `%` runs (a warning names what is left out)"),
    "( )": (ACCEPTED, "comment; `(T1 D=75. ...)` (Fusion 360, HSMWorks) or `(TOOL - 1 ... DIA. - 75.)` "
                      "(Mastercam) gives the tool's diameter, checked against cutter.diameter_mm"),
    ";": (ACCEPTED, "comment to the end of the line"),
    "/": (ACCEPTED, "block delete at the start of a line (`/` or `/1`): skipped or run as "
                    "toolpath.block_delete says (a warning counts the skipped blocks)"),
    "#": (REFUSED, "macro variables are not supported; post the program expanded"),
    "[ ]": (REFUSED, "macro expressions are not supported; post the program expanded"),
}


def canonical_g(value):
    """'G01' -> 'G1', 'G90.10' -> 'G90.1' (a G word's number as the table keys it)."""
    return f"G{round(value, 3):g}"


def canonical_m(value):
    return f"M{round(value, 3):g}"


def all_words():
    """[(word, status, note)] of every entry, in the table's order."""
    out = [(w, s, n) for w, (s, _, n) in G_CODES.items()]
    out += [(w, s, n) for w, (s, _, n) in M_CODES.items()]
    out += [(w, s, n) for w, (s, n) in LETTERS.items()]
    out += [(w, s, n) for w, (s, n) in SYNTAX.items()]
    return out


def _label(group):
    """'G81, G82, ..., G89' -> 'G81-G89'; other words listed."""
    out, run = [], []

    def flush():
        if len(run) >= 3:
            out.append(f"{run[0][1]}-{run[-1][1]}")
        else:
            out.extend(w for _, w in run)
        run.clear()

    for w in group:
        head, num = w[0], w[1:]
        if head in "GM" and num.isdigit():
            if run and (run[-1][0] + 1 != int(num) or run[-1][1][0] != head):
                flush()
            run.append((int(num), w))
        else:
            flush()
            out.append(w)
    flush()
    return ", ".join(f"`{w}`" for w in out)


def markdown_table():
    """The table of docs/toolpaths.md: consecutive words with the same
    status and note share a row."""
    rows, group, key = [], [], None
    for word, status, note in all_words() + [(None, None, None)]:
        if (status, note) != key and group:
            rows.append(f"| {_label(group)} | {key[0]} | {key[1]} |")
            group = []
        key = (status, note)
        group.append(word)
    return "\n".join(["| word | read | what it does here |", "|---|---|---|"] + rows)


if __name__ == "__main__":
    print(markdown_table())
