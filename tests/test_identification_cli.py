"""End-to-end: synth -> identify / calibrate-payload, plan-poses, table2."""

import json

import numpy as np
import pytest

from robstiff_drake.commands.main import main
from robstiff_drake.identification.stiffness.measurement_table import read_table


def cli(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def test_synth_then_identify(capsys, tmp_path, robot):
    data = tmp_path / "c.csv"
    code, out, _ = cli(capsys, "synth", "stiffness", data, "--n", 120, "--seed", 3, "--tool", "0,0,350")
    assert code == 0
    text = data.read_text()
    assert "# Made with:" in text and "noise" in text  # says how it was made
    code, out, err = cli(capsys, "identify", data, "--tool", "0,0,350", "--json", "-")
    assert code == 0, err
    res = json.loads(out)
    k = np.array(res["joint_stiffness_Nm_per_rad"])
    np.testing.assert_allclose(k[:3], robot.joint_stiffness_Nm_per_rad[:3], rtol=0.03)
    assert res["identifiable"] == [True] * 5 + [False]
    assert res["joint_stiffness_std_Nm_per_rad"][5] is None
    assert res["n_measurements"] == 120
    assert res["rms_residual_mm"] == pytest.approx(0.01, rel=0.2)
    # the file records its tool point: identify without --tool uses it
    code, out, _ = cli(capsys, "identify", data, "--json", "-")
    assert json.loads(out)["joint_stiffness_Nm_per_rad"] == res["joint_stiffness_Nm_per_rad"]
    # with the wrong tool point (the line removed, --tool at the flange) the fit is visibly worse
    data.write_text("".join(ln for ln in text.splitlines(keepends=True) if not ln.startswith("# tool_mm:")))
    code, out, _ = cli(capsys, "identify", data, "--tool", "0,0,0", "--json", "-")
    assert json.loads(out)["rms_residual_mm"] > 2 * res["rms_residual_mm"]


def test_identify_plot_and_table(capsys, tmp_path):
    data = tmp_path / "c.csv"
    cli(capsys, "synth", "stiffness", data, "--n", 60)
    plot = tmp_path / "fit.png"
    code, out, _ = cli(capsys, "identify", data, "--plot", plot)
    assert code == 0
    assert plot.read_bytes()[:4] == b"\x89PNG"
    assert "not identifiable, kept at nominal" in out
    assert "95 % interval" in out


def test_synth_with_an_effect_says_so(capsys, tmp_path):
    data = tmp_path / "c.csv"
    code, out, _ = cli(capsys, "synth", "stiffness", data, "--effect", "lost_motion=0.03", "--seed", 2)
    assert code == 0 and "(0.0300 mm beyond the six-spring model)" in out
    assert "0.0300 mm of it beyond what refitting the six joint compliances absorbs" in data.read_text()
    code, _, err = cli(capsys, "synth", "stiffness", data, "--effect", "gremlins")
    assert code == 2 and "unknown effect 'gremlins'" in err


def test_synth_payload_then_calibrate(capsys, tmp_path, robot):
    data = tmp_path / "p.csv"
    assert cli(capsys, "synth", "payload", data, "--seed", 4)[0] == 0
    block = tmp_path / "payload.yaml"
    code, out, err = cli(capsys, "calibrate-payload", data, "--json", "-", "--yaml", block)
    assert code == 0, err
    res = json.loads(out)
    for key in ("mass_kg", "com_mm", "force_bias_N", "torque_bias_Nm", "rms_force_N", "rms_torque_Nm"):
        assert key in res
    assert res["mass_kg"] == pytest.approx(robot.payload.mass_kg, rel=0.005)
    import yaml

    doc = yaml.safe_load(block.read_text())["payload_calibration"]
    assert doc["mass_kg"] == pytest.approx(res["mass_kg"], abs=1e-4)
    np.testing.assert_allclose(doc["com_mm"], res["com_mm"], atol=1e-3)


def test_plan_poses_beats_random(capsys, tmp_path):
    plan = tmp_path / "plan.csv"
    code, out, _ = cli(capsys, "plan-poses", 48, "--candidates", 40, "--out", plan, "--json", "-")
    assert code == 0
    res = json.loads(out)
    assert res["d_efficiency_gain"] > 1.2
    planned = np.array([v for v in res["rel_std_planned"] if v is not None])
    random = np.array([v for v in res["rel_std_random_median"] if v is not None])
    assert np.all(planned < random)
    t = read_table(plan, required=("q1", "q2", "q3", "q4", "q5", "q6", "fx", "fy", "fz"), text_columns=("pose",))
    assert len(t) == 48
    assert "Measure dx,dy,dz" in " ".join(t.comments)
    code, _, err = cli(capsys, "plan-poses", 3)
    assert code == 2 and "outside the allowed range [6, 500]" in err


def test_table2_analysis(capsys, tmp_path):
    code, out, _ = cli(capsys, "table2", "--json", "-", "--plot", tmp_path / "t2.png")
    assert code == 0
    groups = {g["group"]: g for g in json.loads(out)["groups"]}
    assert groups["A"]["rows"] == [1, 2, 3, 4, 5, 6, 17]
    bx = groups["B"]["components"][0]
    # group B along x: mean -0.7383 mm at 180 N and -1.4278 mm at 360 N
    assert bx["displacement_ratio"] == pytest.approx(1.4278 / 0.73833, rel=1e-3)
    assert bx["offset_at_zero_load_mm"] == pytest.approx(-0.0489, abs=2e-4)
    assert groups["C"]["components"] == [None, None, None]
    pooled = json.loads(out)["offset_along_load"]
    # both -x groups move further along the load than linear: about +0.045 mm
    assert pooled["pooled_mm"] == pytest.approx(0.0448, abs=5e-4)
    assert 0.01 < pooled["p_value"] < 0.05
    assert (tmp_path / "t2.png").exists()


def _with_forces_along(path, out, direction):
    """The campaign at ``path`` with every force turned onto ``direction`` (its magnitude kept)."""
    lines = path.read_text().splitlines()
    head = next(i for i, line in enumerate(lines) if not line.startswith("#"))
    cols = lines[head].split(",")
    fi = [cols.index(c) for c in ("fx", "fy", "fz")]
    u = np.asarray(direction, dtype=float) / np.linalg.norm(direction)
    rows = []
    for line in lines[head + 1:]:
        c = line.split(",")
        f = np.linalg.norm([float(c[i]) for i in fi])
        for i, v in zip(fi, u * f):
            c[i] = f"{v:.6g}"
        rows.append(",".join(c))
    out.write_text("\n".join(lines[:head + 1] + rows) + "\n")
    return out


@pytest.mark.parametrize("direction", [(1, 1, 1), (1, -1, 0.5)])
def test_collinear_forces_never_give_a_negative_stiffness_marked_identifiable(capsys, tmp_path, direction):
    """Every force along one line (a synthetic campaign's forces turned
    onto one direction): before, identify exited 0 with joints 3 and 4 (or 1
    and 3) negative and marked identifiable; now it refuses in one line."""
    data = tmp_path / "c.csv"
    assert cli(capsys, "synth", "stiffness", data, "--n", 120, "--seed", 3, "--tool", "0,0,350")[0] == 0
    bad = _with_forces_along(data, tmp_path / "collinear.csv", direction)
    code, out, err = cli(capsys, "identify", bad, "--json", "-")
    assert code == 2 and len(err.strip().splitlines()) == 1, (code, err)
    assert "along one line" in err and "negative compliance for joint" in err, err


def test_half_the_rows_in_kn_warn_of_a_unit_mix(capsys, tmp_path):
    """Every other row's forces written in kN in the N columns: before, no
    warning; now a warning naming the rows, in the text and the JSON."""
    data = tmp_path / "c.csv"
    assert cli(capsys, "synth", "stiffness", data, "--n", 120, "--seed", 3, "--tool", "0,0,350")[0] == 0
    lines = data.read_text().splitlines()
    head = next(i for i, line in enumerate(lines) if not line.startswith("#"))
    fi = [lines[head].split(",").index(c) for c in ("fx", "fy", "fz")]
    rows = []
    for n, line in enumerate(lines[head + 1:]):
        c = line.split(",")
        if n % 2:
            for i in fi:
                c[i] = f"{float(c[i]) / 1000:.6g}"
        rows.append(",".join(c))
    mixed = tmp_path / "mixed.csv"
    mixed.write_text("\n".join(lines[:head + 1] + rows) + "\n")
    code, out, err = cli(capsys, "identify", mixed, "--json", "-")
    assert code == 0, err
    res = json.loads(out)
    mix = [w for w in res["warnings"] if "a unit mix?" in w]
    assert mix and "60 rows move 1e+03 x more" in mix[0] and f"lines {head + 3}, {head + 5}," in mix[0], mix
    assert "a unit mix?" in err
    # the file as written (one unit) gives no such warning
    code, out, _ = cli(capsys, "identify", data, "--json", "-")
    assert not any("unit mix" in w for w in json.loads(out)["warnings"])
