"""A unit written as another (lbf or kgf in the N columns, inches in the mm
columns) scales every identified stiffness alike and leaves the fit as it
was: `identify` and `diagnose` now warn when every identified joint is off
the robot file's by about a unit's factor (identification/stiffness/
unit_scale.py), with the measurement that decides.  Planted in campaigns
this code did not make: Drake's plant (tests/setup_errors.py) and the real
FANUC R-2000iC campaign (skipped with the reason when absent), whose joints
lie 0.63-2.72x of its robot file's: as written, no warning."""

import json
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parent))
import realdata  # noqa: E402
import setup_errors as se  # noqa: E402

from robstiff_drake.identification.stiffness.joint_stiffness import identify  # noqa: E402
from robstiff_drake.identification.stiffness.unit_scale import KGF_N, LBF_N, unit_scale_note  # noqa: E402
from robstiff_drake.model.robot import load_robot  # noqa: E402

K0 = np.array([1.5e6, 1.1e6, 8e5, 3e5, 3e5, 2e5])
ALL = np.ones(6, dtype=bool)


def _note(ratios, identifiable=ALL):
    return unit_scale_note(K0 * np.asarray(ratios), K0, identifiable, "c.csv", "r.yaml")


def test_the_rule():
    assert _note([1.0, 1.02, 0.98, 1.1, 0.9, 1.0]) is None  # as written
    assert _note([0.63, 2.72, 2.69, 1.09, 1.71, 1.25]) is None  # a file 1.5x off on average, both ways
    assert "lbf written as N" in _note(np.full(6, 1 / LBF_N))
    assert "kgf (or daN) written as N" in _note(np.full(6, 1 / KGF_N))
    assert "inches written as mm" in _note(np.full(6, 25.4))
    assert _note([0.2, 0.2, 0.2, 0.2, 0.2, 1.5]) is None  # one joint the other way: not a common scale
    assert _note(np.full(6, 0.6)) is None  # softer, but by no unit's factor
    assert _note(np.full(6, 1 / LBF_N), identifiable=[True, True, False, False, False, False]) is None  # 2 joints
    # the joints kept at the file's value (not identifiable) do not count
    assert "lbf" in _note([1 / LBF_N] * 5 + [1.0], identifiable=[True] * 5 + [False])


def _fit_note(robot, campaign, tool_m):
    fit = identify(robot, campaign, tool_m=tool_m)
    return unit_scale_note(fit.stiffness_Nm_per_rad, robot.joint_stiffness_Nm_per_rad, fit.identifiable,
                           campaign.path, robot.source)


@pytest.fixture(scope="module")
def drake_campaign():
    c = se.make_campaign("none", 11)
    return load_robot(), c.campaign, np.asarray(c.declared_tool_m, dtype=float)


@pytest.mark.parametrize("kind", ["tool_point", "untared", "soft_forearm"])
def test_drakes_plant_other_mistakes_are_no_unit(kind):
    c = se.make_campaign(kind, 11)
    assert _fit_note(load_robot(), c.campaign, np.asarray(c.declared_tool_m, dtype=float)) is None


def test_drakes_plant_units_written_as_others(drake_campaign):
    robot, c, tool = drake_campaign
    assert _fit_note(robot, c, tool) is None
    assert "lbf written as N" in _fit_note(robot, replace(c, force_N=c.force_N / LBF_N), tool)
    assert "kgf (or daN)" in _fit_note(robot, replace(c, force_N=c.force_N / KGF_N), tool)
    assert "inches written as mm" in _fit_note(robot, replace(c, disp_mm=c.disp_mm / 25.4), tool)


@pytest.fixture(scope="module")
def fanuc(tmp_path_factory):
    realdata.require(realdata.FANUC)
    robot, campaign, tool_m, path = realdata.fanuc_campaign(tmp_path_factory.mktemp("fanuc") / "fanuc.csv")
    return path, robot, campaign, tool_m


def test_the_real_fanuc_campaign_as_written_is_no_unit_and_lbf_is_named(fanuc):
    _, robot, c, tool = fanuc
    assert _fit_note(robot, c, tool) is None
    lbf = _fit_note(robot, replace(c, force_N=c.force_N / LBF_N), tool)
    assert lbf is not None and "lbf written as N" in lbf and "known weight" in lbf
    assert "inches written as mm" in _fit_note(robot, replace(c, disp_mm=c.disp_mm / 25.4), tool)


def test_identify_warns_in_the_text_and_the_json(fanuc, tmp_path, capsys):
    from robstiff_drake.commands.main import main

    path, robot, _, _ = fanuc
    lines = Path(path).read_text().splitlines()
    head = next(i for i, line in enumerate(lines) if line.startswith("pose,") or line.startswith("q1"))
    cols = lines[head].split(",")
    fcols = [cols.index(f) for f in ("fx", "fy", "fz")]
    out_lines = lines[: head + 1]
    for line in lines[head + 1:]:
        v = line.split(",")
        for k in fcols:
            v[k] = f"{float(v[k]) / LBF_N:.6f}"
        out_lines.append(",".join(v))
    lbf = tmp_path / "lbf.csv"
    lbf.write_text("\n".join(out_lines) + "\n")
    js = tmp_path / "id.json"
    assert main(["identify", str(lbf), "--robot", str(realdata.FANUC_ROBOT), "--json", str(js)]) == 0
    err = capsys.readouterr().err
    assert "possibly forces in lbf written as N" in err
    assert any("lbf written as N" in w for w in json.loads(js.read_text())["warnings"])
