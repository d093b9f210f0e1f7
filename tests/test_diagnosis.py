"""Residual diagnosis on campaigns with an effect nobody declared."""

import json

import numpy as np
import pytest

from robstiff_drake.commands.main import main
from robstiff_drake.identification import synth
from robstiff_drake.identification.diagnosis import CANDIDATES, diagnose

NOISE = 0.01


@pytest.mark.parametrize("effect", list(CANDIDATES))
def test_the_undeclared_effect_is_named_first(robot, effect):
    rng = np.random.default_rng(hash(effect) % 2**32)
    for case in range(3):  # random poses, loads, parameters, sizes and seeds
        size = float(rng.uniform(0.02, 0.06))
        c = synth.stiffness_campaign(robot, n=120, noise_mm=NOISE, seed=int(rng.integers(1 << 30)),
                                     effects={effect: size})
        d = diagnose(robot, c.to_campaign())
        assert d.selected and d.selected[0] == effect, (effect, size, d.selected)
        assert d.rms_after_mm <= 1.25 * NOISE, (effect, d.rms_after_mm)
        assert d.rms_before_mm > d.rms_after_mm


def test_a_campaign_without_effect_gets_none(robot):
    for seed in range(8):
        c = synth.stiffness_campaign(robot, n=120, noise_mm=NOISE, seed=500 + seed)
        d = diagnose(robot, c.to_campaign())
        assert d.selected == [], d.selected
        assert d.rms_after_mm == d.rms_before_mm <= 1.25 * NOISE


def test_drift_needs_the_order_column(robot):
    c = synth.stiffness_campaign(robot, n=120, seed=3, effects={"drift": 0.04})
    camp = c.to_campaign()
    camp.seq = None
    d = diagnose(robot, camp)
    drift = next(r for r in d.rounds[0] if r.name == "drift")
    assert drift.status == "skipped" and "seq" in drift.reason
    assert "drift" not in d.selected


def test_a_candidate_the_campaign_cannot_separate_is_never_selected(robot):
    # one pose: nothing varies with posture, so posture-dependent stiffness has no column
    with pytest.raises(ValueError, match="cannot show in this campaign"):
        synth.stiffness_campaign(robot, n=40, loads_per_pose=40, seed=4, effects={"posture_dependent_stiffness": 0.04})
    c = synth.stiffness_campaign(robot, n=40, loads_per_pose=40, seed=4)
    d = diagnose(robot, c.to_campaign())
    posture = next(r for r in d.rounds[0] if r.name == "posture_dependent_stiffness")
    assert posture.status == "not identifiable"
    assert "posture_dependent_stiffness" not in d.selected


def test_too_few_measurements_skip_candidates(robot):
    c = synth.stiffness_campaign(robot, n=9, loads_per_pose=3, seed=6)
    d = diagnose(robot, c.to_campaign())
    skipped = [r for r in d.rounds[0] if r.status == "skipped"]
    assert skipped and all("measurements" in r.reason for r in skipped)
    assert d.selected == []


def test_diagnose_cli_outputs(capsys, tmp_path, robot):
    data = tmp_path / "c.csv"
    assert main(["synth", "stiffness", str(data), "--effect", "force_bias=0.04", "--seed", "9"]) == 0
    capsys.readouterr()
    report, plots = tmp_path / "report.md", tmp_path / "plots"
    code = main(["diagnose", str(data), "--json", "-", "--report", str(report), "--plots", str(plots)])
    out, err = capsys.readouterr()
    assert code == 0, err
    res = json.loads(out)
    for key in ("rms_before_mm", "rms_after_mm", "selected_effects", "candidates", "joint_stiffness_Nm_per_rad"):
        assert key in res
    assert res["selected_effects"] == ["force_bias"]
    assert len(res["candidates"]) == len(CANDIDATES)
    bias = next(c for c in res["candidates"] if c["name"] == "force_bias")
    assert set(bias["params"]) == {"b_fx (N)", "b_fy (N)", "b_fz (N)"}
    assert bias["p_value"] < 1e-4 and bias["f_stat"] > 10
    assert res["rms_after_mm"] < 0.5 * res["rms_before_mm"]
    assert "# Residual diagnosis" in report.read_text()
    names = {p.name for p in plots.iterdir()}
    assert {"residual_vs_joint_torque.png", "residual_vs_load_magnitude.png", "residual_vs_joint_angles.png",
            "residual_vs_order.png"} <= names
    assert {f"candidate_{n}.png" for n in CANDIDATES} <= names


def test_diagnose_cli_bad_input(capsys, tmp_path):
    code = main(["diagnose", str(tmp_path / "none.csv")])
    _, err = capsys.readouterr()
    assert code == 2 and len(err.strip().splitlines()) == 1 and "cannot read" in err
