"""The instrument of studies/chip_direction.py: its force source differs
from the plant's in the chip's direction alone: with the plant's law
("path") it is the plant's (the program's direction where the tool is),
with a tool-motion law the force turns with the tool's motion (a tool
moving at 30 degrees to the program), and the compensator's linear law is
left as the plant has it."""

import sys
from pathlib import Path

import numpy as np
import pytest

from robstiff_drake.model.plant_cutting import PlantCuttingLaw, PlantCuttingPhysics

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "studies"))
sys.path.insert(0, str(ROOT / "tests"))

import chip_direction as cd  # noqa: E402
from test_plant_cutting import LINEAR, arm, at_an_angle, straight_path_source  # noqa: E402,F401


@pytest.mark.parametrize("law", ["path", "travel", "vector:2", "vtooth"])
def test_the_studys_source_turns_the_force_with_the_tool_only_under_a_tool_motion_law(arm, law):  # noqa: F811
    kin, tool, q0 = arm
    cut = PlantCuttingLaw(LINEAR)
    cd.ToolMotionChip.LAW, cd.ToolMotionChip.log = law, []
    src = straight_path_source(kin, tool, q0, cut, cls=cd.ToolMotionChip)
    w, tool_way, path_way = at_an_angle(kin, q0, src, cut, 30.0)
    assert np.linalg.norm(tool_way[:3] - path_way[:3]) > 0.2 * np.linalg.norm(path_way[:3])
    np.testing.assert_allclose(w[:3], path_way[:3] if law == "path" else tool_way[:3], rtol=0.03, atol=1.0)
    assert len(cd.ToolMotionChip.log) == 150  # (the plant's law: logged)


def test_the_compensators_linear_law_keeps_the_plants_direction(arm):  # noqa: F811
    kin, tool, q0 = arm
    cut = PlantCuttingLaw(LINEAR, PlantCuttingPhysics.linear())
    cd.ToolMotionChip.LAW, cd.ToolMotionChip.log = "vector:2", []
    w, _, path_way = at_an_angle(kin, q0, straight_path_source(kin, tool, q0, cut, cls=cd.ToolMotionChip), cut, 30.0)
    np.testing.assert_allclose(w[:3], path_way[:3], rtol=0.03, atol=1.0)
    assert cd.ToolMotionChip.log == []
