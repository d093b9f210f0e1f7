"""Any library robot in the closed loop: a short block pass on the FANUC
(modified DH, sign flips and the J2/J3 interaction) through simulate,
sweep and a run folder; a scenario's `robot:` key against --robot; a pass
its robot cannot follow; identification accuracy in each robot's
controller convention against the IRB6400's."""

import json
from pathlib import Path

import numpy as np
import pytest
import yaml

from robstiff_drake.commands.main import main
from robstiff_drake.model import kinematics as kin
from robstiff_drake.model.robot import load_robot

DATA = Path(__file__).parent / "data"


def cli(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def moved_scenario(tmp_path, robot_name, dx_mm, dz_mm, name="short.yaml", robot_key=True):
    """tests/data/short_block.yaml with the block and the pass moved by (dx, 0, dz) mm."""
    doc = yaml.safe_load((DATA / "short_block.yaml").read_text())
    for box in doc["workpiece"]["boxes_mm"]:
        box[0] += dx_mm
        box[1] += dx_mm
        box[4] += dz_mm
    for w in doc["path"]["waypoints_mm"]:
        w[0] += dx_mm
        w[2] += dz_mm
    if robot_key:
        doc["robot"] = robot_name
    path = tmp_path / name
    path.write_text(yaml.safe_dump(doc))
    return path


@pytest.fixture(scope="module")
def fanuc_run(tmp_path_factory):
    """The short pass at the FANUC's reference point (1750, 0, 470) mm, both ways."""
    tmp = tmp_path_factory.mktemp("fanuc")
    sc = moved_scenario(tmp, "r2000ic_165f", 150.0, -230.0)
    out = tmp / "run"
    code = main(["simulate", str(sc), "--out", str(out), "--json", str(tmp / "summary.json")])
    assert code == 0
    return sc, out, json.loads((tmp / "summary.json").read_text())


def test_the_fanuc_runs_in_the_closed_loop_and_compensation_works(fanuc_run):
    _, _, summary = fanuc_run
    assert summary["robot"] == "r2000ic_165f"
    s = summary["surface_error_mm"]
    assert s["uncompensated"]["mean"] > 0.12  # the arm yields into the part
    assert abs(s["compensated"]["mean"]) < 0.15 * s["uncompensated"]["mean"]


def test_the_run_folder_holds_the_controllers_angles(fanuc_run):
    """The joint log's q*_deg are FANUC's J1..J6 and its corrections the
    controller's; read back with the robot they put the tool on the
    commanded path (within the arm's deflection), and the run's settings
    name the robot."""
    from robstiff_drake.identification.runs import logs as rl
    from robstiff_drake.identification.runs import settings as rs

    _, out, _ = fanuc_run
    robot = load_robot("r2000ic_165f")
    assert yaml.safe_load((out / "sim_scenario.yaml").read_text())["robot"] == "r2000ic_165f"
    assert rs.read_settings(out / "compensator.yaml")[1].robot == "r2000ic_165f"
    _, log = rl.read_joint_log(out / "joint_log.csv")
    path_q = robot.joint_rad(log.q_deg) - robot.model_delta_rad(log.correction_deg)
    p = kin.tool_position(robot.dh, path_q, robot.payload.tool_point_m)
    lines = [ln for ln in (out / "sim_timeseries_compensated.csv").read_text().splitlines() if not ln.startswith("#")]
    header = lines[0].split(",")
    table = np.array([[float(v) for v in ln.split(",")] for ln in lines[1:]])
    rows = {h: table[:, i] for i, h in enumerate(header)}
    cmd = np.column_stack([np.interp(log.t_s, rows["t_s"], rows[f"commanded_{a}_mm"]) for a in "xyz"]) / 1e3
    assert np.max(np.abs(p - cmd)) < 5e-5  # the path's joint references put the tool on the path (CSV rounding)
    # the same numbers read as if they were the model's angles would be far off (J3 is coupled, J3..J6 flipped)
    wrong = kin.tool_position(robot.dh, np.deg2rad(log.q_deg - log.correction_deg), robot.payload.tool_point_m)
    assert np.max(np.abs(wrong - cmd)) > 0.1
    # the joint reference `compensate --reference` streams is in the controller's degrees too: read as
    # compensate reads it, it puts the tool on the commanded path
    from robstiff_drake.commands.compensate import read_reference

    t_ref, q_ref = read_reference(out / "joint_reference.csv", robot)
    p_ref = kin.tool_position(robot.dh, robot.joint_map.to_model(q_ref), robot.payload.tool_point_m)
    cmd_ref = np.column_stack([np.interp(t_ref, rows["t_s"], rows[f"commanded_{a}_mm"]) for a in "xyz"]) / 1e3
    assert np.max(np.abs(p_ref - cmd_ref)) < 5e-5


def test_diagnose_run_takes_the_runs_robot_and_refuses_another(capsys, fanuc_run):
    _, out, _ = fanuc_run
    code, _, err = cli(capsys, "diagnose-run", out, "--robot", "irb6400", "--out", out.parent / "diag")
    assert code == 2 and "--robot irb6400 disagrees with the robot of" in err and "r2000ic_165f" in err
    assert not (out.parent / "diag").exists()


def test_robot_flag_must_agree_with_the_scenarios(capsys, tmp_path):
    sc = moved_scenario(tmp_path, "r2000ic_165f", 150.0, -230.0)
    code, _, err = cli(capsys, "simulate", sc, "--robot", "kr240_r2900", "--out", tmp_path / "o")
    assert code == 2 and len(err.strip().splitlines()) == 1
    assert "--robot kr240_r2900 disagrees with the robot of" in err and "robot: r2000ic_165f" in err
    assert not (tmp_path / "o").exists()


def test_a_pass_the_robot_cannot_follow_is_one_line(capsys, tmp_path):
    # 3.5 m out: beyond the KUKA's reach
    sc = moved_scenario(tmp_path, "kr240_r2900", 2000.0, 0.0)
    code, _, err = cli(capsys, "simulate", sc, "--out", tmp_path / "o")
    assert code == 2 and len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert "path: path point at t = 0.000 s" in err and "out of reach (robot kr240_r2900)" in err
    assert not (tmp_path / "o").exists()
    # a pass outside the working ranges: at (2.5-2.7 m, 0, -0.8 m) the KUKA's A2 would have to go past -5 deg
    sc = moved_scenario(tmp_path, "kr240_r2900", 1000.0, -1500.0, name="low.yaml")
    code, _, err = cli(capsys, "simulate", sc, "--out", tmp_path / "o")
    assert code == 2 and "outside its joint limit" in err and "(robot kr240_r2900)" in err


def test_sweep_runs_the_scenarios_robot(capsys, tmp_path, fanuc_run):
    """One sweep run at the scenario's own settings is the simulate run."""
    sc, _, summary = fanuc_run
    code, out, err = cli(capsys, "sweep", sc, "--period-ms", "4", "--cutoff-hz", "2", "--workers", "1", "--json", "-")
    assert code == 0, err
    res = json.loads(out)
    assert res["robot"] == "r2000ic_165f"
    row = res["runs"][0]
    assert row["stable"] and "predicted" in row
    assert row["surface_error_mm"]["mean"] == pytest.approx(summary["surface_error_mm"]["compensated"]["mean"],
                                                            abs=1e-9)
    # with a scenario without `robot:`, --robot picks it
    bare = moved_scenario(tmp_path, "", 150.0, -230.0, name="bare.yaml", robot_key=False)
    code, out, err = cli(capsys, "sweep", bare, "--period-ms", "4", "--cutoff-hz", "2", "--workers", "1",
                         "--no-predict", "--robot", "r2000ic_165f", "--json", "-")
    assert code == 0, err
    assert json.loads(out)["runs"][0]["surface_error_mm"] == pytest.approx(row["surface_error_mm"])


def test_identification_in_each_controller_convention_is_as_accurate_as_the_irb6400s():
    """Campaigns written in each robot's controller convention (through the
    file) identify as well as the IRB6400's: each joint's RMS relative error
    within twice the IRB6400's (plus 0.2 %), every joint 1-5 identifiable."""
    import sys

    sys.path.insert(0, str(Path(__file__).parents[1] / "studies"))
    from robot_library_identification import accuracy

    rms = {}
    for name in ("irb6400", "irb6640", "kr240_r2900", "r2000ic_165f"):
        errs, _, counted = accuracy(name, 8)
        assert np.all(counted[:5] == 8)
        rms[name] = np.sqrt(np.nanmean(errs[:, :5] ** 2, axis=0))
    for name, r in rms.items():
        assert np.all(r < 2 * rms["irb6400"] + 0.002), (name, r, rms["irb6400"])
