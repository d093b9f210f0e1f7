"""G-code programs from CAM, read into moves as a Fanuc-style controller
reads them: a one-tool, 3-axis milling program as a generic Fanuc / ISO
post writes it (Fusion 360, HSMWorks, Mastercam, NX).  Plain Python; no
Drake.

How a line is split and read (control characters, ASCII, comments):
model/gcode/lexer.py.  Which words are accepted, ignored or refused, and
why: model/gcode/words.py (docs/toolpaths.md shows the table).  A block:

* its G words first, whatever their place on the line: units (G20 / G21),
  distance mode (G90 / G91), plane and arc-centre mode apply to the whole
  block (``F47.244 G20`` is 47.244 in/min);
* then in LinuxCNC's order of execution (Fanuc leaves it to the machine
  builder): feed and spindle speed, tool change, spindle on / off, dwell,
  the move, program stop / end;
* a line of coordinates alone repeats the last motion word (modal), as a
  post writes consecutive moves.

Numbers without a decimal point (``X10``): ``decimal_point="calculator"``
reads 10 mm (10 in under G20), as LinuxCNC and a Fanuc with
calculator-type input do; ``"increment"`` reads 10 least input
increments, 0.010 mm (0.0010 in), as a Fanuc reads it by default (its
IS-B increment system).  G4 X: s, or 0.001 s.  F is mm/min either way
(in/min under G20: refused without a decimal point in increment mode,
where controls differ).

Nothing after M30 / M2 or the closing ``%`` runs; a warning names what is
left out.  Errors: ``file:line:column: WORD: what`` (InputError), before
anything runs.  Units: every coordinate of a ``Move`` is in mm in the
program's (work) frame, feeds in mm/min.

No package on PyPI fits (see docs/toolpaths.md): gcodeparser reads
3D-printer G-code; pygcode parses this subset but is GPLv3 (this project is
MIT) and unreleased since 2017."""

from dataclasses import dataclass, field
from pathlib import Path

from robstiff_drake.errors import InputError
from robstiff_drake.model.gcode import lexer
from robstiff_drake.model.gcode.modal import ProgramState
from robstiff_drake.model.gcode.moves import ARC_END_TOLERANCE_MM, MAX_MOVES, MM_PER_INCH, PLANES, Move

# The largest program file this reader takes (a CAM program of a few
# hundred thousand lines is a few MB).
MAX_PROGRAM_BYTES = 50_000_000
DECIMAL_POINT = ("calculator", "increment")
BLOCK_DELETE = ("skip", "run")


@dataclass
class Program:
    """A read program: its moves, the file, the start point (mm, work
    frame: the first point where X, Y and Z are all set), warnings (legal
    but likely not what was meant), the tool (its number, and the
    diameter its comment gives, mm, with the comment's line) and the
    dwell before the first move (s)."""

    moves: list
    path: str
    start_mm: tuple
    warnings: list = field(default_factory=list)
    tool_number: int = None
    tool_diameter_mm: float = None
    tool_line: int = None
    dwell_before_s: float = 0.0
    units_stated: bool = True  # a G20 or G21 before the first move (else read as mm: diagrams/toolpath warns)
    start_line: int = None  # the line that fixed the start point (its last unknown axis)

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


def read_program(text, path="program", *, decimal_point="calculator", block_delete="skip"):
    """Read G-code ``text`` (of file ``path``, for messages) into a Program.
    The tool starts at the first point where the program has set X, Y and
    Z (the moves that lead there from an unknown position are skipped: the
    robot is brought there before the program runs).  Raises InputError
    naming the file, line, column and word."""
    if decimal_point not in DECIMAL_POINT:
        raise ValueError(f"decimal_point must be one of {DECIMAL_POINT}")
    if block_delete not in BLOCK_DELETE:
        raise ValueError(f"block_delete must be one of {BLOCK_DELETE}")
    st = ProgramState(str(path), decimal_point == "increment", block_delete == "skip")
    lines = lexer.split_lines(text)
    for n, line in enumerate(lines, 1):
        if st.ended:
            st.after_end(n, line)
            continue
        try:
            block = lexer.lex(n, line)
        except lexer.LexError as e:
            raise InputError(f"{path}:{n}:{e.column}: {e}") from None
        st.block(block)
    st.finish()
    if not st.moves:
        raise InputError(f"{path}: no motion from a known point (G0, G1, G2 or G3 after X, Y and Z are set) in "
                         "the program")
    return Program(st.moves, str(path), st.moves[0].start_mm, st.warnings, st.tool_number, st.tool_diameter_mm,
                   st.tool_line, st.dwell_before_s, st.units_before_first_move, st.start_line)


def decode_program(raw, path):
    """The text of a program file's bytes (UTF-8, else Latin-1 as old
    controls' ISO files are; InputError on NUL bytes)."""
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError:
        text = raw.decode("latin-1")
    if "\x00" in text:
        before = text[:text.index("\x00")]
        line, col = before.count("\n") + 1, len(before) - before.rfind("\n")
        raise InputError(f"{path}:{line}:{col}: control character U+0000 (NUL): not a text file")
    return text


def read_program_file(path, label=None, **options):
    """Read a G-code file (InputError on anything wrong, naming it as
    ``label``, default its path); ``options``: see read_program."""
    label = str(path) if label is None else str(label)
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: no such G-code program" if not path.exists() else f"{path}: not a file")
    try:
        raw = path.read_bytes()
    except OSError as e:
        raise InputError(f"{path}: cannot read ({e.strerror})") from None
    if len(raw) > MAX_PROGRAM_BYTES:
        raise InputError(f"{path}: {len(raw)} bytes, more than the {MAX_PROGRAM_BYTES} this reader takes")
    return read_program(decode_program(raw, label), label, **options)


__all__ = ["ARC_END_TOLERANCE_MM", "MAX_MOVES", "MM_PER_INCH", "PLANES", "Move", "Program", "read_program",
           "read_program_file"]
