"""G-code programs and corner blending:
the reader's subset and its one-line errors, the corner path's geometry
(tangent, curvature-continuous for lines, inside the zone), the speed
profile (kept along a blend, smooth, no step), the unchanged straight path,
the scenario's toolpath section and the scan along the path."""

import math
import os
import re
import subprocess
import sys

import numpy as np
import pytest
from doc_blocks import blocks

from robstiff_drake.diagrams.scenario import load_scenario, planned_path
from robstiff_drake.errors import InputError
from robstiff_drake.model.gcode.program import read_program
from robstiff_drake.model.path import PlannedPath
from robstiff_drake.model.path_elements import Corner
from robstiff_drake.model.program_path import program_elements

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

# A post's output in the style of Fanuc-type CAM posts: tape marks, program
# number, N numbers, comments in both forms, modal coordinates, trailing dots.
POST = """%
O1234 (TEST; PROGRAM)
N10 G21 G17 G90 G40 G49 G80 G94
N20 G54
N30 S2400 M3
N40 G0 X0. Y0. Z10.
N50 Z2.
N60 G1 Z-1. F300.
N70 X20. ; modal G1 from here
N80 Y10.
N90 G3 X10. Y20. I-10. J0.
N100 G2 X0. Y30. R10.
N110 G91 G1 X-5.
N120 G90 G20 G1 X0. Y1.5 F10.
N130 M5
N140 M30
%
"""


def test_reads_a_post_output():
    p = read_program(POST, "post.nc")
    kinds = [m.kind for m in p.moves]
    assert kinds == ["rapid", "line", "line", "line", "arc", "arc", "line", "line"]
    assert p.start_mm == (0.0, 0.0, 10.0)  # the first point where X, Y and Z are set
    assert p.moves[1].feed_mm_per_min == 300.0 and p.moves[1].spindle_rpm == 2400.0
    assert p.moves[2].end_mm == (20.0, 0.0, -1.0)  # modal G1
    a = p.moves[4]  # G3 from (20, 10) about (10, 10) to (10, 20): a quarter counter-clockwise
    assert a.center_mm == (10.0, 10.0) and not a.clockwise
    assert a.sweep_rad() == pytest.approx(math.pi / 2)
    b = p.moves[5]  # G2 R10 from (10, 20) to (0, 30), clockwise, at most 180 degrees: about (10, 30)
    assert b.center_mm == pytest.approx((10.0, 30.0)) and b.sweep_rad() == pytest.approx(-math.pi / 2)
    assert p.moves[6].end_mm == (-5.0, 30.0, -1.0)  # G91
    last = p.moves[7]  # inches: X0 Y1.5 in -> (0, 38.1) mm (Z not programmed: stays); F10 in/min = 254 mm/min
    assert last.end_mm == pytest.approx((0.0, 38.1, -1.0)) and last.feed_mm_per_min == pytest.approx(254.0)


@pytest.mark.parametrize("line, col, words", [
    ("G1 X1\nT2 M6", 4, ["M6", "after the program has cut (line 3)", "one tool"]),
    ("G81 X1 Y1 Z-2 R1", 1, ["G81", "canned cycles"]),
    ("G41 D1 X1", 1, ["G41", "cutter radius compensation"]),
    ("G1 X1 A30", 7, ["A30", "5-axis"]),
    ("G1 X1 B30", 7, ["B30", "5-axis"]),
    ("G18 G2 X1 Z1 I1 J1", 17, ["J1", "ZX plane (G18)"]),
    ("G2 X1 Y1 I0 J3", 1, ["G2", "not on the arc"]),
    ("G2 X1 Y1", 1, ["G2", "I/J", "R"]),
    ("G1 X1 (unclosed", 7, ["'('", "')'"]),
    ("G1 X1 Q", 7, ["Q without a number"]),
    ("G44 H1 Z5", 1, ["G44", "tool length"]),
    ("M4", 1, ["M4", "counter-clockwise"]),
    ("G1 X1 M32", 7, ["M32", "unsupported M-code"]),
    ("G12 X1", 1, ["G12", "unsupported G-code"]),
])
def test_unsupported_words_name_the_file_line_column_and_word(line, col, words):
    prog = "G0 X0 Y0 Z0\nF100\n" + line + "\n"
    n = 3 + line.count("\n")
    with pytest.raises(InputError) as e:
        read_program(prog, "p.nc")
    msg = str(e.value)
    assert msg.startswith(f"p.nc:{n}:{col}: ") and "\n" not in msg, msg
    for w in words:
        assert w in msg, msg


def test_feed_move_without_f_is_refused():
    with pytest.raises(InputError, match=r"p.nc:2:1: G1 without a feed"):
        read_program("G0 X0 Y0 Z0\nG1 X5\n", "p.nc")


def test_r_arc_matches_ij_arc():
    a = read_program("G0 X0 Y0 Z0\nG3 X-10 Y10 R10 F100\n").moves[0]
    b = read_program("G0 X0 Y0 Z0\nG3 X-10 Y10 I-10 J0 F100\n").moves[0]
    assert a.center_mm == pytest.approx(b.center_mm)
    big = read_program("G0 X0 Y0 Z0\nG3 X-10 Y10 R-10 F100\n").moves[0]  # the longer arc
    assert big.sweep_rad() == pytest.approx(1.5 * math.pi)
    full = read_program("G0 X10 Y0 Z0\nG2 X10 Y0 I-10 J0 F100\n").moves[0]
    assert full.sweep_rad() == pytest.approx(-2 * math.pi)


# ------------------------------------------------------------ corners


L_WP = np.array([[0.0, 0.0, 0.7], [0.2, 0.0, 0.7], [0.2, 0.2, 0.7]])


def finite_differences(path, dt=0.002):
    ts = np.arange(0.0, path.duration_s, dt)
    p = path.positions(ts)
    v = np.gradient(p, dt, axis=0)
    a = np.gradient(v, dt, axis=0)
    return ts, p, v, a


def test_corner_is_rounded_inside_its_zone_at_the_programmed_speed():
    zone = 0.01
    path = PlannedPath(L_WP, 0.02, dwell_s=0.2, ramp_s=0.5, zone_m=zone)
    assert [type(e).__name__ for e in path.elements] == ["Line", "Corner", "Line"]
    c = path.elements[1]
    # the corner path joins the lines where they are `zone` from the corner, tangent to both
    np.testing.assert_allclose(c.point(0.0), [0.19, 0.0, 0.7], atol=1e-12)
    np.testing.assert_allclose(c.point(c.length), [0.2, 0.01, 0.7], atol=1e-12)
    np.testing.assert_allclose(c.tangent(0.0), [1, 0, 0], atol=1e-9)
    np.testing.assert_allclose(c.tangent(c.length), [0, 1, 0], atol=1e-9)
    # its closest approach to the corner: a quarter of the way to the chord's middle
    s = np.linspace(0, c.length, 2001)
    d = np.linalg.norm(np.array([c.point(x) for x in s]) - [0.2, 0.0, 0.7], axis=1).min()
    assert d == pytest.approx(0.25 * zone * math.sqrt(2) / 2, rel=2e-3)  # (chord middle: zone / sqrt(2) away)
    # speed kept through the corner (within the arc-length table's 0.2 %)
    ts, p, v, a = finite_differences(path)
    speed = np.linalg.norm(v, axis=1)
    in_corner = np.array([path._element(path.arc_length(t)) == 1 for t in ts])
    assert np.all(np.abs(speed[in_corner] - 0.02) < 0.002 * 0.02 + 1e-9)


def test_blended_corner_has_no_acceleration_step():
    sharp = PlannedPath(L_WP, 0.02, dwell_s=0.2, ramp_s=0.5, zone_m=0.0)
    blended = PlannedPath(L_WP, 0.02, dwell_s=0.2, ramp_s=0.5, zone_m=0.01)
    _, _, _, a0 = finite_differences(sharp)
    _, _, _, a1 = finite_differences(blended)
    # the sharp corner turns the velocity in one step: an acceleration spike of v / dt
    assert np.linalg.norm(a0, axis=1).max() > 3.0
    # the blend: v^2 / r with r a few mm (the Bezier's tightest radius is about r / 4)
    assert np.linalg.norm(a1, axis=1).max() < 0.2


def test_corner_curvature_is_zero_where_it_joins_lines():
    c = Corner([0, 0, 0], [1, 0, 0], [1, 0, 0], [1, 1, 0])
    for s0, sgn in ((0.0, 1), (c.length, -1)):
        h = 1e-4 * sgn
        t0, t1 = c.tangent(s0), c.tangent(s0 + h)
        assert np.linalg.norm(t1 - t0) / abs(h) < 0.05  # curvature (1/m) ~ 0 at the ends
    mid = c.length / 2
    k_mid = np.linalg.norm(c.tangent(mid + 1e-4) - c.tangent(mid - 1e-4)) / 2e-4
    assert k_mid > 1.0


def test_zone_is_reduced_to_half_the_shorter_move():
    wp = np.array([[0.0, 0.0, 0.7], [0.004, 0.0, 0.7], [0.004, 0.1, 0.7]])
    path = PlannedPath(wp, 0.02, zone_m=0.05)
    c = path.elements[1]
    np.testing.assert_allclose(c.point(0.0), [0.002, 0.0, 0.7], atol=1e-12)
    np.testing.assert_allclose(c.point(c.length), [0.004, 0.002, 0.7], atol=1e-12)


def test_reversal_stops_the_path():
    wp = np.array([[0.0, 0.0, 0.7], [0.1, 0.0, 0.7], [0.0, 0.0, 0.7]])
    path = PlannedPath(wp, 0.02, ramp_s=0.5, zone_m=0.01)
    s_turn = 0.1
    t = np.linspace(0, path.duration_s, 20001)
    s = np.array([path.arc_length(x) for x in t])
    i = np.argmin(np.abs(s - s_turn))
    assert path.speed(t[i]) < 1e-3  # at rest where it turns back


def test_straight_path_is_unchanged_by_the_rewrite():
    # the constant feed between two cosine ramps, as the project always planned it
    wp = np.array([[1.4825, 0, 0.7], [1.7175, 0, 0.7]])
    path = PlannedPath(wp, 0.02, 0.0, 0.2, 0.5, zone_m=0.005)
    assert path.duration_s == pytest.approx(0.2 + 0.235 / 0.02 + 0.5)
    for tau in (0.1, 0.25, 0.4):
        expected = 0.5 * 0.02 * (tau - 0.5 / math.pi * math.sin(math.pi * tau / 0.5))
        assert path.arc_length(0.2 + tau) == pytest.approx(expected, rel=1e-12)
    assert path.arc_length(0.2 + 5.0) == pytest.approx(0.5 * 0.02 * 0.5 + 0.02 * 4.5, rel=1e-12)


def test_speed_changes_are_smooth_ramps_in_the_faster_move():
    from robstiff_drake.model.path_elements import Line

    els = [Line([0, 0, 0.7], [0.1, 0, 0.7]), Line([0.1, 0, 0.7], [0.3, 0, 0.7]), Line([0.3, 0, 0.7], [0.4, 0, 0.7])]
    path = PlannedPath.from_elements(els, [0.01, 0.04, 0.01], ramp_s=0.5)
    t = np.linspace(0, path.duration_s, 40001)
    v = np.array([path.speed(x) for x in t])
    s = np.array([path.arc_length(x) for x in t])
    assert np.abs(np.diff(v)).max() < 0.04 * math.pi / 2 / 0.5 * (t[1] - t[0]) * 1.01  # no step: bounded acceleration
    # the slow moves keep their feed: the speed-up starts and the slow-down ends on the boundaries
    assert v[(s > 0.01) & (s < 0.1 - 1e-6)].max() <= 0.01 + 1e-12
    assert v[(s > 0.3 + 1e-6) & (s < 0.39)].max() <= 0.01 + 1e-12
    assert v.max() == pytest.approx(0.04, rel=1e-9)


def test_program_arc_elements_follow_the_circle():
    prog = read_program("G0 X0 Y0 Z0\nG1 X10 F600\nG3 X10 Y20 I0 J10\nG1 X0\n")

    def transform(p):
        return (np.array([1600.0, 0.0, 700.0]) + np.asarray(p)) / 1e3

    els, speeds = program_elements(prog.moves, 0.1, transform)
    arc = els[1]
    for s in np.linspace(0, arc.length, 11):
        p = arc.point(s)
        assert math.hypot(p[0] - 1.61, p[1] - 0.01) == pytest.approx(0.01, abs=1e-12)
    assert speeds == [0.01, 0.01, 0.01]


# ------------------------------------------------------------ scenarios


def test_example_scenario_reads_its_program():
    sc = load_scenario(os.path.join(ROOT, "diagrams", "contour_with_arcs.yaml"))
    assert sc.path.feed_mm_per_s == pytest.approx(20.0) and sc.cutter.spindle_rpm == 3600.0
    path = planned_path(sc)
    # program zero at the work offset: the first cut starts at X-140 Y-20 Z0 -> (1460, -20, 700) mm
    p = path.point_at(0.0)
    np.testing.assert_allclose(p * 1e3, [1460.0, -20.0, 720.0], atol=1e-9)  # (the start: Z20 above)


def test_toolpath_option_replaces_the_waypoints(tmp_path):
    prog = tmp_path / "bad.nc"
    prog.write_text("G0 X0 Y0 Z5\nG1 Z0 F1200\nT2 M6\n")
    cp = subprocess.run([sys.executable, "-m", "robstiff_drake", "simulate",
                         os.path.join(ROOT, "diagrams", "block_milling.yaml"), "--toolpath", str(prog), "--out",
                         str(tmp_path / "out")], capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert cp.returncode == 2
    assert cp.stderr.strip() == f"robstiff: error: {prog}:3:4: M6: a tool change after the program has cut (line 2): " \
                                "a second tool; one program, one tool"


def test_scan_follows_a_path_along_y(tmp_path):
    """A pass along +y: the scan runs along the path (arc length, x, y), not across it along x."""
    from robstiff_drake.diagrams.experiment import run_cut
    from robstiff_drake.model.robot import load_robot

    text = open(os.path.join(ROOT, "diagrams", "block_milling.yaml")).read()
    text = text.replace("    - [1525.0, 1675.0, -10.0, 40.0, 703.0]", "    - [1585.0, 1635.0, -75.0, 75.0, 703.0]")
    text = text.replace("    - [1482.5, 0.0, 700.0]\n    - [1717.5, 0.0, 700.0]",
                        "    - [1600.0, -117.5, 700.0]\n    - [1600.0, 117.5, 700.0]")
    text = text.replace("  lines_y_mm: [15.0]", "  along: auto")
    f = tmp_path / "y_pass.yaml"
    f.write_text(text)
    sc = load_scenario(f)
    res = run_cut(sc, load_robot(), compensation=False)
    line = res.scans[0]
    assert line.s_m is not None
    face = np.isfinite(line.error_m)
    assert np.ptp(line.y_at[face]) > 0.1  # the machined face along y (150 mm less margins)
    assert np.ptp(line.x_m[face]) < 1e-9
    assert res.surface_error_mm["rms"] > 0.05  # the arm deflects under the cut
    assert {"entry_max_abs", "exit_max_abs", "steady_mean", "steady_max_abs"} <= set(res.surface_error_mm)


# ------------------------------------------------------------ posted programs on the cell


FACE = os.path.join(ROOT, "diagrams", "face_contour_fanuc.yaml")


def scenario_with_program(tmp_path, program_text, scenario=FACE, **replace):
    """A copy of ``scenario`` in tmp_path that runs ``program_text`` (its text's lines replaced as ``replace``)."""
    prog = tmp_path / "prog.nc"
    prog.write_text(program_text)
    text = open(scenario).read()
    text = text.replace("program: face_contour_fanuc.nc", f"program: {prog}")
    for old, new in replace.items():
        assert old in text, old
        text = text.replace(old, new)
    f = tmp_path / "scenario.yaml"
    f.write_text(text)
    return f, prog


def test_posted_examples_run_unchanged_and_make_the_same_path():
    from robstiff_drake.diagrams.toolpath import program_warnings

    fusion = load_scenario(FACE)
    mastercam = load_scenario(FACE, toolpath=os.path.join(ROOT, "diagrams", "face_contour_mastercam.nc"))
    for sc in (fusion, mastercam):
        assert sc.path.feed_mm_per_s == pytest.approx(20.0) and sc.cutter.spindle_rpm == 3600.0
        assert sc._program.tool_diameter_mm == 75.0 and sc._program.warnings == []
        assert [w.split(";")[0] for w in program_warnings(sc)] == [
            "toolpath.program: 2 cutting feeds (F300, F1200 mm/min)"]
    a, b = planned_path(fusion), planned_path(mastercam)
    assert a.duration_s == pytest.approx(b.duration_s, abs=1e-9)
    ts = np.linspace(0.0, a.duration_s, 200)
    np.testing.assert_allclose(a.positions(ts), b.positions(ts), atol=1e-9)
    # the program's zero on the plate's top: the plunge at the plate's corner goes to z = 703 - 2 mm
    assert min(p[2] for p in a.positions(ts)) * 1e3 == pytest.approx(701.0)


def test_the_tool_comment_is_checked_against_the_cutter(tmp_path):
    text = open(os.path.join(ROOT, "diagrams", "face_contour_fanuc.nc")).read().replace("D=75.", "D=50.")
    f, prog = scenario_with_program(tmp_path, text)
    with pytest.raises(InputError) as e:
        load_scenario(f)
    msg = str(e.value)
    assert msg.startswith(f"{f}:") and "cutter.diameter_mm: 75 mm, but the program's tool (T1, " in msg
    assert f"{prog}:8) is 50 mm" in msg


PLATE_PROGRAM = """%
(T1 D=75. CR=0. - ZMIN=-2. - FACE MILL)
G90 G94 G17 G49 G40 G80
G21
T1 M6
S3600 M3
G54
G0 X-110. Y-40.
G43 Z15. H1
G0 Z5.
G1 Z-2. F300.
X60. F1200.
{extra}
G0 Z15.
M30
%
"""


def test_a_rapid_into_uncut_stock_is_refused_through_cut_stock_it_is_not(tmp_path):
    # back along the faced strip at the cut's depth: the material is gone
    f, _ = scenario_with_program(tmp_path, PLATE_PROGRAM.format(extra="G0 X-60."))
    load_scenario(f)
    # across the uncut half of the plate at the cut's depth: a crash
    f, prog = scenario_with_program(tmp_path, PLATE_PROGRAM.format(extra="G0 Y40."))
    with pytest.raises(InputError) as e:
        load_scenario(f)
    msg = str(e.value)
    assert msg.startswith(f"{prog}:13: a rapid move (G0) to (60, 40, -2) runs the 75 mm cutter 2 mm below the top "
                          "of workpiece box 1 where no earlier cut has removed the material"), msg
    # a feed into uncut stock with the spindle stopped
    f, prog = scenario_with_program(tmp_path, PLATE_PROGRAM.format(extra="M5\nG1 Y40."))
    with pytest.raises(InputError, match=rf"^{prog}:14: a feed move with the spindle stopped \(M5 or S0\)"):
        load_scenario(f)
    # ... a rapid down into the plate before any cut
    f, prog = scenario_with_program(tmp_path, PLATE_PROGRAM.format(extra="").replace("G0 Z5.", "G0 X0. Z-1."))
    with pytest.raises(InputError, match=rf"^{prog}:10: a rapid move \(G0\) to \(0, -40, -1\)"):
        load_scenario(f)


def test_a_program_that_misses_the_workpiece_gets_one_line_with_both_extents(tmp_path):
    f, prog = scenario_with_program(tmp_path, PLATE_PROGRAM.format(extra=""),
                                    **{"work_offset_mm: [1600.0, 0.0, 703.0]": "work_offset_mm: [0.0, 0.0, 0.0]"})
    with pytest.raises(InputError) as e:
        load_scenario(f)
    msg = str(e.value)
    assert "\n" not in msg and "air cut" not in msg
    assert msg.startswith(f"{prog}: the program's cuts span X -110..60, Y -40..-40, Z -2..5 mm (its frame)"), msg
    assert "the workpiece spans X 1540..1660, Y -40..40 mm, top at Z 703 mm" in msg
    offset = msg.split("--work-offset ")[-1].split(" ")[0]
    assert offset == "1625,40,703"  # the middle of the cuts over the plate's middle, Z0 on its top
    sc = load_scenario(f, work_offset=offset)  # placed: it loads
    assert sc.toolpath.work_offset_mm == [1625.0, 40.0, 703.0]
    sc = load_scenario(f, work_offset="1600,0,703,0")
    assert sc.toolpath.work_offset_mm == [1600.0, 0.0, 703.0] and sc.toolpath.work_rotation_deg == 0.0


@pytest.mark.parametrize("text, what", [("1600,0", "expected X,Y,Z"), ("1600,0,x", "component 3 'x' is not a number"),
                                        ("1600,0,20000", "component 3 '20000' is outside the allowed range "
                                                         "[-10000, 10000] mm"),
                                        ("1600,0,703,400", "component 4 '400' is outside the allowed range "
                                                           "[-360, 360] deg"),
                                        ("1600,0,nan", "component 3 'nan' is outside")])
def test_work_offset_option_is_checked(text, what):
    with pytest.raises(InputError, match="^" + re.escape(f"--work-offset: {what}")):
        load_scenario(FACE, work_offset=text)


def test_a_program_out_of_reach_names_the_first_line_that_leaves_it(tmp_path):
    from robstiff_drake.diagrams.milling_cell import planned_path as cell_path
    from robstiff_drake.model.robot import load_robot

    extra = "G1 X60. Y-40. Z60.\nG1 X2500. Y-40. Z60.\nG1 X60. Y-40. Z60."  # 2.5 m along +x: out of reach
    f, prog = scenario_with_program(tmp_path, PLATE_PROGRAM.format(extra=extra))
    sc = load_scenario(f)
    robot = load_robot(None)
    with pytest.raises(InputError) as e:
        cell_path(sc, robot, robot.tool_point(where="the test"))
    msg = str(e.value)
    assert msg.startswith(f"{prog}:14: path point at t = ") and "(robot " in msg, msg


def test_a_dwell_rests_on_the_path_and_g61_stops_at_every_corner(tmp_path):
    base, _ = scenario_with_program(tmp_path, PLATE_PROGRAM.format(extra="G1 Y-30."))
    p0 = planned_path(load_scenario(base))
    d = tmp_path / "dwell"
    d.mkdir()
    f, _ = scenario_with_program(d, PLATE_PROGRAM.format(extra="G4 P2000\nG1 Y-30."))
    p1 = planned_path(load_scenario(f))
    assert p1.duration_s > p0.duration_s + 2.0
    ts = np.arange(0.0, p1.duration_s, 0.01)
    v = np.array([p1.speed(t) for t in ts])
    rest = ts[v == 0.0]
    at_corner = rest[np.linalg.norm(p1.positions(rest) * 1e3 - [1660.0, -40.0, 701.0], axis=1) < 1e-9]
    assert at_corner.max() - at_corner.min() == pytest.approx(2.0, abs=0.011)  # two seconds at the corner
    # zones: a corner path at the face pass's end in G64, none (and a stop) in G61
    assert any(type(e).__name__ == "Corner" for e in p0.elements)
    g = tmp_path / "g61"
    g.mkdir()
    f, _ = scenario_with_program(g, PLATE_PROGRAM.format(extra="G1 Y-30.").replace("G54", "G54 G61"))
    p2 = planned_path(load_scenario(f))
    assert not any(type(e).__name__ == "Corner" for e in p2.elements)
    t_corner = ts[np.argmin(np.linalg.norm(p2.positions(ts) * 1e3 - [1660.0, -40.0, 701.0], axis=1))]
    assert p2.speed(t_corner) < 1e-3


def test_the_documented_example_runs_as_written(tmp_path):
    """docs/toolpaths.md: its my_program.nc on the block, without the work
    offset: the one line the page shows.  With it the page's first block runs
    it (the same command; its run folder's summary is checked there:
    tests/test_wheel_install.py's _check_my_program_on_the_block)."""
    doc = open(os.path.join(ROOT, "docs", "toolpaths.md"), encoding="utf-8").read()
    program = re.search(r"<!-- example-file: my_program.nc -->\n```\n(.*?)```", doc, flags=re.S).group(1)
    console = re.search(r"```console\n(.*?)```", doc, flags=re.S).group(1).splitlines()
    (tmp_path / "my_program.nc").write_text(program)
    os.symlink(os.path.join(ROOT, "diagrams"), tmp_path / "diagrams")
    commands = [line[2:] for line in console if line.startswith("$ ")]
    assert len(commands) == 2 and "--work-offset" not in commands[0] and "--work-offset" in commands[1]
    expected_error = console[console.index("$ " + commands[0]) + 1]

    def run(command):
        argv = command.split()
        assert argv[0] == "robstiff"
        return subprocess.run([sys.executable, "-m", "robstiff_drake"] + argv[1:], capture_output=True, text=True,
                              cwd=tmp_path, timeout=600)

    cp = run(commands[0])
    assert cp.returncode == 2 and cp.stderr.strip() == expected_error, cp.stderr
    assert open(tmp_path / "my_program.nc").read() == program  # the input is untouched
    # the second command is the last of the page's first block, which the wheel test runs as written
    first = blocks("toolpaths.md")[0]
    assert first.marker == "" and first.commands()[-1] == commands[1], (first.where, commands[1])


@pytest.mark.parametrize("program, line, words", [
    # a rapid plunge written in a G43 line while G0 is modal, the position already known
    (PLATE_PROGRAM.format(extra="").replace("G0 X-110. Y-40.\nG43 Z15. H1\nG0 Z5.",
                                            "N50 G0 X-60. Y-40. Z15.\nN55 G43 Z-2. H1"), 9, "a rapid move (G0) to "
                                                                                         "(-60, -40, -2)"),
    # the same with Z unknown until the G43 line: the start point itself is in the plate's corner
    (PLATE_PROGRAM.format(extra="").replace("G0 X-110. Y-40.\nG43 Z15. H1\nG0 Z5.",
                                            "N50 G0 X-60. Y-40.\nN55 G43 Z-2. H1"), 9, "the program starts at "
                                                                                     "(-60, -40, -2)"),
    # a program whose first move starts 2 mm inside uncut stock
    (PLATE_PROGRAM.format(extra="").replace("G0 X-110. Y-40.\nG43 Z15. H1\nG0 Z5.\nG1 Z-2. F300.",
                                            "G0 X0 Y0 Z-2.\nG1 Y-40. F300."), 8, "the program starts at (0, 0, -2)"),
], ids=["g43-rapid", "g43-start", "start-in-stock"])
def test_every_rapid_and_the_start_point_are_checked_against_the_stock(tmp_path, program, line, words):
    f, prog = scenario_with_program(tmp_path, program)
    with pytest.raises(InputError) as e:
        load_scenario(f)
    msg = str(e.value)
    assert msg.startswith(f"{prog}:{line}: {words}") and "a crash on a machine" in msg and "\n" not in msg, msg
