"""Setup mistakes of a tracker campaign planted in the declaration, not in
the measurements (identification/tracker/setup_terms.py): the payload's
mass in the robot file and the vertical the model takes (the instrument's
frame turned), and the payload's centre of mass.  On a campaign of Drake's IRB 6400 (40 kg payload, a sag of
1-2 mm) they are named with their size; on the real UR10 series B
(tests/realdata.py; skipped with the reason when absent) the clean series
is not accused and a 10 kg mistake is named, with the compliance scale
beside it (this light arm's data do not separate the two)."""

from dataclasses import replace

import numpy as np
import pytest
import realdata
import tracker_world as tw

from robstiff_drake.identification.tracker.campaign import read_tracker_campaign
from robstiff_drake.identification.tracker.diagnosis import diagnose_tracker
from robstiff_drake.model.robot import load_robot

NOISE = 0.03


def _turned(campaign, deg):
    a = np.deg2rad(deg)
    R = np.array([[1.0, 0.0, 0.0], [0.0, np.cos(a), -np.sin(a)], [0.0, np.sin(a), np.cos(a)]])
    return replace(campaign, pos=campaign.pos @ R.T)


def _declared(robot, mass_kg):
    return replace(robot, payload=replace(robot.payload, mass_kg=mass_kg))


def _findings(robot, campaign):
    rep = diagnose_tracker(robot, campaign, noise_mm=NOISE, residual_map=False).report
    return rep, {f["name"]: f for f in rep["setup_findings"]}


@pytest.fixture(scope="module")
def irb6400(tmp_path_factory):
    robot = load_robot("irb6400")
    path = tmp_path_factory.mktemp("setup") / "irb6400.csv"
    path.write_text(tw.make_tracker_campaign(robot, 21, n=600, noise_mm=NOISE).csv_text)
    return robot, read_tracker_campaign(str(path), robot)


def test_a_clean_campaign_has_no_setup_finding(irb6400):
    rep, found = _findings(*irb6400)
    assert found == {}, found
    assert not {"payload_mass", "payload_com", "gravity_tilt"} & set(rep["selected_effects"])


@pytest.mark.parametrize("mass_kg", [0.0, 20.0])
def test_a_payload_declared_wrong_is_named_with_its_mass(irb6400, mass_kg):
    robot, campaign = irb6400  # the arm carries the file's 40 kg; the user declares another mass
    rep, found = _findings(_declared(robot, mass_kg), campaign)
    f = found["payload_mass"]
    total = mass_kg + f["estimate"]["dm (kg)"]
    assert abs(total - 40.0) < 3.0, f
    assert f["text"].startswith("SETUP FINDING: the payload acting on the arm is about") and f["beyond_typical"]
    assert f"declares {mass_kg:.3g} kg" in f["text"]
    assert f["separated"], f["alternatives"]
    assert rep["rms_after_mm"] < 1.1 * NOISE  # the held-out RMS back at the noise


def test_a_payload_centre_of_mass_declared_wrong_is_named(irb6400):
    robot, campaign = irb6400  # the arm's 40 kg act at (0, 0, 180) mm; the user declares 30 mm (the bare spindle's)
    rb = replace(robot, payload=replace(robot.payload, com_m=np.array([0.0, 0.0, 0.030])))
    rep, found = _findings(rb, campaign)
    assert "payload_mass" not in found, found  # the mass is right: not accused
    f = found["payload_com"]
    assert abs(30.0 + f["estimate"]["dz (mm)"] - 180.0) < 10.0, f
    assert np.hypot(f["estimate"]["dx (mm)"], f["estimate"]["dy (mm)"]) < 10.0, f
    assert f["text"].startswith("SETUP FINDING: the payload's centre of mass is about") and f["beyond_typical"]
    assert f["separated"] and any(a["model"].startswith("payload_mass in its place") for a in f["alternatives"])
    assert rep["rms_after_mm"] < 1.1 * NOISE


def test_a_vertical_one_degree_off_is_named(irb6400):
    robot, campaign = irb6400
    rep, found = _findings(robot, _turned(campaign, 1.0))
    f = found["gravity_tilt"]
    size = np.hypot(f["estimate"]["tilt_x (deg)"], f["estimate"]["tilt_y (deg)"])
    assert 0.8 < size < 1.2, f
    assert f["text"].startswith("SETUP FINDING: the arm's base stands about")
    assert rep["rms_after_mm"] < 1.1 * NOISE


@pytest.fixture(scope="module")
def ur10_b(tmp_path_factory):
    realdata.require(realdata.IPA_UR10)
    robot = load_robot(str(realdata.Path(__file__).resolve().parent / "data" / "ur10_user.yaml"))
    path = realdata.ipa_ur10_campaign_csv("B", tmp_path_factory.mktemp("ur10") / "ur10_B.csv")
    return robot, read_tracker_campaign(str(path), robot)


def test_the_real_ur10_is_not_accused_and_a_ten_kg_mistake_is_named(ur10_b):
    robot, campaign = ur10_b
    _, clean = _findings(robot, campaign)
    assert clean == {}, clean
    _, tilted = _findings(robot, _turned(campaign, 1.0))  # below what this light arm's sag shows: not named
    assert tilted == {}, tilted
    _, found = _findings(_declared(robot, robot.payload.mass_kg + 10.0), campaign)
    f = found["payload_mass"]
    total = robot.payload.mass_kg + 10.0 + f["estimate"]["dm (kg)"]
    assert 0.0 <= total < 4.0, f  # the probe and its adapter (the file's 1.2 kg), not 11.2 kg
    assert "SETUP FINDING" in f["text"]
    assert len(f["alternatives"]) == 3 and all(a["heldout_rms_mm"] > 0 for a in f["alternatives"])
    if not f["separated"]:
        assert "with and without a known extra weight" in f["text"]
