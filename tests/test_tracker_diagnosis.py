"""Absolute-position (laser tracker) campaigns made by Drake's perturbed
plant (tests/tracker_world.py): traced to the effects planted, the error
cut to the noise, the corrected robot file, validation, and bad input."""

import ast
import json
from pathlib import Path

import numpy as np
import pytest
import tracker_world as tw

from robstiff_drake.commands.main import main
from robstiff_drake.identification.tracker.robot_writer import write_corrected_robot
from robstiff_drake.identification.tracker.campaign import read_tracker_campaign
from robstiff_drake.identification.tracker.diagnosis import diagnose_tracker
from robstiff_drake.identification.tracker.model import gravity, perturbed_dh
from robstiff_drake.model import kinematics as kin
from robstiff_drake.model.robot import load_robot
from robstiff_drake.plant import JOINT_NAMES, make_robot_plant

UR10 = Path(__file__).resolve().parent / "data" / "ur10_user.yaml"
NOISE = 0.03
# mean length of a 3D Gaussian error of NOISE per component: 2 sqrt(2/pi) sigma
MEAN3D = 2 * np.sqrt(2 / np.pi) * NOISE


def _write(tmp_path, world, name="c.csv"):
    path = tmp_path / name
    path.write_text(world.csv_text)
    return path


def _diagnose(capsys, argv):
    code = main(["diagnose"] + [str(a) for a in argv] + ["--json", "-"])
    out, err = capsys.readouterr()
    assert code == 0, err
    return json.loads(out)


def test_the_generator_shares_no_code_with_the_diagnosis():
    from robstiff_drake.diagrams import tracker_world as generator  # tests/tracker_world.py hands its names on

    tree = ast.parse(Path(generator.__file__).read_text())
    imported = {n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)}
    forbidden = {f"robstiff_drake.identification.{m}" for m in
                 ("tracker_model", "tracker_fit", "tracker_terms", "tracker_diagnosis", "registration")}
    assert not imported & (forbidden | {"robstiff_drake.model.kinematics"}), imported
    assert "pydrake.multibody.plant" in imported


@pytest.mark.parametrize("name", ["irb6400", "r2000ic_165f", "kr240_r2900", str(UR10)])
def test_gravity_torques_are_drakes(name):
    robot = load_robot(name)
    plant, _ = make_robot_plant(robot)
    ctx = plant.CreateDefaultContext()
    idx = [plant.GetJointByName(n).position_start() for n in JOINT_NAMES]
    q = np.random.default_rng(3).uniform(-1.5, 1.5, size=(6, 6))
    tau, _ = gravity(robot, kin.frames(robot.dh, q), q)
    for i in range(len(q)):
        x = np.zeros(plant.num_positions())
        x[idx] = q[i]
        plant.SetPositions(ctx, x)
        np.testing.assert_allclose(tau[i], plant.CalcGravityGeneralizedForces(ctx)[idx], atol=1e-9 * np.abs(tau).max())


def test_hayati_tilt_in_kinematics_and_urdf(tmp_path):
    # beta in the numpy chain and in the URDF Drake parses agree (standard and modified DH)
    for name in ("irb6400", "r2000ic_165f"):
        robot = load_robot(name)
        delta = np.zeros((6, 5))
        delta[1, 4], delta[2, 4] = 0.01, -0.02
        from dataclasses import replace
        bent = replace(robot, dh=perturbed_dh(robot.dh, delta), name=name + "_bent")
        plant, _ = make_robot_plant(bent)
        ctx = plant.CreateDefaultContext()
        idx = [plant.GetJointByName(n).position_start() for n in JOINT_NAMES]
        for q in np.random.default_rng(4).uniform(-1, 1, size=(4, 6)):
            x = np.zeros(plant.num_positions())
            x[idx] = q
            plant.SetPositions(ctx, x)
            p = plant.CalcPointsPositions(ctx, plant.GetFrameByName("flange"), np.zeros((3, 1)),
                                          plant.world_frame())[:, 0]
            np.testing.assert_allclose(p, kin.tool_position(bent.dh, q), atol=1e-12)


@pytest.mark.parametrize("name, seed", [("irb6400", 11), (str(UR10), 12)])
def test_campaign_traced_and_cut_to_the_noise(capsys, tmp_path, name, seed):
    robot = load_robot(name)
    world = tw.make_tracker_campaign(robot, seed, n=700, noise_mm=NOISE)
    data = _write(tmp_path, world)
    rep = _diagnose(capsys, [data, "--robot", name, "--noise-mm", NOISE])
    e = rep["error_3d_mm"]
    assert e["before"]["mean"] > 0.5, e  # registration and the nominal arm leave the geometry and the sag
    assert e["after"]["mean"] <= 1.2 * MEAN3D, e
    for effect in ("joint_offsets", "link_lengths", "link_twists", "joint_compliance", "time_drift"):
        assert effect in rep["selected_effects"], (effect, rep["selected_effects"])
    assert rep["explains_data"] is True, rep["verdict"]
    # the measured point within 2 mm of the true one (d6 and the point's z are one parameter: the rank test says so)
    assert np.linalg.norm(np.array(rep["tool_mm"]) - world.true["tool_mm"]) < 2.0
    assert "d6" in rep["not_identifiable_geometry"]
    # the sag's stiffness of the main axes within 15 % of the plant's
    k_true = world.true["k_Nm_per_rad"]
    for j in (1, 2):
        assert rep["joint_stiffness_Nm_per_rad"][j] == pytest.approx(k_true[j], rel=0.15)
    assert set(rep["registration"]) >= {"rotation", "translation_mm"}
    assert all(set(c) == {"terms", "correlation"} for c in rep["confounded"])


def test_corrected_robot_file_reproduces_the_fit(capsys, tmp_path):
    for name, seed in (("r2000ic_165f", 21), ("kr240_r2900", 22)):  # modified DH and coupled joints; sign flips
        robot = load_robot(name)
        world = tw.make_tracker_campaign(robot, seed, n=500, noise_mm=NOISE)
        data = _write(tmp_path, world, f"{name}.csv")
        d = diagnose_tracker(robot, read_tracker_campaign(data, robot), noise_mm=NOISE, residual_map=False)
        out = tmp_path / f"{name}_corrected.yaml"
        write_corrected_robot(out, robot, d.fit, d.report, str(data), d.problem.q)
        new = load_robot(str(out))
        q_ctrl = np.random.default_rng(5).uniform(np.rad2deg(robot.q_lower_rad) * 0.5,
                                                  np.rad2deg(robot.q_upper_rad) * 0.5, size=(50, 6))
        want = kin.tool_position(perturbed_dh(robot.dh, d.fit.geo), robot.joint_rad(q_ctrl), d.fit.u)
        got = kin.tool_position(new.dh, new.joint_rad(q_ctrl), new.payload.measured_point_m)
        np.testing.assert_allclose(new.payload.tool_point_m, robot.payload.tool_point_m, atol=0)  # kept
        assert np.max(np.abs(got - want)) < 1e-9
        assert "held-out" in out.read_text().lower() and str(data) in out.read_text()
        # every command takes it like any robot file
        assert main(["fk", *map(str, q_ctrl[0]), "--robot", str(out), "--json", "-"]) == 0
        fk = json.loads(capsys.readouterr().out)
        np.testing.assert_allclose(np.array(fk["position_mm"]) / 1e3,
                                   kin.tool_position(new.dh, new.joint_rad(q_ctrl[0])), atol=1e-9)
        # and the corrected arm, its stiffness included, leaves nothing of the geometry and the sag to find
        d2 = diagnose_tracker(new, read_tracker_campaign(data, new), noise_mm=NOISE, residual_map=False)
        assert not {"joint_offsets", "link_lengths", "link_twists", "joint_compliance"} & \
            set(d2.report["selected_effects"]), d2.report["selected_effects"]
        assert d2.report["error_3d_mm"]["before"]["mean"] < 0.1 * d.report["error_3d_mm"]["before"]["mean"]


def test_validation_file(capsys, tmp_path):
    robot = load_robot("irb6400")
    a = _write(tmp_path, tw.make_tracker_campaign(robot, 31, n=500, noise_mm=NOISE), "a.csv")
    b = _write(tmp_path, tw.make_tracker_campaign(robot, 31, n=200, noise_mm=NOISE, pose_seed=1), "b.csv")
    rep = _diagnose(capsys, [a, "--noise-mm", NOISE, "--validate", b])
    v = rep["validation"]
    assert v["data"] == str(b) and v["n_measurements"] == 200
    assert v["error_3d_mm_reregistered"]["after"]["mean"] < 2 * MEAN3D
    assert v["error_3d_mm"]["after"]["mean"] < 0.2 * v["error_3d_mm"]["before"]["mean"]
    assert not [m for m in rep["warnings"] if "--validate" in m], rep["warnings"]


def test_a_validation_file_that_repeats_the_campaign_warns(capsys, tmp_path):
    """--validate with the campaign itself (or rows of it) is legal but no
    independent check: a warning in the text and the JSON."""
    robot = load_robot("irb6400")
    text = tw.make_tracker_campaign(robot, 31, n=150, noise_mm=NOISE).csv_text
    a = tmp_path / "a.csv"
    a.write_text(text)
    lines = text.splitlines()
    header = [i for i, line in enumerate(lines) if line.startswith("q1")][0]
    b = tmp_path / "b.csv"
    b.write_text("\n".join(lines[:header + 1] + lines[header + 1:header + 41]) + "\n")
    code = main(["diagnose", str(a), "--noise-mm", str(NOISE), "--validate", str(b), "--json", "-"])
    out, err = capsys.readouterr()
    assert code == 0, err
    rep = json.loads(out)
    warned = [m for m in rep["warnings"] if "--validate" in m]
    assert warned and "40 of its 40 rows are rows of" in warned[0] and "not independent" in warned[0], rep["warnings"]
    assert "warning: --validate" in err


def test_a_tracker_export_reads_as_the_plain_file(tmp_path):
    robot = load_robot("irb6400")
    plain = _write(tmp_path, tw.make_tracker_campaign(robot, 41, n=60), "plain.csv")
    export = _write(tmp_path, tw.make_tracker_campaign(robot, 41, n=60, extra_columns=True), "export.csv")
    a, b = read_tracker_campaign(plain, robot), read_tracker_campaign(export, robot)
    np.testing.assert_allclose(a.q_deg, b.q_deg, atol=1e-6)
    np.testing.assert_allclose(a.pos, b.pos, atol=1e-5)
    np.testing.assert_allclose(a.t_s, b.t_s, atol=0.06)
    assert b.units["x"] == "mm" and b.pos_unit_mm == 1.0


def _variant(tmp_path, text, name, fn):
    lines = text.splitlines()
    head = next(i for i, l in enumerate(lines) if not l.startswith("#"))
    out = lines[:head + 1] + [fn(l) for l in lines[head + 1:]]
    path = tmp_path / name
    path.write_text("\n".join(out) + "\n")
    return path


def _scale_xyz(factor):
    def fn(line):
        c = line.split(",")
        c[6:9] = [f"{float(v) * factor:.9g}" for v in c[6:9]]
        return ",".join(c)
    return fn


@pytest.mark.parametrize("factor, word", [(1e-3, "metres"), (1 / 25.4, "inches")])
def test_positions_in_other_units_are_refused(capsys, tmp_path, factor, word):
    world = tw.make_tracker_campaign(load_robot("irb6400"), 51, n=40)
    path = _variant(tmp_path, world.csv_text, "u.csv", _scale_xyz(factor))
    code = main(["diagnose", str(path)])
    err = capsys.readouterr().err
    assert code == 2 and len(err.strip().splitlines()) == 1 and word in err, err


def test_a_unit_in_the_header_is_converted(capsys, tmp_path):
    world = tw.make_tracker_campaign(load_robot("irb6400"), 52, n=300)
    path = _variant(tmp_path, world.csv_text.replace("x,y,z", "x [m],y [m],z [m]"), "m.csv", _scale_xyz(1e-3))
    rep = _diagnose(capsys, [path, "--noise-mm", NOISE])
    assert rep["position_unit_mm"] == 1000.0 and rep["error_3d_mm"]["after"]["mean"] < 1.5 * MEAN3D
    assert any("converted to mm" in w for w in rep["warnings"])


def test_frames_that_cannot_be_registered(capsys, tmp_path):
    robot = load_robot("irb6400")
    text = tw.make_tracker_campaign(robot, 53, n=40).csv_text
    lines = text.splitlines()
    head = next(i for i, l in enumerate(lines) if not l.startswith("#"))
    few = tmp_path / "few.csv"  # three poses, repeated
    few.write_text("\n".join(lines[:head + 1] + lines[head + 1:head + 4] * 4) + "\n")
    line = tmp_path / "line.csv"  # the tool moved along a straight line with a fixed orientation
    from robstiff_drake.model import ik

    T0 = ik.tool_down_pose(np.array([1.5, -0.3, 0.8]))
    qs = []
    for s_ in np.linspace(0, 0.6, 12):
        T = T0.copy()
        T[1, 3] += s_
        qs.append(ik.solve_for(robot, T, np.array([0, 0, 0.2])))
    pts = kin.tool_position(robot.dh, np.array(qs), np.array([0, 0, 0.2])) * 1e3
    rows = [",".join(f"{v:.6f}" for v in robot.controller_deg(q)) + "," + ",".join(f"{v:.5f}" for v in p)
            for q, p in zip(qs, pts)]
    line.write_text("# tool_mm: 0, 0, 200\nq1,q2,q3,q4,q5,q6,x,y,z\n" + "\n".join(rows) + "\n")
    for path, word in ((few, "distinct pose"), (line, "one line")):
        code = main(["diagnose", str(path)])
        err = capsys.readouterr().err
        assert code == 2 and len(err.strip().splitlines()) == 1 and word in err, err


def test_a_robot_file_for_another_arm_is_refused(capsys, tmp_path):
    world = tw.make_tracker_campaign(load_robot("irb6400"), 54, n=60)
    data = _write(tmp_path, world)
    code = main(["diagnose", str(data), "--robot", str(UR10)])
    err = capsys.readouterr().err
    assert code == 2 and len(err.strip().splitlines()) == 1 and "does not describe this arm" in err, err


def test_a_drift_without_clock_is_a_trend_not_a_cause(capsys, tmp_path):
    robot = load_robot("irb6400")
    world = tw.make_tracker_campaign(robot, 55, n=600, noise_mm=0.01, clock=False)
    rep = _diagnose(capsys, [_write(tmp_path, world), "--noise-mm", 0.01])
    trend = [t for t in rep["effects"] if t["kind"] == "trend"]
    if np.linalg.norm(world.true["drift_mm"]) > 0.1:
        assert [t["name"] for t in trend] == ["order_trend"]
    if trend:
        assert rep["explains_data"] is not True and "order" in rep["verdict"]
    assert "time_drift" not in rep["selected_effects"]


def test_the_residual_map_only_when_it_generalises(capsys, tmp_path):
    # joint 3 off by an error of the elbow's absolute angle, sin(3 (J2 + J3)): no joint's own periodic error
    # holds it, the map (which has the elbow's sum) does, in every fold
    robot = load_robot(str(UR10))
    world = tw.make_tracker_campaign(robot, 61, n=1500, noise_mm=NOISE, coupled=1e-4)
    rep = _diagnose(capsys, [_write(tmp_path, world), "--robot", UR10, "--noise-mm", NOISE])
    e = rep["error_3d_mm"]
    assert rep["residual_map"]["kept"] is True, rep["residual_map"]
    assert e["after_with_residual_map"]["mean"] < 0.9 * e["after"]["mean"], e
    assert all(f["with"] < f["without"] for f in rep["residual_map"]["per_fold_mm"])
    assert "non-parametric" in rep["verdict"] and rep["explains_data"] is False
    # without it, the map is tried and not kept
    world = tw.make_tracker_campaign(robot, 62, n=1500, noise_mm=NOISE)
    rep = _diagnose(capsys, [_write(tmp_path, world, "b.csv"), "--robot", UR10, "--noise-mm", NOISE])
    assert rep["residual_map"]["kept"] is False and rep["explains_data"] is True, rep["verdict"]
    assert rep["periodic_errors"] == [], rep["periodic_errors"]  # no periodic error where the plant has none


def test_the_residual_map_is_zero_outside_the_campaigns_domain():
    # fitted on poses with joint 2 in [-90, -30] deg, it says nothing at joint 2 = +60 deg
    from robstiff_drake.identification.tracker import residual_map as rmap

    rng = np.random.default_rng(5)
    J = rng.uniform(-0.5, 0.5, size=(400, 6))
    J[:, 1] = rng.uniform(np.deg2rad(-90), np.deg2rad(-30), 400)
    Jv = rng.normal(size=(400, 3, 6))
    resid = 1e-4 * np.sin(3 * J[:, [1]]) * np.ones((400, 3))
    mp = rmap.ResidualMap(6, 1e-6).fit(J, Jv, resid)
    assert np.all(mp.weight(J) == 1.0)
    far = J[:20].copy()
    far[:, 1] = np.deg2rad(60)
    assert np.all(mp.weight(far) == 0.0) and np.all(mp.predict(far, Jv[:20]) == 0.0)


def test_a_periodic_joint_error_of_unknown_period(capsys, tmp_path):
    """A reducer's error on joint 3, every 24.1 deg, 0.9 mrad (Drake's plant):
    found by the periodogram, its period's interval holding 24.1, its size
    within 5 %, written into the corrected robot file that fk reads, and a
    second diagnosis with that file finds it no more."""
    robot = load_robot(str(UR10))
    world = tw.make_tracker_campaign(robot, 71, n=1500, noise_mm=NOISE, periodic=[(3, 24.1, 0.9e-3)])
    data = _write(tmp_path, world)
    out = tmp_path / "ur10_corrected.yaml"
    rep = _diagnose(capsys, [data, "--robot", UR10, "--noise-mm", NOISE, "--write-robot", out])
    top = rep["periodic_errors"][0]
    assert top["joint"] == 3 and top["period_ci95_deg"][0] <= 24.1 <= top["period_ci95_deg"][1], top
    assert top["amplitude_mrad"] == pytest.approx(0.9, rel=0.05), top
    assert "joint 3: an angle error periodic every 24." in top["text"] and "reducer or encoder" in top["text"]
    assert all(e["amplitude_mrad"] < 0.05 for e in rep["periodic_errors"][1:]), rep["periodic_errors"]
    assert rep["explains_data"] is True and rep["error_3d_mm"]["after"]["mean"] <= 1.2 * MEAN3D
    text = out.read_text()
    assert "joint_periodic_errors:" in text and "joint: 3" in text
    new = load_robot(str(out))
    q_ctrl = np.array([10.0, -80.0, 47.0, -60.0, 30.0, 5.0])
    assert main(["fk", *map(str, q_ctrl), "--robot", str(out), "--json", "-"]) == 0
    fk = json.loads(capsys.readouterr().out)
    e3 = 1e-3 * (top["sin_mrad"] * np.sin(np.deg2rad(q_ctrl[2]) * 360 / top["period_deg"])
                 + top["cos_mrad"] * np.cos(np.deg2rad(q_ctrl[2]) * 360 / top["period_deg"]))
    assert new.joint_rad(q_ctrl)[2] - np.deg2rad(q_ctrl[2]) == pytest.approx(e3, abs=0.05e-3)
    np.testing.assert_allclose(np.array(fk["position_mm"]) / 1e3, kin.tool_position(new.dh, new.joint_rad(q_ctrl)),
                               atol=1e-9)
    d2 = diagnose_tracker(new, read_tracker_campaign(data, new), noise_mm=NOISE, residual_map=False)
    assert not [e for e in d2.report["periodic_errors"] if e["joint"] == 3 and e["amplitude_mrad"] > 0.05]


def test_harmonics_of_a_joints_turn_are_named(capsys, tmp_path):
    # joints 2 and 3 off by 0.1 mrad at the 3rd and 4th harmonic of their turn (periods 120 and 90 deg): named as
    # periodic errors of those joints, the error down to the noise, nothing left for the map.  The two periods are
    # closer than the periodogram's resolution over the joints' spans (about 360 / span cycles per turn), so they
    # are not told apart one by one: the test asks for the joints and the band, not for each period
    robot = load_robot(str(UR10))
    world = tw.make_tracker_campaign(robot, 63, n=1500, noise_mm=NOISE, unnamed=1e-4)
    rep = _diagnose(capsys, [_write(tmp_path, world), "--robot", UR10, "--noise-mm", NOISE])
    for joint in (2, 3):
        hits = [e for e in rep["periodic_errors"] if e["joint"] == joint and 60 <= e["period_deg"] <= 180]
        assert hits and max(e["amplitude_mrad"] for e in hits) > 0.05, (joint, rep["periodic_errors"])
    assert {e["joint"] for e in rep["periodic_errors"]} == {2, 3}, rep["periodic_errors"]
    assert rep["error_3d_mm"]["after"]["mean"] <= 1.25 * MEAN3D, rep["error_3d_mm"]
    assert rep["residual_map"]["kept"] is False and rep["explains_data"] is True, rep["verdict"]


def test_applied_loads_give_every_loaded_joints_stiffness(capsys, tmp_path):
    # each pose measured unloaded and under 300-700 N: the weight and the loads deflect the same springs; the
    # loaded diagnosis's terms are tried as blocks and none is taken where the plant has only springs
    robot = load_robot("irb6400")
    world = tw.make_tracker_campaign(robot, 71, n=600, noise_mm=NOISE, loads=True)
    rep = _diagnose(capsys, [_write(tmp_path, world), "--noise-mm", NOISE])
    assert rep["explains_data"] is True, rep["verdict"]
    assert "joint_compliance" in rep["selected_effects"]
    assert not [n for n in rep["selected_effects"] if n.startswith("load:")]
    tried = {r["name"] for rnd in rep["rounds"] for r in rnd}
    assert {"load:lost_motion", "load:backlash_j2", "load:force_crosstalk"} <= tried
    np.testing.assert_allclose(rep["joint_stiffness_Nm_per_rad"][:5], world.true["k_Nm_per_rad"][:5], rtol=0.05)


def test_every_output_of_a_tracker_diagnosis_has_its_wrote_line(capsys, tmp_path):
    """As the stiffness diagnosis: a "wrote" line for the corrected robot
    file, the JSON and the report (the tracker's run printed none for the
    JSON and the report)."""
    robot = load_robot("irb6400")
    a = _write(tmp_path, tw.make_tracker_campaign(robot, 31, n=150, noise_mm=NOISE), "a.csv")
    outs = [tmp_path / "corrected.yaml", tmp_path / "d.json", tmp_path / "r.md"]
    code = main(["diagnose", str(a), "--noise-mm", str(NOISE), "--write-robot", str(outs[0]), "--json", str(outs[1]),
                 "--report", str(outs[2])])
    out, err = capsys.readouterr()
    assert code == 0, err
    for p in outs:
        assert p.exists() and f"wrote {p}" in out, (p, out[-800:])
    assert f"wrote {outs[0]}: the corrected robot file" in out


def test_a_pose_column_that_names_every_row_one_pose_is_refused(capsys, tmp_path):
    """Every row under one pose id (before: a reshape ValueError in the
    residual map): one line naming the row whose angles contradict the id."""
    world = tw.make_tracker_campaign(load_robot("irb6400"), 51, n=60)
    lines = world.csv_text.splitlines()
    head = next(i for i, line in enumerate(lines) if not line.startswith("#"))
    text = "\n".join(lines[:head] + [lines[head] + ",pose"] + [line + ",P1" for line in lines[head + 1:]]) + "\n"
    path = tmp_path / "one_pose.csv"
    path.write_text(text)
    code = main(["diagnose", str(path)])
    err = capsys.readouterr().err
    assert code == 2 and len(err.strip().splitlines()) == 1, err
    assert f"{path}:{head + 3}: pose 'P1' has q" in err and "a pose id names one pose" in err, err
    # ids that each name one pose (a pose measured twice shares its id) are read
    rows = [f"{line},P{i}" for i, line in enumerate(lines[head + 1:])]
    path.write_text("\n".join(lines[:head] + [lines[head] + ",pose"] + rows + [rows[0]]) + "\n")
    from robstiff_drake.identification.tracker.campaign import read_tracker_campaign as read

    assert len(read(path, load_robot("irb6400")).pose) == len(rows) + 1


def _with_periodic(tmp_path, entries, name="ur10_periodic.yaml"):
    text = UR10.read_text() + "\njoint_periodic_errors:\n" + "".join(
        f"  - {{joint: {j}, period_deg: {p}, sin_mrad: {s}, cos_mrad: {c}}}\n" for j, p, s, c in entries)
    path = tmp_path / name
    path.write_text(text)
    return path


def test_a_robot_files_periodic_errors_move_the_joints_and_back(tmp_path):
    """joint_periodic_errors: the model's angle is the controller's plus the
    error, to_controller inverts it, a file without the key is unchanged."""
    plain = load_robot(str(UR10))
    robot = load_robot(str(_with_periodic(tmp_path, [(3, 24.1, 0.9, -0.3), (3, 12.05, 0.2, 0.0), (5, 360, 1.5, 2)])))
    q = np.random.default_rng(8).uniform(-170, 170, size=(200, 6))
    q[:, 2] = np.clip(q[:, 2], -150, 150)
    dq = robot.joint_rad(q) - plain.joint_rad(q)
    q3, q5 = np.deg2rad(q[:, 2]), np.deg2rad(q[:, 4])
    want3 = 1e-3 * (0.9 * np.sin(q3 * 360 / 24.1) - 0.3 * np.cos(q3 * 360 / 24.1) + 0.2 * np.sin(q3 * 360 / 12.05))
    np.testing.assert_allclose(dq[:, 2], want3, atol=1e-12)
    np.testing.assert_allclose(dq[:, 4], 1e-3 * (1.5 * np.sin(q5) + 2 * np.cos(q5)), atol=1e-12)
    assert not np.any(dq[:, [0, 1, 3, 5]])
    np.testing.assert_allclose(robot.controller_deg(robot.joint_rad(q)), q, atol=1e-9)
    assert plain.joint_map.periodic == () and plain.joint_map.is_identity


def test_periodic_errors_that_would_turn_a_joint_backwards_are_refused(capsys, tmp_path):
    # 5 mrad every 2 deg: the joint's angle would change by 0.9 rad per rad of the motor's (an amplitude in the
    # wrong unit, or a period): one line naming the key
    path = _with_periodic(tmp_path, [(2, 2.0, 5.0, 0.0)])
    code = main(["fk", "0", "-90", "0", "-90", "0", "0", "--robot", str(path)])
    err = capsys.readouterr().err
    assert code == 2 and "joint_periodic_errors" in err and "backwards" in err and "Traceback" not in err, err
    path = _with_periodic(tmp_path, [(7, 20.0, 0.5, 0.0)], "bad_joint.yaml")
    code = main(["fk", "0", "-90", "0", "-90", "0", "0", "--robot", str(path)])
    err = capsys.readouterr().err
    assert code == 2 and "joint_periodic_errors[0].joint" in err, err


def test_the_fft_periodogram_is_the_direct_least_squares_fit():
    """The periodogram's reduction of the sum of squares (sums over poses by an
    FFT of binned angles) against a least-squares fit of the two columns by
    numpy's lstsq at the same periods."""
    from robstiff_drake.identification.tracker import periodic as tpd

    rng = np.random.default_rng(9)
    ang = rng.uniform(-3.0, 4.0, 800)
    L = rng.normal(size=(800, 3))
    r = rng.normal(size=(800, 3)) + 0.5 * L * np.sin(360 / 24.1 * ang + 0.3)[:, None]
    nu, power = tpd.periodogram(ang, L, r)
    assert 360 / nu[np.argmax(power)] == pytest.approx(24.1, abs=0.2)
    for i in (0, 37, int(np.argmax(power)), len(nu) - 1):
        X = tpd.columns(ang, L, 360 / nu[i]).reshape(-1, 2)
        coef = np.linalg.lstsq(X, r.reshape(-1), rcond=None)[0]
        direct = float(r.reshape(-1) @ r.reshape(-1) - np.sum((r.reshape(-1) - X @ coef) ** 2))
        assert power[i] == pytest.approx(direct, rel=0.02, abs=1e-6 * direct + 1e-9), (i, nu[i])
