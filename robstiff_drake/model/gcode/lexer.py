"""A G-code file's text read into blocks as a controller reads it.
Plain Python; no Drake.

* A block ends at LF or CR (CR LF is one end), the ISO end-of-block
  characters.  Every other control or invisible character (VT, FF, NEL,
  U+2028, zero-width and bidirectional marks ...) is refused wherever it
  stands, comments included: an editor, ``grep`` and a controller would
  not agree on where the line ends or what it says.
* Outside comments only ASCII is read: letters, digits, ``+ - .``,
  blanks; any other character (an Arabic-Indic digit read as a digit by
  Python, a non-breaking space) is refused with its column.
* Comments: ``( ... )`` (not nested, closed on the line) and ``;`` to the
  end of the line; they may hold any printable text.
* A word: an ASCII letter, blanks allowed, then a number with an optional
  sign and decimal point (``X-12.5``, ``X.5``, ``X12.``); no exponents.
* ``/`` or ``/1`` at the start of a block: block delete; ``%`` alone on its
  line: a tape mark.

Errors are ``file:line:column: what`` (one line; InputError)."""

import re
import unicodedata
from dataclasses import dataclass, field

_END_OF_BLOCK = re.compile(r"\r\n|\r|\n")
_NUMBER = re.compile(r"[+-]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)")
_EXPONENT = re.compile(r"[eE][+-]?[0-9]")
# character categories refused anywhere: controls, format (zero-width, bidi),
# line / paragraph separators, surrogates, private use, unassigned
_INVISIBLE = {"Cc", "Cf", "Zl", "Zp", "Cs", "Co", "Cn"}
_NAMES = {"\x0b": "vertical tab", "\x0c": "form feed", "\x85": "next line (NEL)", "\x00": "NUL",
          "\x1b": "escape", "\x7f": "delete"}


@dataclass(frozen=True)
class Word:
    """One word: ``letter`` (upper case), the number as written, its value,
    whether it had a decimal point, and the letter's column (1-based)."""

    letter: str
    text: str
    value: float
    dot: bool
    column: int

    def __str__(self):
        return f"{self.letter}{self.text}"


@dataclass
class Block:
    line: int
    words: list = field(default_factory=list)
    comments: list = field(default_factory=list)  # [(column, text)]
    block_delete: bool = False
    tape_mark: bool = False  # a '%' line


def split_lines(text):
    """The lines of ``text``, ended by LF, CR or CR LF only."""
    lines = _END_OF_BLOCK.split(text)
    if lines and lines[-1] == "":
        lines.pop()
    return lines


def describe(ch):
    name = _NAMES.get(ch) or unicodedata.name(ch, "").lower()
    return f"U+{ord(ch):04X}" + (f" ({name})" if name else "")


def invisible_character(line):
    """(column, character) of the first control or invisible character of
    a line (a tab is a blank), or None."""
    for i, ch in enumerate(line):
        if ch != "\t" and unicodedata.category(ch) in _INVISIBLE:
            return i + 1, ch
    return None


class LexError(Exception):
    """(column, message): the caller adds the file and line."""

    def __init__(self, column, message):
        super().__init__(message)
        self.column = column


def lex(line_no, text):
    """The Block of one line (LexError on anything a controller would not read)."""
    bad = invisible_character(text)
    if bad:
        col, ch = bad
        raise LexError(col, f"control character {describe(ch)}: a controller, an editor and grep would not "
                            "agree on this line; remove it")
    b = Block(line_no)
    i, n = 0, len(text)
    while i < n:
        ch = text[i]
        col = i + 1
        if ch in " \t":
            i += 1
        elif ch == "(":
            close = text.find(")", i + 1)
            inner = text.find("(", i + 1)
            if close < 0:
                raise LexError(col, "a comment '(' without its ')' on the line")
            if 0 <= inner < close:
                raise LexError(inner + 1, "a '(' inside a comment (comments do not nest)")
            b.comments.append((col, text[i + 1:close]))
            i = close + 1
        elif ch == ")":
            raise LexError(col, "a ')' without its '('")
        elif ch == ";":
            b.comments.append((col, text[i + 1:]))
            break
        elif ch == "/":
            if b.words or b.block_delete or b.tape_mark:
                raise LexError(col, "'/' (block delete) is read only at the start of a block")
            b.block_delete = True
            i += 1
            if i < n and text[i].isascii() and text[i].isdigit():
                if text[i] != "1":
                    raise LexError(col, f"'/{text[i]}' (optional block skip {text[i]}) is not supported; "
                                        "'/' or '/1' only")
                i += 1
        elif ch == "%":
            if b.words or b.block_delete or b.tape_mark:
                raise LexError(col, "'%' (a tape mark) must stand alone on its line")
            b.tape_mark = True
            i += 1
        elif ch.isascii() and ch.isalpha():
            if b.tape_mark:
                raise LexError(col, "'%' (a tape mark) must stand alone on its line")
            i = _word(b, text, i)
        elif not ch.isascii():
            raise LexError(col, f"non-ASCII character {describe(ch)} outside a comment: G-code words are ASCII "
                                "letters and digits")
        elif ch == "#":
            raise LexError(col, "'#': macro variables are not supported; post the program expanded")
        elif ch in "[]":
            raise LexError(col, f"'{ch}': macro expressions are not supported; post the program expanded")
        elif ch.isdigit() or ch in "+-.":
            m = _NUMBER.match(text, i)
            raise LexError(col, f"cannot read {(m.group(0) if m else ch)!r}: a number without its address letter")
        else:
            raise LexError(col, f"cannot read {ch!r} (expected words such as G1, X10.5)")
    return b


def _word(b, text, i):
    """Read the word at text[i] into b; the index after it."""
    letter = text[i].upper()
    col = i + 1
    j = i + 1
    while j < len(text) and text[j] in " \t":
        j += 1
    m = _NUMBER.match(text, j)
    if m is None:
        k = j
        while k < len(text) and text[k] in "+-.":
            k += 1
        if k < len(text) and not text[k].isascii():
            raise LexError(k + 1, f"non-ASCII character {describe(text[k])} in the word {letter}: G-code numbers "
                                  "are ASCII digits")
        if j < len(text) and text[j] in "#[":
            raise LexError(j + 1, f"{letter}{text[j]}: macro variables and expressions are not supported; post the "
                                  "program expanded")
        raise LexError(col, f"{letter} without a number")
    end = m.end()
    if _EXPONENT.match(text, end):
        e = re.match(r"[eE][+-]?[0-9]+", text[end:]).group(0)
        raise LexError(end + 1, f"{letter}{m.group(0)}{e}: G-code numbers have no exponent; write the number out")
    if end < len(text) and not text[end].isascii():
        raise LexError(end + 1, f"non-ASCII character {describe(text[end])} in the word {letter}{m.group(0)}: "
                                "G-code numbers are ASCII digits")
    num = m.group(0)
    b.words.append(Word(letter, num, float(num), "." in num, col))
    return end
