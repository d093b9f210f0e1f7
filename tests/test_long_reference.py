"""A long joint reference (`compensate --reference`): read in one pass in
memory linear in its rows with a small constant (counted with
tracemalloc, not timed), its bad cells named by file, line and column
wherever they are, and the reference's envelope and interpolation the
same as a plain loop over its rows computes them."""

import tracemalloc

import numpy as np
import pytest

from robstiff_drake.cell import reference_file
from robstiff_drake.cell.loop_guard import feed_direction
from robstiff_drake.cell.reference import Reference
from robstiff_drake.cell.safety import FOLLOW_S, check_reference, motion_within
from robstiff_drake.commands.compensate import read_reference
from robstiff_drake.errors import InputError
from robstiff_drake.model.robot import load_robot

HEADER = "t_s," + ",".join(f"q{j}_deg" for j in range(1, 7))


@pytest.fixture(scope="module")
def robot():
    return load_robot()


def _q0(robot):
    return 0.5 * (np.degrees(robot.q_lower_rad) + np.degrees(robot.q_upper_rad))


def _write(path, robot, rows, period_s=0.004, edit=None):
    """A slow path of ``rows`` rows around the middle of the working ranges;
    ``edit(lines)`` changes the data lines (a list of str) before writing."""
    t = np.arange(rows) * period_s
    q = _q0(robot) + 2.0 * np.sin(2 * np.pi * t[:, None] / 30.0 + np.arange(6))
    lines = [f"{a:.4f}," + ",".join(f"{v:.6f}" for v in b) for a, b in zip(t, q)]
    if edit:
        edit(lines)
    path.write_text("# a test reference\n" + HEADER + "\n" + "\n".join(lines) + "\n")
    return t, q


def _peak_bytes(fn):
    tracemalloc.start()
    try:
        fn()
        return tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


def test_reading_a_long_reference_holds_memory_linear_in_its_rows(tmp_path, robot):
    """Reading and preparing the reference (what compensate holds before
    its loop) at 30,000 and 120,000 rows: the peak of Python's and numpy's
    allocations grows about 4x, and stays under 500 bytes a row (the
    arrays the loop needs are 152 bytes a row; reading the file whole as
    text and Python lists held about 1 kB a row here and 3 kB of the
    process's resident memory)."""
    peaks = {}
    for n in (30000, 120000):
        path = tmp_path / f"ref{n}.csv"
        _write(path, robot, n)

        def prepare():  # as compensate does before its loop
            t, q = read_reference(path, robot)
            ref = Reference(t, np.degrees(q, out=q))
            feed_direction(robot, robot.payload.tool_point_m, ref.q,
                           to_model=lambda q: robot.joint_map.to_model(np.radians(q)))
            return ref

        peaks[n] = _peak_bytes(prepare)
    per_row = peaks[120000] / 120000
    print(f"peak {peaks[30000] / 1e6:.1f} MB at 30,000 rows, {peaks[120000] / 1e6:.1f} MB at 120,000 "
          f"({per_row:.0f} bytes a row)")
    assert per_row < 500, per_row
    assert peaks[120000] / peaks[30000] < 5.0


def test_the_values_are_the_files(tmp_path, robot):
    t, q = _write(tmp_path / "r.csv", robot, 130000)
    t_read, q_read = read_reference(tmp_path / "r.csv", robot)
    assert np.allclose(t_read, t, atol=1e-9) and np.allclose(np.degrees(q_read), q, atol=1e-6)


def _edit_line(k, text):
    def edit(lines):
        lines[k] = text(lines[k])
    return edit


@pytest.mark.parametrize("k", [3, 99000])  # in the first block of lines and far past it
@pytest.mark.parametrize("text, words", [
    (lambda s: ",".join([s.split(",")[0], "abc"] + s.split(",")[2:]), "column 2 (q1_deg): 'abc' is not a number"),
    (lambda s: ",".join(s.split(",")[:3] + ["nan"] + s.split(",")[4:]),
     "column 4 (q3_deg): 'nan' is not a finite number"),
    (lambda s: s + ",7", "8 fields, the header has 7"),
    (lambda s: ",".join(s.split(",")[:6] + ["1,5"]), "8 fields, the header has 7"),
], ids=["text", "nan", "extra-field", "decimal-comma"])
def test_a_bad_cell_is_named_by_line_and_column(tmp_path, robot, k, text, words):
    path = tmp_path / "r.csv"
    _write(path, robot, 100000, edit=_edit_line(k, text))
    with pytest.raises(InputError) as e:
        reference_file.read_reference_rows(path)
    assert str(e.value).startswith(f"{path}:{k + 3}") and words in str(e.value), str(e.value)


def test_comments_and_blank_lines_inside_keep_the_line_numbers(tmp_path, robot):
    """Lines numbered as in the file past comments and blank lines in the
    middle of a long file: a speed error beyond them names its line."""
    def edit(lines):
        lines[70000] = "# a comment in the middle\n\n" + lines[70000]
        v = [float(x) for x in lines[90000].split(",")]
        v[2] += 30.0  # a step no axis makes in 4 ms
        lines[90000] = ",".join(repr(x) for x in v)
    path = tmp_path / "r.csv"
    _write(path, robot, 100000, edit=edit)
    t, q, numbers = reference_file.read_reference_rows(path)
    assert len(t) == 100000 and numbers[0] == 3 and numbers[69999] == 70002 and numbers[70000] == 70005
    with pytest.raises(InputError) as e:
        read_reference(path, robot)
    assert str(e.value).startswith(f"{path}:90005: q2 moves at"), str(e.value)


def test_a_byte_that_is_not_utf8_is_named_by_line(tmp_path, robot):
    path = tmp_path / "r.csv"
    _write(path, robot, 80000)
    data = bytearray(path.read_bytes())
    at = data.index(b"\n", len(data) * 3 // 4) + 3
    data[at] = 0xFF
    path.write_bytes(bytes(data))
    line = data[:at].count(b"\n") + 1
    with pytest.raises(InputError) as e:
        reference_file.read_reference_rows(path)
    assert str(e.value) == f"{path}:{line}, column 3: not UTF-8 text"


def test_a_duplicated_column_is_refused(tmp_path, robot):
    path = tmp_path / "r.csv"
    path.write_text("t_s,q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg,q1_deg\n0,1,2,3,4,5,6,7\n")
    with pytest.raises(InputError, match=r"r.csv:1: duplicated column 'q1_deg' \(columns 2 and 8\)"):
        reference_file.read_reference_rows(path)


def _motion_loop(t, q, window_s):
    """The envelope by a plain loop over the rows (the definition)."""
    out = np.zeros_like(q)
    for i in range(len(t)):
        lo = 0
        while t[i] - t[lo] > window_s + 1e-12:
            lo += 1
        seg = q[max(lo - 1, 0): i + 1]
        out[i] = seg.max(axis=0) - seg.min(axis=0)
    return out


def test_the_envelope_is_the_loops_at_irregular_times():
    rng = np.random.default_rng(7)
    for n in (1, 2, 5, 700):
        t = np.round(np.cumsum(rng.choice([0.004, 0.004, 0.008, 0.012, 0.1, 0.3], n)) - 0.004, 4)
        q = rng.normal(size=(n, 6)).cumsum(axis=0)
        for window_s in (0.004, 0.004 + FOLLOW_S, 0.5):
            assert np.array_equal(motion_within(t, q, window_s), _motion_loop(t, q, window_s)), (n, window_s)


def test_the_reference_at_any_time_is_the_interpolation_and_the_envelope():
    """``Reference.at`` forward, backward and past both ends against
    np.interp and the plain loop's envelope of the two rows around."""
    rng = np.random.default_rng(3)
    n = 400
    t = np.round(np.cumsum(rng.choice([0.004, 0.008, 0.02], n)) - 0.004, 4)
    q = rng.normal(size=(n, 6)).cumsum(axis=0)
    ref = Reference(t, q)
    m1, mf = _motion_loop(t, q, 0.004), _motion_loop(t, q, 0.004 + FOLLOW_S)
    times = np.r_[-1.0, np.sort(rng.uniform(-0.1, t[-1] + 0.1, 300)), t[::7], rng.uniform(0, t[-1], 100), 1e9]
    for ts in times:
        got_q, got_m1, got_mf = ref.at(float(ts))
        assert np.allclose(got_q, [np.interp(ts, t, q[:, j]) for j in range(6)], atol=1e-12)
        i = max(0, min(int(np.searchsorted(t, ts, side="right")) - 1, n - 1))
        j = min(i + 1, n - 1)
        assert got_m1 == np.maximum(m1[i], m1[j]).tolist() and got_mf == np.maximum(mf[i], mf[j]).tolist()


@pytest.mark.parametrize("block", [7, 1 << 16])
def test_the_checks_in_blocks_find_the_first_bad_row(robot, block, monkeypatch):
    """check_reference's tests run over blocks of rows: the first bad row
    is found across a block's edge (blocks of 7 rows) as in one block."""
    from robstiff_drake.cell import safety

    monkeypatch.setattr(safety, "CHECK_BLOCK", block)
    t = np.arange(60) * 0.004
    q = np.tile(_q0(robot), (60, 1))
    for bad_row, edit, words in [(14, lambda q: q.__setitem__((14, 1), q[14, 1] + 5.0), "q2 moves at"),
                                 (20, lambda q: q.__setitem__((slice(21, None), 0), q[21:, 0] + 0.02),
                                  "q1 accelerates at"),
                                 (28, lambda q: q.__setitem__((28, 2), 1e4), "q3 = 10000 deg is outside")]:
        qq = q.copy()
        edit(qq)
        with pytest.raises(InputError) as e:
            check_reference("ref.csv", robot, t, qq, 0.004, rows=np.arange(60) + 3)
        assert str(e.value).startswith(f"ref.csv:{bad_row + 3}: {words}"), str(e.value)
