"""The FANUC R-2000iC campaign (real third-party data, ../shared/realdata):
`robstiff diagnose` traces it honestly.  Skipped, with the reason, when the
data are not there."""

import json
import re

import numpy as np
import pytest
import realdata

from robstiff_drake.commands.main import main

REASON = realdata.missing(realdata.FANUC)
pytestmark = pytest.mark.skipif(REASON is not None, reason=str(REASON))
NOISE_MM = "0.03"  # a tracker's noise per displacement component


@pytest.fixture(scope="module")
def fanuc(tmp_path_factory):
    return realdata.fanuc_campaign_csv(tmp_path_factory.mktemp("fanuc") / "fanuc.csv")


def _json(capsys, argv):
    code = main(argv + ["--json", "-"])
    out, err = capsys.readouterr()
    assert code == 0, err
    return json.loads(out), err


def test_the_six_springs_alone_are_physical(capsys, fanuc):
    res, _ = _json(capsys, ["identify", str(fanuc), "--robot", realdata.FANUC_ROBOT])
    assert res["non_physical_joints"] == []
    assert all(k > 0 for k in res["joint_stiffness_Nm_per_rad"])


def test_diagnosis_is_honest(capsys, fanuc):
    res, err = _json(capsys, ["diagnose", str(fanuc), "--robot", realdata.FANUC_ROBOT, "--noise-mm", NOISE_MM])
    # a physical final model, every kept term of physical size AT ITS ESTIMATE (an interval that merely reaches the
    # bound no longer keeps a term: the 234 mm measured point offset kept that way before is a lead)
    assert res["non_physical_joints"] == [] and all(k > 0 for k in res["joint_stiffness_Nm_per_rad"])
    assert all(t["plausible"] for t in res["terms"]), res["terms"]
    kept = [t["name"] for t in res["terms"]]
    assert "measured_point_offset" not in kept and "tool_offset" not in kept
    # does not explain at a tracker's noise, and never sends the user to look for a sign error
    assert res["explains_data"] is False and "does NOT explain" in res["verdict"]
    assert not any("signs" in m for m in [res["verdict"]] + res["warnings"]), res["warnings"]
    # no term survives the calibrated pose-clustered test (CR2, Bell-McCaffrey t; clustered_test.py): the two
    # joint-1 compliance variations the uncorrected test (CR1 + F(q, G - 1)) kept before (angle_compliance_j1_q2 and
    # _q4, 18 % held out; one parameter each, HTZ gives the same) reach p = 1.7e-4 at best against 0.01 / 91; the
    # six springs are the final model, and the row
    # they leave 1.2 mm off (file line 20, pose P17) is a gross outlier
    assert kept == [] and "no term of physical size was kept" in res["verdict"]
    assert res["rms_after_mm"] == res["rms_before_mm"]
    spread = res["fold_spread"]
    assert len(spread["seeds"]) >= 5 and spread["reduction_max"] == 0
    assert [o["line"] for o in res["outliers"]] == [20]
    # the tool offset beyond its typical size that fits is a lead, with its confounding said
    lead = {r["name"]: r for r in res["leads"]}
    assert "tool_offset" in lead and lead["tool_offset"]["plausible"] is False
    assert lead["tool_offset"]["forbidden"] is False and "residual above the noise floor" in lead["tool_offset"]["reason"]
    assert all(set(c) == {"terms", "correlation"} and abs(c["correlation"]) >= 0.8 for c in res["confounded"])
    assert any("tool_offset" in c["terms"] for c in res["confounded"]), res["confounded"]
    assert "not added" in res["verdict"] and "confounded" in res["verdict"]
    # and names the measurements that would separate the pair
    # (the verdict's lead is the best-fitting one: the measured point offset, confounded with the tool offset)
    assert re.search(r"plan-poses N --separate \w+,\w+", res["verdict"]) and "tool_offset" in res["verdict"], \
        res["verdict"]


def test_the_confounded_explanations_are_shown_side_by_side(capsys, fanuc):
    # a tool point 163 mm off, or the measured point 214 mm off the loaded point, would fit more of the residual,
    # but each trades off against joint 5's stiffness and none takes out most of what is above the floor: the
    # kept model and the alternatives side by side, with their held-out RMS and the plan that separates them;
    # none is picked
    res, _ = _json(capsys, ["diagnose", str(fanuc), "--robot", realdata.FANUC_ROBOT, "--noise-mm", NOISE_MM])
    assert all("prior_size" in t and t["beyond_typical"] is False and "finding" not in t for t in res["terms"])
    alts = res["alternatives"]
    assert alts[0]["kept"] is True and alts[0]["held_out_mm"] == res["rms_after_mm"]
    assert alts[0]["terms"] == [t["name"] for t in res["terms"]]
    by = {a["terms"][-1]: a for a in alts[1:]}
    assert all(a["kept"] is False and a["held_out_mm"] < res["rms_after_mm"] for a in alts[1:])
    tool = by["tool_offset"]
    assert tool["beyond_typical"] and "declared tool point" in tool["finding"]
    assert (tool["confounded_with"].startswith("stiffness_j") or tool["confounded_with"] == "measured_point_offset") \
        and abs(tool["correlation"]) >= 0.8
    assert f"--separate tool_offset,{tool['confounded_with']}" in tool["plan"]
    assert "measured_point_offset" in by
    kept = {t["name"] for t in res["terms"]}
    assert not kept & {"tool_offset", "measured_point_offset"}
    code = main(["diagnose", str(fanuc), "--robot", realdata.FANUC_ROBOT, "--noise-mm", NOISE_MM])
    out, _ = capsys.readouterr()
    assert code == 0 and "cannot decide between (none is picked" in out and "plan-poses 24 --separate tool_offset," \
        in out


def test_the_answer_does_not_depend_on_how_the_poses_are_labelled(capsys, fanuc, tmp_path):
    # P01..P43 written P1..P43 (they sort otherwise as text): the same folds, the same answer
    relabelled = tmp_path / "fanuc_p1.csv"
    relabelled.write_text(re.sub(r"^P0(\d),", r"P\1,", fanuc.read_text(), flags=re.M))
    assert relabelled.read_text() != fanuc.read_text()
    argv = ["diagnose", "--robot", realdata.FANUC_ROBOT, "--noise-mm", NOISE_MM]
    a, _ = _json(capsys, argv[:1] + [str(fanuc)] + argv[1:])
    b, _ = _json(capsys, argv[:1] + [str(relabelled)] + argv[1:])
    assert (a["rms_before_mm"], a["rms_after_mm"]) == (b["rms_before_mm"], b["rms_after_mm"])
    assert [t["name"] for t in a["terms"]] == [t["name"] for t in b["terms"]]


def test_plan_separates_the_confounded_pair(capsys, fanuc, tmp_path):
    res, _ = _json(capsys, ["diagnose", str(fanuc), "--robot", realdata.FANUC_ROBOT, "--noise-mm", NOISE_MM])
    a, b = next(c["terms"] for c in res["confounded"] if "tool_offset" in c["terms"])
    plan, _ = _json(capsys, ["plan-poses", "24", "--robot", realdata.FANUC_ROBOT, "--separate", f"{a},{b}",
                             "--campaign", str(fanuc), "--noise-mm", NOISE_MM, "--out", str(tmp_path / "p.csv")])
    assert abs(plan["correlation_after"]) < abs(plan["correlation_before"])
    widths = np.array([[p["half_width_95_before"], p["half_width_95_after"]] for p in plan["parameters"]])
    assert np.all(widths[:, 1] < widths[:, 0])
    assert len(plan["rows"]) == 24 and (tmp_path / "p.csv").read_text().count("\n") > 24
