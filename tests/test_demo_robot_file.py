"""demo --robot ROBOT.yaml runs the block test at the robot file's
machining_workspace.reference_tool_point_mm ("the block test's", in
docs/your_robot.md), as the library's block_milling_NAME.yaml are placed.
Before, a newcomer's copy of the FANUC file ran the IRB6400's block at
(1600, 0, 700) mm, not the FANUC's (1750, 0, 470): another cut than
`demo --robot r2000ic_165f` (+0.140 against +0.236 mm uncompensated, the
tool point aside)."""

from pathlib import Path

import numpy as np
import yaml

from robstiff_drake.commands.demo import BLOCK, moved_block
from robstiff_drake.model.robot import load_robot

ROOT = Path(__file__).resolve().parents[1]


def _positions(path):
    d = yaml.safe_load(Path(path).read_text())
    return d["workpiece"]["boxes_mm"], d["path"]["waypoints_mm"], d["scan"]["lines_y_mm"]


def _copy(name, tmp_path, edit=lambda s: s):
    text = (ROOT / "models" / f"{name}.yaml").read_text().replace(f"name: {name}", "name: my_copy")
    path = tmp_path / "my_copy.yaml"
    path.write_text(edit(text))
    return load_robot(str(path))


def test_a_copy_of_the_fanuc_file_gets_the_fanucs_block_test(tmp_path):
    robot = _copy("r2000ic_165f", tmp_path)
    path, shift = moved_block(robot, tmp_path)
    assert path != BLOCK and np.allclose(shift, [150.0, 0.0, -230.0])
    got = _positions(path)
    want = _positions(ROOT / "diagrams" / "block_milling_r2000ic_165f.yaml")
    for g, w in zip(got, want):
        np.testing.assert_allclose(np.array(g, dtype=float), np.array(w, dtype=float), atol=1e-9)


def test_the_irb6400s_point_keeps_the_block_as_it_is(tmp_path):
    path, shift = moved_block(_copy("irb6400", tmp_path), tmp_path)
    assert path == BLOCK and not np.any(shift)


def test_a_point_off_the_axis_moves_the_scan_line_too(tmp_path):
    robot = _copy("irb6400", tmp_path, lambda s: s.replace("reference_tool_point_mm: [1600.0, 0.0, 700.0]",
                                                           "reference_tool_point_mm: [1650.0, 100.0, 650.0]"))
    path, shift = moved_block(robot, tmp_path)
    boxes, ends, lines = _positions(path)
    assert np.allclose(shift, [50.0, 100.0, -50.0])
    assert boxes == [[1575.0, 1725.0, 90.0, 140.0, 653.0]] and lines == [115.0]
    assert np.allclose(np.mean(ends, axis=0), [1650.0, 100.0, 650.0])
