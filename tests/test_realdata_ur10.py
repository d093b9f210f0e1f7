"""A real laser-tracker data set no one here generated: a UR10 measured by
third parties in two series a year apart (tests/realdata.py; skipped, with
the reason, without the data), diagnosed with the robot file a user writes
from UR's published DH table."""

from pathlib import Path

import numpy as np
import pytest
import realdata

from robstiff_drake.identification.tracker.campaign import read_tracker_campaign
from robstiff_drake.identification.tracker.diagnosis import diagnose_tracker
from robstiff_drake.model.robot import load_robot

UR10 = Path(__file__).resolve().parent / "data" / "ur10_user.yaml"


@pytest.fixture(scope="module")
def series(tmp_path_factory):
    realdata.require(realdata.IPA_UR10)
    folder = tmp_path_factory.mktemp("ur10")
    return {s: realdata.ipa_ur10_campaign_csv(s, folder / f"ur10_{s}.csv") for s in ("A", "B")}


def test_the_ur10_series_held_out_error_and_its_periodic_joint_errors(series):
    """Series B (1,495 poses): the held-out mean 3D error from about 1 mm
    (the published DH table) to at most 0.15 mm, with the kinematic set and
    periodic errors of several joints named; the residual map never worse
    on a fold; the kinematics fitted on B carry over to series A, taken a
    year before at other poses with the tracker elsewhere."""
    robot = load_robot(str(UR10))
    other = read_tracker_campaign(str(series["A"]), robot)
    d = diagnose_tracker(robot, read_tracker_campaign(str(series["B"]), robot), validation=other)
    rep = d.report
    e = rep["error_3d_mm"]
    assert e["before"]["mean"] > 0.8, e
    assert e["after"]["mean"] <= 0.15, e
    assert {"joint_offsets", "link_lengths", "link_twists"} <= set(rep["selected_effects"])
    per = rep["periodic_errors"]
    assert len({p["joint"] for p in per}) >= 3, per
    for p in per:
        assert "an angle error periodic every" in p["text"] and p["amplitude_mrad"] > 0
        if p["period_ci95_deg"]:
            assert p["period_ci95_deg"][0] <= p["period_deg"] <= p["period_ci95_deg"][1]
    rm = rep["residual_map"]
    if rm["kept"]:
        assert all(f["with"] < f["without"] for f in rm["per_fold_mm"]), rm
    transfer = {t["what"]: t for t in rep["validation"]["transfer"]}
    assert transfer["kinematics"]["carries_over"], transfer
    assert transfer["registration"]["carries_over"] is False  # the tracker stood elsewhere a year later
    assert np.isfinite(rep["validation"]["error_3d_mm_reregistered"]["after"]["mean"])
