"""docs/toolpaths.md's table of G-code words cannot fall behind the reader:
the table in the document is the one robstiff_drake/model/gcode/words.py
holds, and every word in it does what its row says when a program uses
it: an accepted or ignored word is read, a refused one is refused with one
line naming the file, line, column and the word."""

import re
from pathlib import Path

import pytest

from robstiff_drake.errors import InputError
from robstiff_drake.model.gcode import words as W
from robstiff_drake.model.gcode.program import read_program

DOC = Path(__file__).resolve().parents[1] / "docs" / "toolpaths.md"
HEAD = "G0 X0 Y0 Z10\nF100\n"
TAIL = "G1 X1\n"

# A line that uses the word as a program would (the default: the word alone).
CONTEXT = {
    "G2": "G2 X10 Y0 I5 J0", "G3": "G3 X10 Y0 R5", "G4": "G4 P100", "G9": "G9 G1 X2",
    "G18": "G18 G2 X10 Z10 I5 K0", "G19": "G19 G3 Y10 Z10 J5 K0", "G28": "G28 G91 Z0.", "G30": "G30 G91 Z0.",
    "G41": "G41 D1 X5", "G42": "G42 D1 X5", "G43": "G43 Z15. H1", "G44": "G44 Z15. H1", "G53": "G53 G0 Z0.",
    "G5.1": "G5.1 Q1", "G10": "G10 L2 P1 X0", "G65": "G65 P9000", "G52": "G52 X10", "G92": "G92 X0 Y0",
    "G68": "G68 X0 Y0 R45", "G51": "G51 X0 Y0 P2", "G51.1": "G51.1 X0", "G66": "G66 P9000", "G96": "G96 S200",
    "M6": "T1 M6", "M98": "M98 P100", "M99": "M99",
    "N": "N10 G1 X2", "X": "G1 X2", "Y": "G1 Y2", "Z": "G1 Z2", "I": "G2 X10 Y0 I5", "J": "G3 X0 Y0 J5",
    "K": "G18 G2 X5 Z15 K5", "R": "G2 X10 Y0 R5", "F": "F200", "S": "S1000", "T": "T1", "H": "G43 Z15. H1",
    "D": "D1", "P": "G4 P100", "Q": "G5.1 Q1", "L": "G1 X1 L2", "E": "G1 X1 E2",
    **{a: f"G1 X1 {a}10" for a in "ABCUVW"},
    "( )": "G1 X2 (a comment)", ";": "G1 X2 ; a comment", "/": "/G1 X2", "#": "#1=2", "[ ]": "G1 X[1]",
}
FIRST_LINE = {"O": "O1001", "%": "%"}  # words read only before the first move


def doc_table():
    text = DOC.read_text(encoding="utf-8")
    m = re.search(r"<!-- words-table:start -->\n(.*?)\n<!-- words-table:end -->", text, flags=re.S)
    assert m, "docs/toolpaths.md: no words table between its markers"
    return m.group(1)


def test_the_documents_table_is_the_readers_table():
    assert doc_table() == W.markdown_table(), \
        "docs/toolpaths.md's words table differs from model/gcode/words.py: paste the output of " \
        "`python -m robstiff_drake.model.gcode.words` between its markers"


def test_every_row_of_the_document_is_a_word_of_the_table():
    known = {w: s for w, s, _ in W.all_words()}
    for row in doc_table().splitlines()[2:]:
        cells = [c.strip() for c in row.strip("|").split("|")]
        for word in re.findall(r"`([^`]+)`", cells[0]):
            if "-" in word and word[0] in "GM":  # a range: G81-G89
                lo, hi = word.split("-")
                words = [f"{lo[0]}{n}" for n in range(int(lo[1:]), int(hi[1:]) + 1)]
            else:
                words = [word]
            for w in words:
                assert known.get(w) == cells[1], f"docs/toolpaths.md: {w} is {cells[1]}, the reader has {known.get(w)}"


@pytest.mark.parametrize("word, status, note", W.all_words(), ids=[w for w, _, _ in W.all_words()])
def test_every_word_does_what_the_table_says(word, status, note):
    if word in FIRST_LINE:
        text, line = FIRST_LINE[word] + "\n" + HEAD + TAIL, 1
    elif word in ("M2", "M30"):  # (nothing after them runs)
        text, line = HEAD + TAIL + word + "\n", 4
    else:
        text, line = HEAD + CONTEXT.get(word, word) + "\n" + TAIL, 3
    if status == W.REFUSED:
        with pytest.raises(InputError) as e:
            read_program(text, "p.nc")
        msg = str(e.value)
        assert re.match(rf"p\.nc:{line}:\d+: ", msg) and "\n" not in msg, msg
        assert (word[0] if word in W.SYNTAX else word) in msg, msg
    else:
        p = read_program(text, "p.nc")
        assert p.moves, word
