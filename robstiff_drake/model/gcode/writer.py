"""A G-code program written again with corrected coordinates: the input's
own lines, words, line numbers, comments and number style, only the
coordinates of its corrected (cutting) moves changed, and a move the
correction splits written as several blocks.  Plain Python; no Drake.

A corrected line keeps all its words; its X / Y / Z (and, for an arc,
I / J / K or R) take the first piece's values, and an axis the line did
not name is added after its last coordinate word when the corrected end
differs from where the controller is in that axis.  The further pieces
follow as blocks of coordinates alone (the motion word is modal), the
last carrying the line's stop words (G9, M0, M1, M2, M30) when it had
any; a block-delete ``/`` is repeated on each.  Numbers are written with
a decimal point (so that a control reading numbers without one as
increments reads them right) and at most 4 decimals in mm (5 in inches).

Incremental (G91) coordinates on a corrected line are refused
(ProgramWriteError, naming the line): the corrected program is written
for absolute programs."""

import re

import numpy as np

from robstiff_drake.model.gcode import lexer
from robstiff_drake.model.gcode.moves import MM_PER_INCH, PLANES

STOP_WORDS = {("G", 9.0), ("M", 0.0), ("M", 1.0), ("M", 2.0), ("M", 30.0)}
_CENTRE_LETTERS = {"XY": ("I", "J"), "ZX": ("K", "I"), "YZ": ("J", "K")}
_WORD_AT = re.compile(r"[A-Za-z][ \t]*[+-]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)")


class ProgramWriteError(ValueError):
    def __init__(self, message, line):
        super().__init__(message)
        self.line = line


def number(value, decimals):
    """``value`` with at most ``decimals`` decimals, always a decimal point ("120.", "-2.7312")."""
    text = f"{value:.{decimals}f}".rstrip("0")
    if text in ("-.", "-0.", "."):
        text = "0."
    return "0." if text == "-0." else text


def _spans(text, block):
    """[(start, end, Word)]: each word's characters in the line."""
    out = []
    for w in block.words:
        i = w.column - 1
        m = _WORD_AT.match(text, i)
        out.append((i, m.end() if m else i + 1, w))
    return out


def _edit(text, spans, replace, remove, insert_after, extra):
    """``text`` with words replaced ({span index: text}), removed (set of
    indices), and ``extra`` (text) put after span ``insert_after`` (or at
    the end of the code when None)."""
    pieces, last = [], 0
    code_end = len(text)
    for k, (a, b, _) in enumerate(spans):
        pieces.append(text[last:a])
        if k in remove:
            pieces.append("")
        else:
            pieces.append(replace.get(k, text[a:b]))
        if k == insert_after and extra:
            pieces.append(" " + extra)
        last = b
    tail = text[last:code_end]
    if insert_after is None and extra:
        pieces.append(" " + extra if spans else extra)
    pieces.append(tail)
    return re.sub(r"[ \t]{2,}", " ", "".join(pieces)) if remove else "".join(pieces)


def _centre_words(move, start, piece, unit, decimals, arc_absolute, uses_r):
    a, b, _ = PLANES[move.plane]
    la, lb = _CENTRE_LETTERS[move.plane]
    c = np.asarray(piece.center_mm, dtype=float)
    if uses_r:
        r = float(np.hypot(start[a] - c[0], start[b] - c[1]))
        e = piece.end_mm
        a0 = np.arctan2(start[b] - c[1], start[a] - c[0])
        a1 = np.arctan2(e[b] - c[1], e[a] - c[0])
        sweep = ((a0 - a1) if move.clockwise else (a1 - a0)) % (2 * np.pi)
        return {"R": number((-r if sweep > np.pi else r) / unit, decimals)}
    if arc_absolute:
        return {la: number(c[0] / unit, decimals), lb: number(c[1] / unit, decimals)}
    return {la: number((c[0] - start[a]) / unit, decimals), lb: number((c[1] - start[b]) / unit, decimals)}


def rewrite_corrected(text, moves, corrections, header_lines=()):
    """The program ``text`` with ``corrections`` ({line: MoveCorrection},
    model/program_correction.py) written in; ``moves`` the program's
    gcode.Move list; ``header_lines`` comment texts put after the program
    number (or at the top).  Returns (new text, blocks added)."""
    newline = "\r\n" if "\r\n" in text else ("\r" if "\r" in text and "\n" not in text else "\n")
    lines = lexer.split_lines(text)
    by_line = {m.line: m for m in moves}
    paren = "(" in text or ";" not in text
    header = [f"({h.replace('(', '[').replace(')', ']')})" if paren else f"; {h}" for h in header_lines]
    out = []
    unit, absolute, arc_absolute = 1.0, True, False
    position = None  # where the controller is after the last written block (mm), once X, Y and Z are known
    added = 0
    header_at = 0
    for n, raw in enumerate(lines, start=1):
        try:
            block = lexer.lex(n, raw)
        except lexer.LexError:
            out.append(raw)
            continue
        if n <= 3 and (block.tape_mark or any(w.letter == "O" for w in block.words)):
            header_at = len(out) + 1
        for w in block.words:
            if w.letter == "G":
                if w.value == 20:
                    unit = MM_PER_INCH
                elif w.value == 21:
                    unit = 1.0
                elif w.value == 90:
                    absolute = True
                elif w.value == 91:
                    absolute = False
                elif abs(w.value - 90.1) < 1e-9:
                    arc_absolute = True
                elif abs(w.value - 91.1) < 1e-9:
                    arc_absolute = False
        decimals = 4 if unit == 1.0 else 5
        move = by_line.get(n)
        corr = corrections.get(n)
        if corr is None or move is None:
            out.append(raw)
            if move is not None:
                position = np.asarray(move.end_mm, dtype=float)
            continue
        if not absolute:
            raise ProgramWriteError(f"line {n}: incremental (G91) coordinates on a corrected move: the corrected "
                                    "program is written for absolute (G90) programs", n)
        spans = _spans(raw, block)
        start = np.asarray(position if position is not None else move.start_mm, dtype=float)
        uses_r = any(w.letter == "R" for w in block.words)
        prefix = "/" if block.block_delete else ""
        stops = {k for k, (_, _, w) in enumerate(spans) if (w.letter, w.value) in STOP_WORDS}
        split = len(corr.pieces) > 1
        for p, piece in enumerate(corr.pieces):
            end = np.asarray(piece.end_mm, dtype=float)
            values = {ax: number(end[i] / unit, decimals) for i, ax in enumerate("XYZ")}
            if move.kind == "arc":
                values.update(_centre_words(move, start, piece, unit, decimals, arc_absolute, uses_r))
            if p == 0:
                replace, present = {}, set()
                last_coord = None
                for k, (_, _, w) in enumerate(spans):
                    if w.letter in values:
                        replace[k] = w.letter + values[w.letter]
                        present.add(w.letter)
                        last_coord = k
                missing = [ax + values[ax] for ax in "XYZ" if ax not in present
                           and abs(end["XYZ".index(ax)] - start["XYZ".index(ax)]) > 1e-9]
                missing += [f"{k}{v}" for k, v in values.items() if k not in "XYZ" and k not in present]
                remove = stops if split else set()
                out.append(_edit(raw, spans, replace, remove, last_coord, " ".join(missing)))
            else:
                words = [ax + values[ax] for i, ax in enumerate("XYZ") if abs(end[i] - start[i]) > 1e-9]
                words += [f"{k}{v}" for k, v in values.items() if k not in "XYZ"]
                if p == len(corr.pieces) - 1 and stops:
                    words += [str(spans[k][2]) for k in sorted(stops)]
                out.append(prefix + " ".join(words))
                added += 1
            start = end
        position = start
    out[header_at:header_at] = header
    return newline.join(out) + (newline if text.endswith(("\n", "\r")) else ""), added
