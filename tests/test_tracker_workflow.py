"""The laser-tracker workflow from an installed package: `robstiff synth
tracker` (Drake's plant of a perturbed arm, diagrams/tracker_world.py) makes
a campaign, `diagnose` reads it (its first line names the robot, the default
one said so; a unit warning only for a conversion) and `--write-robot`
keeps the machining tool point and stores the tracker's target under
payload.measured_point_mm."""

import json

import numpy as np

from robstiff_drake.commands.main import main
from robstiff_drake.model.robot import load_robot


def test_synth_tracker_then_diagnose(capsys, tmp_path):
    data = tmp_path / "tracker.csv"
    assert main(["synth", "tracker", str(data), "--n", "120", "--seed", "4", "--export"]) == 0
    capsys.readouterr()
    text = data.read_text()
    assert text.startswith("# Tracker campaign made by robstiff synth tracker") and "X [mm]" in text
    out = tmp_path / "corrected.yaml"
    assert main(["diagnose", str(data), "--write-robot", str(out), "--json", str(tmp_path / "d.json")]) == 0
    cap = capsys.readouterr()
    first = cap.out.splitlines()[0]
    assert "with the robot irb6400" in first and "the default: no --robot given" in first, first
    assert "converted to mm" not in cap.err  # the header says mm: nothing is converted
    rep = json.loads((tmp_path / "d.json").read_text())
    assert rep["robot"]["name"] == "irb6400" and rep["robot"]["default"] is True
    assert rep["error_3d_mm"]["after"]["rms"] < 0.2 * rep["error_3d_mm"]["before"]["rms"]
    # the machining tool point is the original's; the target has its own key
    nominal, new = load_robot(), load_robot(str(out))
    np.testing.assert_allclose(new.payload.tool_point_m, nominal.payload.tool_point_m, atol=0)
    np.testing.assert_allclose(new.payload.measured_point_m * 1e3, rep["tool_mm"], atol=1e-6)
    assert "measured_point_mm:" in out.read_text()
    # a second diagnosis with the corrected file starts from its measured point, and names the file
    assert main(["diagnose", str(data), "--robot", str(out)]) == 0
    first = capsys.readouterr().out.splitlines()[0]
    assert f"({out})" in first and "default" not in first, first


def test_another_robots_campaign_names_the_robot_used(capsys, tmp_path):
    """A KR 240 campaign diagnosed without --robot: the one line names the
    robot the limits are from and says to give --robot."""
    data = tmp_path / "kr.csv"
    assert main(["synth", "tracker", str(data), "--n", "60", "--seed", "3", "--robot", "kr240_r2900"]) == 0
    capsys.readouterr()
    assert main(["diagnose", str(data)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "of the robot irb6400" in err and "--robot" in err, err
