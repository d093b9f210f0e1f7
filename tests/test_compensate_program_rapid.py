"""The project's own RAPID reader (model/rapid_reader.py, used to run a
written module back through the simulation): what the writer wrote comes
back, and what the reader does not take is refused with the line."""

import numpy as np
import pytest

from robstiff_drake.model import rapid_reader as rr
from robstiff_drake.model import rapid_writer as rw


def _module():
    R = np.array([[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]])  # the tool down
    tilt = np.array([[np.cos(1e-3), 0.0, np.sin(1e-3)], [0.0, 1.0, 0.0], [-np.sin(1e-3), 0.0, np.cos(1e-3)]])
    q0, q1 = rw.quaternion(R), rw.quaternion(R @ tilt)
    targets = [rw.Target("line", np.array([0.0, 40.0, 10.0]), q0, (0, 0, 0, 0), 100.0, True, 4),
               rw.Target("line", np.array([40.0, 40.0, -3.0]), q1, (0, 0, 0, 0), 20.0, False, 6),
               rw.Target("arc", np.array([60.0, 60.0, -3.0]), q1, (0, 0, 0, 0), 20.0, False, 7,
                         np.array([54.1421, 45.8579, -3.0]), q0, (0, 0, 0, 0))]
    text = rw.module_text("short_compensated", targets, tool_mm=[0.0, 0.0, 350.0], payload_mass_kg=40.0,
                          payload_com_mm=[0.0, 0.0, 180.0], wobj_mm=[1600.0, -40.0, 700.0],
                          wobj_quat=rw.quaternion(np.eye(3)), zone_mm=5.0, header_lines=["a test"])
    return text, targets, (R, R @ tilt)


def test_the_reader_reads_back_what_the_writer_wrote():
    text, targets, (R0, R1) = _module()
    moves = rr.read_moves(text)
    assert [m.instruction for m in moves] == ["MoveL", "MoveL", "MoveC"]
    assert np.allclose(moves[1].targets[0][0], targets[1].pos_mm, atol=1e-4)
    assert np.allclose(moves[2].targets[0][0], targets[2].via_mm, atol=1e-4)  # the circle point first
    assert np.allclose(moves[2].targets[1][0], targets[2].pos_mm, atol=1e-4)
    assert np.allclose(rr.rotation(moves[0].targets[0][1]), R0, atol=1e-7)
    assert np.allclose(rr.rotation(moves[1].targets[0][1]), R1, atol=1e-7)  # the 1 mrad tilt survives
    assert moves[1].speed != moves[0].speed


def test_a_motion_it_does_not_take_names_the_line():
    text, _, _ = _module()
    lines = text.splitlines()
    k = next(i for i, ln in enumerate(lines) if ln.strip().startswith("MoveC"))
    lines[k] = lines[k].replace("MoveC [[", "MoveC [[1,", 1)
    with pytest.raises(rr.RapidReadError, match=f"line {k + 1}:"):
        rr.read_moves("\n".join(lines))
