"""A file written wrongly is a setup mistake, not a physical effect: one force
axis with the wrong sign, a joint's column in radians, two joint columns
interchanged.  The diagnosis tries the file read each other way
(identification/diagnosis/misreadings.py) and names the reading the six
springs fit far better, with the check to make; a clean file is accused of
nothing.  Before, these were blamed on lost motion, crosstalk or a trend, or
left without a verdict ("check the signs and units of the displacements
and forces" for an angle written in radians).  On a Drake-made campaign
(tests/setup_errors.py, always) and on the real FANUC campaign (skipped,
with the reason, without ../shared/realdata)."""

from dataclasses import replace

import numpy as np
import pytest
import realdata
import setup_errors as se

from robstiff_drake.commands.main import main
from robstiff_drake.errors import InputError
from robstiff_drake.identification.diagnosis.campaign_diagnosis import diagnose
from robstiff_drake.identification.stiffness.joint_stiffness import identify
from robstiff_drake.model.robot import load_robot


def _flip_force(c, k):
    f = c.force_N.copy()
    f[:, k] *= -1
    return replace(c, force_N=f)


def _radians(c, j):
    q = c.q_deg.copy()
    q[:, j - 1] = np.deg2rad(q[:, j - 1])
    return replace(c, q_deg=q)


def _swap(c, a, b):
    q = c.q_deg.copy()
    q[:, [a - 1, b - 1]] = q[:, [b - 1, a - 1]]
    return replace(c, q_deg=q)


PLANTS = [("force_sign_y", lambda c: _flip_force(c, 1)), ("radians_q5", lambda c: _radians(c, 5)),
          ("swap_q2q3", lambda c: _swap(c, 2, 3))]


@pytest.fixture(scope="module")
def drake_made():
    c = se.make_campaign("none", 11)  # Drake's plant, no setup mistake, 0.01 mm noise
    return c.campaign, c.declared_tool_m


@pytest.fixture(scope="module")
def robot():
    return load_robot()


def test_a_clean_campaign_is_not_read_another_way(robot, drake_made):
    campaign, tool = drake_made
    d = diagnose(robot, campaign, tool_m=tool, noise_mm=se.NOISE_MM)
    assert d.misreadings == [] and "read another way" not in d.verdict
    assert d.explains_data is True


@pytest.mark.parametrize("name, plant", PLANTS, ids=[p[0] for p in PLANTS])
def test_a_misread_column_is_named_as_the_setup_mistake(robot, drake_made, name, plant):
    campaign, tool = drake_made
    d = diagnose(robot, plant(campaign), tool_m=tool, noise_mm=se.NOISE_MM)
    assert d.misreadings and d.misreadings[0]["name"] == name, [r["name"] for r in d.misreadings]
    best = d.misreadings[0]
    assert best["decisive"]
    assert best["held_out_mm"] <= 0.9 * best["as_written_mm"] and min(best["fold_gains"]) > 0
    assert d.verdict.startswith("setup finding (the file read another way)") and best["check"] in d.verdict
    assert d.explains_data is not True


def test_forces_in_kN_are_named_with_the_displacement_units(robot, drake_made):
    # the ratio of displacement to force cannot tell dx in micrometres from forces in kN: both are named (before,
    # only the displacements were, and the user was sent to check the wrong column)
    campaign, tool = drake_made
    with pytest.raises(InputError, match=r"fx,fy,fz are .*x too small \(forces in kN written as N give 1000x\)"):
        identify(robot, replace(campaign, force_N=campaign.force_N * 1e-3), tool_m=tool)


# -- the real FANUC campaign -------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def fanuc(tmp_path_factory):
    realdata.require(realdata.FANUC)
    return realdata.fanuc_campaign(tmp_path_factory.mktemp("fanuc") / "fanuc.csv")[:3]


def test_the_real_campaign_is_not_read_another_way(fanuc):
    r, campaign, tool = fanuc
    d = diagnose(r, campaign, tool_m=tool, noise_mm=0.03)
    assert d.misreadings == [], d.misreadings


@pytest.mark.parametrize("name, plant", PLANTS + [("radians_q2", lambda c: _radians(c, 2))],
                         ids=[p[0] for p in PLANTS] + ["radians_q2"])
def test_the_real_campaign_misread_is_named(fanuc, name, plant):
    # on the real campaign the six springs leave 0.24 mm held out (8x a tracker's noise): the mistake is named
    # although much else is unexplained (before: lost_motion kept for q5 in radians; nothing for the others)
    r, campaign, tool = fanuc
    d = diagnose(r, plant(campaign), tool_m=tool, noise_mm=0.03)
    assert d.misreadings and d.misreadings[0]["name"] == name, [x["name"] for x in d.misreadings]
    assert "read another way" in d.verdict and d.explains_data is not True
    # decisive, every fold.  q2/q3 interchanged was named only as possible under the uncorrected clustered test
    # (CR1 + F(q, G - 1)): the file as written then kept angle_compliance_j1_q2, whose fit left the reading better
    # by 24 % held out but not on every fold of 43 poses; under the calibrated test (clustered_test.py; HTZ too)
    # the file as written keeps nothing and the reading wins on every fold
    assert d.misreadings[0]["decisive"] is True, d.misreadings[0]


def test_the_cli_prints_the_reading(capsys, tmp_path, drake_made):
    campaign, tool = drake_made
    bad = _flip_force(campaign, 1)
    path = tmp_path / "flipped.csv"
    head = "# tool_mm: " + ", ".join(f"{v * 1e3:g}" for v in tool)
    rows = [",".join(f"{v:.10g}" for v in np.concatenate([q, f, d]))
            for q, f, d in zip(bad.q_deg, bad.force_N, bad.disp_mm)]
    path.write_text("\n".join([head, "q1,q2,q3,q4,q5,q6,fx,fy,fz,dx,dy,dz"] + rows) + "\n")
    assert main(["diagnose", str(path), "--noise-mm", str(se.NOISE_MM)]) == 0
    out, _ = capsys.readouterr()
    assert "the file read another way (setup findings; check these first):" in out
    assert "force_sign_y: the file fits far better read with fy with the wrong sign" in out
