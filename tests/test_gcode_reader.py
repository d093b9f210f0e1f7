"""The G-code reader reads a program as a controller does (issue 19 item 2)
and takes a generic Fanuc / ISO post's program unchanged (issue 20 item 1):
line ends, characters, the program's end, repeated words, units and modes
over the whole block, the decimal-point rule, block delete, dwells and
exact stops, arcs in the three planes, the one tool and its comment,
reference returns; every error names file:line:column (one line)."""

import math

import pytest

from robstiff_drake.errors import InputError
from robstiff_drake.model.gcode.program import read_program

HEAD = "G0 X0 Y0 Z10\nF100\n"  # a known start and a feed


def moves_of(text, **kw):
    return [(m.kind, m.start_mm, m.end_mm) for m in read_program(text, "p.nc", **kw).moves]


def refused(text, where, *words, **kw):
    """The one-line error of ``text``: it starts with ``where`` and names ``words``."""
    with pytest.raises(InputError) as e:
        read_program(text, "p.nc", **kw)
    msg = str(e.value)
    assert "\n" not in msg and msg.startswith(where + " "), msg
    for w in words:
        assert w in msg, msg
    return msg


# ------------------------------------------------------------ lines and characters


@pytest.mark.parametrize("ch, name", [("\x0b", "vertical tab"), ("\x0c", "form feed"), ("\x85", "next line"),
                                      ("\u2028", "line separator"), ("\u200b", "zero width space"),
                                      ("\u202e", "right-to-left override"), ("\x1b", "escape"), ("\x00", "NUL")])
def test_a_control_character_is_refused_where_it_stands_even_in_a_comment(ch, name):
    line = f"N70 G1 X40. ; (was Z-0.3){ch}Z-0.3"
    col = line.index(ch) + 1
    refused(HEAD + line + "\n", f"p.nc:3:{col}:", "control character", name)


def test_lines_end_at_lf_cr_and_crlf_only():
    lf = moves_of("G0 X0 Y0 Z10\nG1 X5 F100\nY5\n")
    assert moves_of("G0 X0 Y0 Z10\rG1 X5 F100\rY5\r") == lf
    assert moves_of("G0 X0 Y0 Z10\r\nG1 X5 F100\r\nY5\r\n") == lf
    # a tab is a blank
    assert moves_of("G0\tX0 Y0 Z10\nG1\tX5 F100\nY5\n") == lf


@pytest.mark.parametrize("digits", ["\u0664\u0660", "\u096a\u0966", "\uff14\uff10"])  # Arabic-Indic, Devanagari, fullwidth 40
def test_a_non_ascii_digit_is_refused_at_its_column(digits):
    line = f"G1 X{digits}"
    refused(HEAD + line + "\n", "p.nc:3:5:", "non-ASCII", f"U+{ord(digits[0]):04X}")


def test_non_ascii_text_in_a_comment_is_read():
    assert moves_of(HEAD + "G1 X5 (Ø75 Planfräser)\n") == [("line", (0.0, 0.0, 10.0), (5.0, 0.0, 10.0))]


def test_an_exponent_is_refused_at_the_programs_line():
    refused(HEAD + "G1 X5 F1e9\n", "p.nc:3:9:", "F1e9", "no exponent")  # (the column of the e)


def test_a_feed_out_of_range_blames_the_program_not_the_scenario():
    msg = refused(HEAD + "G1 X5 F1000000000\n", "p.nc:3:7:", "F1000000000", "mm/min")
    assert "path.feed_mm_per_s" not in msg.split("(")[0]


# ------------------------------------------------------------ the end


@pytest.mark.parametrize("end", ["M30", "M2", "%"])
def test_nothing_after_the_end_runs_and_a_warning_names_it(end):
    body = "%\n" + HEAD + "G1 X5\n"
    p = read_program(body + f"{end}\nG1 X40 Y40\nG1 Z-25\n%\n", "p.nc")
    assert [m.end_mm for m in p.moves] == [(5.0, 0.0, 10.0)]
    (w,) = p.warnings
    assert w.startswith("p.nc:6: 2 block(s) after") and "'G1 X40 Y40'" in w, w


def test_the_closing_percent_sign_after_m30_is_no_warning():
    p = read_program("%\nO1\n" + HEAD + "G1 X5\nM30\n%\n\n", "p.nc")
    assert p.warnings == []


# ------------------------------------------------------------ repeated words


@pytest.mark.parametrize("line, col, words", [
    ("G1 X10 X20", 8, ["X20", "X twice", "X10"]),
    ("G1 X10 F100 F200", 13, ["F200", "twice"]),
    ("G0 G1 X5", 4, ["G1", "second motion G-code", "G0"]),
    ("G90 G91 X5", 5, ["G91", "second distance"]),
    ("G20 G21 X5", 5, ["G21", "second units"]),
    ("M3 M5", 4, ["M5", "second spindle M-code"]),
    ("M3 M8 M6 M1", 10, ["M1", "more than 3 M-codes"]),
])
def test_repeated_words_of_one_address_or_group_are_refused(line, col, words):
    refused(HEAD + line + "\n", f"p.nc:3:{col}:", *words)


def test_g_words_of_different_groups_and_m_words_of_different_groups_are_read():
    p = read_program(HEAD + "G17 G90 G21 G40 G49 G80 G94 G54 G64\nT1 M6 M3 M8\nG1 X5 M9 M5\n", "p.nc")
    assert [m.end_mm for m in p.moves] == [(5.0, 0.0, 10.0)]
    assert p.moves[0].spindle_on is False  # M5 on the move's line: the spindle stops first (LinuxCNC's order)


# ------------------------------------------------------------ modes over the whole block


def test_units_apply_to_the_whole_block_whatever_the_order():
    a = read_program(HEAD + "F47.244 G20\nG1 X1.\n", "p.nc").moves[0]
    b = read_program(HEAD + "G20 F47.244\nG1 X1.\n", "p.nc").moves[0]
    assert a.feed_mm_per_min == pytest.approx(1200.0, rel=1e-5) and b.feed_mm_per_min == a.feed_mm_per_min
    assert a.end_mm == pytest.approx((25.4, 0.0, 10.0))
    c = read_program(HEAD + "G1 X1. G20\n", "p.nc").moves[0]
    assert c.end_mm == pytest.approx((25.4, 0.0, 10.0))


def test_distance_mode_applies_to_the_whole_block():
    assert moves_of(HEAD + "G1 X10 G91\nX10\n")[-1][2] == (20.0, 0.0, 10.0)


def test_words_in_any_order_make_the_same_moves():
    a = moves_of(HEAD + "N5 G1 X5. Y2. Z1. F300.\nG2 X7. Y4. I2. J0.\n")
    b = moves_of(HEAD + "N5 F300. Z1. Y2. X5. G1\nJ0. I2. Y4. X7. G2\n")
    assert a == b


# ------------------------------------------------------------ numbers without a decimal point


def test_decimal_point_calculator_and_increment():
    assert moves_of(HEAD + "G1 X10\n")[0][2] == (10.0, 0.0, 10.0)
    inc = moves_of("G0 X0. Y0. Z10.\nF100.\nG1 X10 Y2.5\n", decimal_point="increment")
    assert inc[0][2] == pytest.approx((0.010, 2.5, 10.0))
    inch = moves_of("G20\nG0 X0. Y0. Z1.\nF10.\nG1 X10\n", decimal_point="increment")
    assert inch[0][2] == pytest.approx((0.0254, 0.0, 25.4))
    # F without a point under G20: controls differ, so refused in increment mode
    refused("G20\nG0 X0. Y0. Z1.\nG1 X1. F10\n", "p.nc:3:8:", "F10", "decimal point", decimal_point="increment")
    # F in mm/min is whole mm/min either way
    assert read_program("G0 X0. Y0. Z1.\nG1 X1. F300\n", "p.nc", decimal_point="increment").moves[0]. \
        feed_mm_per_min == 300.0


# ------------------------------------------------------------ a post's words


POST = """%
O1001 (FACE AND CONTOUR)
(T1 D=75. CR=0. - ZMIN=-3. - FACE MILL)
N10 G90 G94 G17 G49 G40 G80
N15 G21
N20 G28 G91 Z0.
N25 G90
N30 T1 M6
N35 T1
N40 S3600 M3
N45 G54
N50 M8
N55 G0 X-60. Y-40.
N60 G43 Z15. H1
N65 G0 Z5.
N70 G1 Z-3. F300.
N75 X60. F1200.
N80 G4 P500
N85 G3 X60. Y0. R20.
N90 G1 X-40.
N95 M1
N100 G2 X-60. Y20. R20.
N105 G1 Y100.
N110 G0 Z15.
N115 M9
N120 M5
N125 G28 G91 Z0.
N130 G90
N135 M30
%
"""


def test_a_fanuc_posts_program_runs_unchanged():
    p = read_program(POST, "post.nc")
    assert p.warnings == []
    assert p.start_mm == (-60.0, -40.0, 15.0)  # G43 Z15. completes the first point
    assert [m.kind for m in p.moves] == ["rapid", "line", "line", "arc", "line", "arc", "line", "rapid"]
    assert p.tool_number == 1 and p.tool_diameter_mm == 75.0 and p.tool_line == 3
    face = p.moves[2]
    assert face.feed_mm_per_min == 1200.0 and face.spindle_rpm == 3600.0 and face.spindle_on
    assert face.stop_after and face.dwell_after_s == 0.5  # G4 P500: rests 0.5 s at its end
    assert p.moves[3].center_mm == pytest.approx((60.0, -20.0)) and p.moves[3].sweep_rad() == pytest.approx(math.pi)
    assert p.moves[-1].end_mm == (-60.0, 100.0, 15.0)  # the G28 G91 Z0. returns are left out


def test_mastercam_tool_comment_and_inch_diameter():
    p = read_program("(TOOL - 1 DIA. OFF. - 1 LEN. - 1 DIA. - 75.)\nT1 M6\n" + HEAD + "G1 X1\n", "p.nc")
    assert p.tool_diameter_mm == 75.0
    p = read_program("(T3 D=2. CR=0. - FACE MILL)\nG20\nT3 M6\nG0 X0 Y0 Z1\nG1 X1 F10\n", "p.nc")
    assert p.tool_diameter_mm == pytest.approx(50.8) and p.tool_number == 3


def test_a_second_tool_is_refused_a_preselection_is_not():
    read_program("T1 M6\nT2\n" + HEAD + "G1 X5\n", "p.nc")  # a preselect of the next tool: no change
    refused("T1 M6\n" + HEAD + "G1 X5\nT2 M6\n", "p.nc:5:4:", "M6", "T2", "T1 since line 1", "one tool")
    refused(HEAD + "G1 X5\nT1 M6\n", "p.nc:4:4:", "M6", "after the program has cut (line 3)")


def test_h_that_is_not_the_tools_number_gets_a_warning():
    p = read_program("T1 M6\n" + HEAD + "G43 Z5 H2\nG1 X5\n", "p.nc")
    assert len(p.warnings) == 1 and p.warnings[0].startswith("p.nc:4: G43 H2 with T1")


def test_g28_with_an_absolute_intermediate_point_moves_there():
    p = read_program(HEAD + "G1 X5\nG28 G90 Z50.\nG1 X10\n", "p.nc")
    assert [(m.kind, m.end_mm) for m in p.moves] == [("line", (5.0, 0.0, 10.0)), ("rapid", (5.0, 0.0, 50.0)),
                                                     ("line", (10.0, 0.0, 50.0))]
    p = read_program(HEAD + "G1 X5\nG53 G0 Z0.\nG1 X10\n", "p.nc")  # G53: left out
    assert p.moves[-1].end_mm == (10.0, 0.0, 10.0)


def test_exact_stop_modes_and_program_stop():
    p = read_program(HEAD + "G61\nG1 X5\nY5\nG64\nX0\nG9 Y0\nX3\nM0\n", "p.nc")
    assert [m.stop_after for m in p.moves] == [True, True, False, True, True]


@pytest.mark.parametrize("line, col, words", [
    ("G4 P1.5", 4, ["P1.5", "whole ms"]),
    ("G4", 1, ["G4", "P (ms) or X (s)"]),
    ("G4 P100 X1", 1, ["G4", "P (ms) or X (s)"]),
    ("G4 P100 Y1", 1, ["G4", "a dwell with a move"]),
    ("G4 P9000000", 4, ["P9000000", "9000 s"]),
    ("P100", 1, ["P100", "with G4"]),
    ("H1", 1, ["H1", "without G43"]),
    ("Q1", 1, ["Q1", "G5.1"]),
    ("G55", 1, ["G55", "a second work offset (G54"]),
    ("O2", 1, ["O2", "a second program"]),
    ("S5", 1, ["S5", "rpm"]),
    ("G1 X20000", 4, ["X20000", "20000 mm"]),
    ("M98 P100", 1, ["M98", "subprogram"]),
    ("G5.1 Q1 X5", 1, ["G5.1"]),
])
def test_misused_words_are_refused(line, col, words):
    if line == "G5.1 Q1 X5":  # (G5.1 with Q is read; its axes are not a move of its own)
        read_program("G54\nO1\n" + HEAD + line + "\n" + "G1 X1\n", "p.nc")
        return
    refused("G54\nO1\n" + HEAD + line + "\n", f"p.nc:5:{col}:", *words)


def test_dwell_in_seconds_and_before_the_first_move():
    p = read_program("G4 X1.5\n" + HEAD + "G1 X5\nG4 X2\n", "p.nc")
    assert p.dwell_before_s == 1.5 and p.moves[-1].dwell_after_s == 2.0
    p = read_program(HEAD + "G1 X5\nG4 X2\n", "p.nc", decimal_point="increment")
    assert p.moves[-1].dwell_after_s == pytest.approx(0.002)


def test_block_delete_skips_or_runs_and_says_so():
    text = HEAD + "G1 X5\n/G1 Y5\n/1 G1 X0\n"
    p = read_program(text, "p.nc")
    assert len(p.moves) == 1 and p.warnings[0].startswith("p.nc:4: 2 block(s) skipped by block delete")
    assert len(read_program(text, "p.nc", block_delete="run").moves) == 3
    refused(HEAD + "G1 X5 /Y5\n", "p.nc:3:7:", "'/'")
    refused(HEAD + "/2 G1 X5\n", "p.nc:3:1:", "'/2'")


# ------------------------------------------------------------ arcs in the three planes


def test_a_vertical_lead_in_arc_in_the_zx_plane():
    # Fusion 360's lead-in: from above the cut down a quarter circle into a move along -X
    p = read_program("G0 X7.1884 Y0.159 Z0.15\nF100\nG18 G3 X6.9884 Z-0.05 I-0.2 K0.\n", "p.nc")
    a = p.moves[0]
    assert a.plane == "ZX" and a.center_mm == pytest.approx((0.15, 6.9884))  # (z, x)
    assert a.sweep_rad() == pytest.approx(math.pi / 2)  # counter-clockwise seen from +Y
    from robstiff_drake.model.program_path import program_elements

    (arc,), _ = program_elements(p.moves, 0.1, lambda q: [v / 1e3 for v in q])
    mid = arc.point(arc.length / 2) * 1e3
    assert math.hypot(mid[0] - 6.9884, mid[2] - 0.15) == pytest.approx(0.2, abs=1e-9)
    assert mid[0] > 6.9884 and mid[2] < 0.15  # the quarter below and beyond the centre
    np_end = arc.tangent(arc.length)
    assert np_end == pytest.approx([-1.0, 0.0, 0.0], abs=1e-9)  # leaves horizontally along -X


def test_arc_centre_words_must_belong_to_the_plane():
    refused(HEAD + "G2 X5 Y5 I5 K0\n", "p.nc:3:13:", "K0", "XY plane (G17)")
    refused(HEAD + "G19 G2 Y5 Z5 I5 K0\n", "p.nc:3:14:", "I5", "YZ plane (G19)")


def test_absolute_arc_centres():
    a = read_program(HEAD + "G90.1 G2 X10 Y0 I5 J0\n", "p.nc").moves[0]
    b = read_program(HEAD + "G2 X10 Y0 I5 J0\n", "p.nc").moves[0]
    assert a.center_mm == b.center_mm == (5.0, 0.0)
    c = read_program("G0 X10 Y0 Z10\nF100\nG90.1 G2 X20 Y0 I15 J0\n", "p.nc").moves[0]
    assert c.center_mm == (15.0, 0.0)


def test_a_program_without_units_is_read_in_mm_with_a_warning():
    """An inch program with no G20 would cut 25.4 x too small: the run says
    so (the scenario's warnings), not the reader's own list."""
    from types import SimpleNamespace

    from robstiff_drake.diagrams.toolpath import program_warnings

    bare = read_program(HEAD + "G1 X5\n", "p.nc")
    assert not bare.units_stated and bare.warnings == []
    (w,) = program_warnings(SimpleNamespace(_program=bare))
    assert w.startswith("p.nc: no G20 or G21 before the first move") and "25.4" in w
    for units in ("G21\n", "G20\n"):
        p = read_program(units + HEAD + "G1 X5\n", "p.nc")
        assert p.units_stated and program_warnings(SimpleNamespace(_program=p)) == []
    late = read_program(HEAD + "G1 X5\nG21\nG1 X6\n", "p.nc")  # stated only after the first move
    assert not late.units_stated
