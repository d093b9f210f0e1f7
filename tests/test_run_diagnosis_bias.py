"""diagnose-run when the compensator's sensor bias is off (a drifted zero,
a payload weighed wrong): the compensator corrects for a force the cut
did not exert and the face sits off by a constant.  On a straight pass a
constant is also what a wrong tool length would leave, so the report must
not send the user to the tool length alone: the force bias is a candidate
whose fix (the bias in the model) a verification cut can confirm.  And a
verification cut beats only the cuts that were made."""

from pathlib import Path

import pytest

from robstiff_drake.identification.runs.diagnosis import _verified_fix
from robstiff_drake.model.robot import load_robot
from test_run_diagnosis import PREDICTIVE, after, diagnose, simulate

TRUE_BIAS_N = (3.0, -2.0, 5.0)  # tests/data/short_block.yaml's sensor
MODEL_BIAS_Z_N = 17.0  # the compensator's: 12 N off along the sensor's z (the tool's axis)


def test_a_wrong_sensor_bias_is_a_candidate_and_its_fix_is_verified(tmp_path, capsys):
    robot = load_robot()
    com = [v * 1e3 for v in robot.payload.com_m]
    (tmp_path / "cal.yaml").write_text(
        "payload_calibration:\n"
        f"  mass_kg: {robot.payload.mass_kg}\n"
        f"  com_mm: [{com[0]}, {com[1]}, {com[2]}]\n"
        f"  force_bias_N: [{TRUE_BIAS_N[0]}, {TRUE_BIAS_N[1]}, {MODEL_BIAS_Z_N}]\n"
        "  torque_bias_Nm: [0.2, -0.1, 0.05]\n"
        "  sensor_mount_rpy_deg: [0.0, 0.0, 0.0]\n")
    text = PREDICTIVE.replace("model:\n", "model:\n  payload_yaml: cal.yaml\n", 1)
    assert "payload_yaml: cal.yaml" in text
    run_dir = simulate(tmp_path, text, "bias")
    rep = diagnose(run_dir, capsys)
    assert rep["surface_error_before_mm"]["rms"] > 0.03  # 12 N through the arm's compliance: tens of um
    named = [c["name"] for c in rep["causes"]] + rep["also_consistent_with"]
    assert "force_bias" in named
    # never a confident "check your tool length" when a bias fits as well
    assert not (rep["causes"] and rep["causes"][0]["name"] == "setup_offset" and not rep["also_consistent_with"])
    cand = next(c for c in rep["candidates"] if c["name"].startswith("force_bias"))
    settings = (run_dir / "diagnosis" / cand["settings"]).read_text()
    fz = float(settings.split("force_bias_N: [", 1)[1].split("]")[0].split(",")[2])
    assert fz == pytest.approx(TRUE_BIAS_N[2], abs=1.5)  # the axis the pass sees: the tool's
    # the verification cut with the bias fix
    cut = tmp_path / "bias_cut"
    from robstiff_drake.commands.main import main
    assert main(["simulate", str(run_dir / "sim_scenario.yaml"), "--compensation", "on", "--compensator",
                 str(run_dir / "diagnosis" / cand["settings"]), "--noise-seed", "101", "--out", str(cut)]) == 0
    for folder in (run_dir, cut):
        for f in Path(folder).glob("sim_*"):
            f.unlink()
    verified = diagnose(run_dir, capsys, "--verify", str(cut))
    b, a = verified["surface_error_before_mm"], after(verified)
    assert a["rms"] < 0.5 * b["rms"]
    assert verified["fix"]["candidate"].startswith("force_bias")


def _report(names):
    return {"candidates": [{"name": n, "params": {n: {}}, "changes": [f"change {n}"], "settings": f"{n}.yaml",
                            "not_in_compensator": []} for n in names]}


def _verdict(cut_names, chosen):
    return {"chosen": chosen, "best": chosen, "tied_with": [], "decided": True, "reason": "best by more than noise",
            "cuts": [{"candidate": n} for n in cut_names], "vs_first_cut": {"better": True}}


def test_a_cut_is_verified_only_against_the_candidates_cut():
    """Two candidates fit the first cut alike and only one was cut: it beats
    the first cut, but which cause it is stays open."""
    fix = _verified_fix(_report(["joint_coupling + loop_lag", "setup_offset + loop_lag"]),
                        _verdict(["joint_coupling + loop_lag"], "joint_coupling + loop_lag"))
    assert fix["status"].startswith("better than the first cut, not verified")
    assert fix["not_cut"] == ["setup_offset + loop_lag"]
    assert fix["settings"] == "joint_coupling + loop_lag.yaml"  # still the better settings to run
    both = _verified_fix(_report(["a", "b"]), _verdict(["a", "b"], "a"))
    assert both["status"] == "verified"
    alone = _verified_fix(_report(["a"]), _verdict(["a"], "a"))
    assert alone["status"] == "verified"


def test_a_preview_run_is_refused_by_diagnose_run_with_the_reason(tmp_path, capsys):
    """A preview run's own compensator.yaml is read (mode: preview), and
    diagnose-run says in one line why it cannot predict that loop, instead
    of calling the file's mode a mistake."""
    from robstiff_drake.commands.main import main
    from robstiff_drake.identification.runs.files import load_run_files

    run_dir = simulate(tmp_path, PREDICTIVE.replace("  mode: predictive\n", "  mode: preview\n", 1), "preview")
    assert load_run_files(run_dir).settings.mode == "preview"
    capsys.readouterr()
    assert main(["diagnose-run", str(run_dir)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "mode: preview" in err[0] and "plain or predictive" in err[0], err
