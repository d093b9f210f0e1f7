"""Residual diagnosis on campaigns with an effect nobody declared."""

import json

import numpy as np
import pytest

from robstiff_drake.commands.main import main
from robstiff_drake.identification.stiffness import synth
from robstiff_drake.identification.diagnosis.campaign_diagnosis import CANDIDATES, diagnose
from robstiff_drake.identification.stiffness.joint_stiffness import identify
from physical_effects import visible_campaign

NOISE = 0.01


@pytest.mark.parametrize("index, effect", list(enumerate(CANDIDATES)))
def test_a_physical_effect_is_named_first_and_added(robot, index, effect):
    # a fixed seed per effect (its index in the library): the same cases every run.  Each effect in its physical
    # pattern, sized to 2-6x the noise beyond the springs at 700 N but never beyond the top of its physical range
    # (tests/physical_effects.py): the CCT term, the forearm's compliance and a TCP error stay below the noise there
    rng = np.random.default_rng([20261123, index])
    for case in range(3):
        c = visible_campaign(robot, effect, rng, float(rng.uniform(0.02, 0.06)), seed=int(rng.integers(1 << 30)),
                             force_N=700.0, noise_mm=NOISE)
        d = diagnose(robot, c.to_campaign(), noise_mm=NOISE)
        assert all(k > 0 for k in d.joint_stiffness_Nm_per_rad), d.verdict  # the final model stays physical
        assert all(t["plausible"] for t in d.terms), d.terms  # and plausible
        assert effect not in [r["name"] for r in d.leads], d.leads  # a physical size is never a lead
        if c.effect_rms_mm[effect][1] >= 2 * NOISE:  # visible: named first, added, and it explains the data
            assert d.selected[:1] == [effect] and d.discovered == [], (effect, d.selected, d.discovered)
            assert d.rms_after_mm <= 1.25 * NOISE < d.rms_before_mm, (effect, d.rms_after_mm)
            assert d.explains_data is True, (effect, d.verdict)
        else:  # below the noise at its physical size: nothing else is named in its place
            assert d.selected in ([], [effect]) and d.explains_data is True, (effect, d.selected, d.verdict)


def test_a_parallel_rod_coupling_is_added_even_where_the_six_springs_are_not_physical(robot):
    # axis 3 driven by a rod from the turret: c23 = -c2, 0.85 of sqrt(c2 c3) with the file's stiffness (physical,
    # within identification/diagnosis/plausibility.py's bound); with six independent springs joint 2's compliance can come out
    # negative, and the coupling is what makes the fit physical: it is added and the verdict is given
    c2 = 1.0 / robot.joint_stiffness_Nm_per_rad[1]
    c = synth.stiffness_campaign(robot, n=120, noise_mm=NOISE, seed=115,
                                 effect_params={"joint_coupling": {"c23_rad_per_Nm": -c2}})
    camp = c.to_campaign()
    assert 2 in identify(robot, camp).non_physical  # the six springs alone: joint 2 negative
    d = diagnose(robot, camp, noise_mm=NOISE)
    assert d.selected == ["joint_coupling"] and d.non_physical == [] and d.explains_data is True, d.verdict
    assert all(k > 0 for k in d.joint_stiffness_Nm_per_rad)
    assert d.final_params["joint_coupling"]["c23 (rad/(N*m))"] == pytest.approx(-c2, rel=0.1)


def test_a_campaign_without_effect_gets_none(robot):
    for seed in range(8):
        c = synth.stiffness_campaign(robot, n=120, noise_mm=NOISE, seed=500 + seed)
        d = diagnose(robot, c.to_campaign(), noise_mm=NOISE)
        assert d.selected == [] and d.discovered == [], (d.selected, d.discovered)
        assert d.rms_after_mm == d.rms_before_mm <= 1.25 * NOISE
        assert d.explains_data is True, d.verdict
        assert d.outliers == []


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
    # skipped for the parameters the 9 rows cannot carry, or for what the term needs (seq, different load sizes)
    assert skipped and any("measurements" in r.reason for r in skipped)
    assert all(any(w in r.reason for w in ("measurements", "measurement times", "load", "seq")) for r in skipped)
    assert d.selected == []


def test_diagnose_cli_outputs(capsys, tmp_path, robot):
    data = tmp_path / "c.csv"
    assert main(["synth", "stiffness", str(data), "--effect", "force_bias=0.02", "--seed", "9"]) == 0
    capsys.readouterr()
    report, plots = tmp_path / "report.md", tmp_path / "plots"
    code = main(["diagnose", str(data), "--json", "-", "--report", str(report), "--plots", str(plots),
                 "--noise-mm", "0.01"])
    out, err = capsys.readouterr()
    assert code == 0, err
    res = json.loads(out)
    for key in ("rms_before_mm", "rms_after_mm", "selected_effects", "candidates", "joint_stiffness_Nm_per_rad",
                "noise_floor_mm", "noise_source", "explains_data", "unexplained_mm", "outliers", "discovered",
                "residual_structure", "warnings", "n_hypotheses", "thresholds", "verdict"):
        assert key in res
    assert res["selected_effects"] == ["force_bias"]
    assert res["noise_floor_mm"] == 0.01 and res["noise_source"] == "stated"
    assert len(res["candidates"]) == len(CANDIDATES)
    bias = next(c for c in res["candidates"] if c["name"] == "force_bias")
    assert set(bias["params"]) == {"b_fx (N)", "b_fy (N)", "b_fz (N)"}
    assert bias["p_grouped"] < 1e-4 and bias["f_stat"] > 10
    assert res["rms_after_mm"] < 0.5 * res["rms_before_mm"]
    term = next(t for t in res["terms"] if t["name"] == "force_bias")
    # the verdict follows the plausibility of the bias the data need
    assert res["explains_data"] is term["plausible"]
    assert res["unexplained_mm"] == pytest.approx(np.sqrt(max(res["rms_after_mm"] ** 2 - 0.01**2, 0)))
    strengths = [s["strength"] for s in res["residual_structure"]]
    assert strengths == sorted(strengths, reverse=True)
    assert "# Residual diagnosis" in report.read_text()
    names = {p.name for p in plots.iterdir()}
    assert {"residual_vs_joint_torque.png", "residual_vs_load_magnitude.png", "residual_vs_joint_angles.png",
            "residual_vs_order.png"} <= names
    assert {f"candidate_{n}.png" for n in CANDIDATES} <= names


@pytest.mark.parametrize("value", ["0", "-0.01", "nan", "20"])
def test_diagnose_cli_bad_noise(capsys, tmp_path, value):
    data = tmp_path / "c.csv"
    assert main(["synth", "stiffness", str(data), "--n", "24", "--seed", "1"]) == 0
    capsys.readouterr()
    code = main(["diagnose", str(data), f"--noise-mm={value}"])
    _, err = capsys.readouterr()
    assert code == 2 and len(err.strip().splitlines()) == 1 and "--noise-mm" in err


def test_diagnose_cli_bad_input(capsys, tmp_path):
    code = main(["diagnose", str(tmp_path / "none.csv")])
    _, err = capsys.readouterr()
    assert code == 2 and len(err.strip().splitlines()) == 1 and "cannot read" in err
