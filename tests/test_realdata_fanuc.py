"""The FANUC R-2000iC campaign (real third-party data, ../shared/realdata):
`robstiff diagnose` traces it honestly.  Skipped, with the reason, when the
data are not there."""

import json

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
    # a physical final model, every kept term of physical size
    assert res["non_physical_joints"] == [] and all(k > 0 for k in res["joint_stiffness_Nm_per_rad"])
    assert all(t["plausible"] for t in res["terms"]), res["terms"]
    # does not explain at a tracker's noise, and never sends the user to look for a sign error
    assert res["explains_data"] is False and "does NOT explain" in res["verdict"]
    assert not any("sign" in m for m in [res["verdict"]] + res["warnings"]), res["warnings"]
    # plausible terms lower the held-out RMS by 20 % or more
    assert res["rms_after_mm"] <= 0.8 * res["rms_before_mm"], (res["rms_before_mm"], res["rms_after_mm"])
    # the implausible tool offset that fits is a lead, with its confounding said
    lead = {r["name"]: r for r in res["leads"]}
    assert "tool_offset" in lead and lead["tool_offset"]["plausible"] is False
    assert all(set(c) == {"terms", "correlation"} and abs(c["correlation"]) >= 0.8 for c in res["confounded"])
    assert any("tool_offset" in c["terms"] for c in res["confounded"]), res["confounded"]
    assert "not added" in res["verdict"] and "confounded" in res["verdict"]


def test_plan_separates_the_confounded_pair(capsys, fanuc, tmp_path):
    res, _ = _json(capsys, ["diagnose", str(fanuc), "--robot", realdata.FANUC_ROBOT, "--noise-mm", NOISE_MM])
    a, b = next(c["terms"] for c in res["confounded"] if "tool_offset" in c["terms"])
    plan, _ = _json(capsys, ["plan-poses", "24", "--robot", realdata.FANUC_ROBOT, "--separate", f"{a},{b}",
                             "--campaign", str(fanuc), "--noise-mm", NOISE_MM, "--out", str(tmp_path / "p.csv")])
    assert abs(plan["correlation_after"]) < abs(plan["correlation_before"])
    widths = np.array([[p["half_width_95_before"], p["half_width_95_after"]] for p in plan["parameters"]])
    assert np.all(widths[:, 1] < widths[:, 0])
    assert len(plan["rows"]) == 24 and (tmp_path / "p.csv").read_text().count("\n") > 24
