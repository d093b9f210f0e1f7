"""diagnose-run: a machining run whose plant carries an effect the
compensator's model lacks (or whose loop lags) is traced, fixed and re-run."""

import json
from pathlib import Path

from robstiff_drake.commands.main import main

ROOT = Path(__file__).parents[1]


def make_run(tmp_path, scenario_text, name, capsys):
    sc = tmp_path / f"{name}.yaml"
    sc.write_text(scenario_text)
    out = tmp_path / name
    assert main(["simulate", str(sc), "--compensation", "on", "--out", str(out)]) == 0
    capsys.readouterr()
    return out


def diagnose(run_dir, capsys):
    code = main(["diagnose-run", str(run_dir), "--json", "-"])
    out, err = capsys.readouterr()
    assert code == 0, err
    return json.loads(out)


def test_a_softer_joint_is_traced_and_fixed(tmp_path, capsys):
    k = "1.5e6, 1.1e6, 6.4e5, 3.0e5, 3.0e5, 2.0e5"  # joint 3 is 20 % softer than the model thinks
    text = (ROOT / "diagrams" / "block_milling.yaml").read_text().replace(
        "plant:\n", f"plant:\n  joint_stiffness_Nm_per_rad: [{k}]\n", 1)
    rep = diagnose(make_run(tmp_path, text, "soft_j3", capsys), capsys)
    assert rep["selected"][0] == "stiffness_error_j3"
    r3 = rep["params"]["stiffness_error_j3"]["r3 (%)"]
    assert 18 < r3 < 35  # the truth: compliance 25 % higher
    assert rep["cause"] == "stiffness_error_j3"
    before, after = rep["surface_error_before_mm"], rep["surface_error_after_mm"]
    assert before["mean"] > 0.08
    assert abs(after["mean"]) < 0.25 * before["mean"]
    assert (tmp_path / "soft_j3" / "diagnosis" / "before_after.png").exists()


def test_lost_motion_is_found_by_the_second_cut(tmp_path, capsys):
    text = (ROOT / "diagrams" / "block_milling.yaml").read_text().replace(
        "plant:\n", "plant:\n  lost_motion_rad: [4.0e-5, 4.0e-5, 4.0e-5, 0.0, 0.0, 0.0]\n", 1)
    rep = diagnose(make_run(tmp_path, text, "backlash", capsys), capsys)
    # one straight pass cannot tell lost motion from a stiffness error: both are listed ...
    consistent = set(rep["selected"][:1]) | set(rep["also_consistent_with"])
    assert "lost_motion" in consistent
    # ... and the second cut with each fix decides
    assert rep["cause"] == "lost_motion"
    assert rep["surface_error_after_mm"]["rms"] < 0.5 * rep["surface_error_before_mm"]["rms"]


def test_the_loops_lag_is_traced_to_predictive_compensation(tmp_path, capsys):
    text = (ROOT / "diagrams" / "interrupted_cut.yaml").read_text()  # plain compensation at 24 ms
    rep = diagnose(make_run(tmp_path, text, "lag", capsys), capsys)
    assert rep["selected"][0] == "loop_lag"
    assert 50 < rep["params"]["loop_lag"]["tau_lag (ms)"] < 300
    assert rep["fix"].startswith("switched on predictive")
    b, a = rep["surface_error_before_mm"], rep["surface_error_after_mm"]
    assert max(a["entry_max_abs"], a["exit_max_abs"]) < 0.5 * max(b["entry_max_abs"], b["exit_max_abs"])


def test_a_run_directory_missing_a_file(tmp_path, capsys):
    (tmp_path / "scenario.yaml").write_text("name: x\n")
    code = main(["diagnose-run", str(tmp_path)])
    _, err = capsys.readouterr()
    assert code == 2 and len(err.strip().splitlines()) == 1
    assert "missing timeseries_compensated.csv" in err
    code = main(["diagnose-run", str(tmp_path / "nope")])
    _, err = capsys.readouterr()
    assert code == 2 and "no such run directory" in err
