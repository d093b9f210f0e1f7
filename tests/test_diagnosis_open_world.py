"""`robstiff diagnose` on campaigns with effects its library does not name,
made by Drake with the effect in the robot's physics (tests/open_world.py),
and the honest verdict: noise floor, lack of fit, outliers, plausibility."""

import ast
import json
from pathlib import Path

import numpy as np
import open_world as ow
import pytest

from robstiff_drake.commands.main import main
from robstiff_drake.identification.stiffness import synth
from robstiff_drake.identification.diagnosis.candidates import CANDIDATES
from robstiff_drake.identification.diagnosis.cross_validation import pose_groups, splits
from robstiff_drake.identification.diagnosis.campaign_diagnosis import diagnose
from robstiff_drake.identification.diagnosis.terms import Context, fit_model, held_out
from robstiff_drake.io import Warnings
from robstiff_drake.model import kinematics as kin

NOISE = ow.NOISE_MM
# the dictionary term each physical effect should be traced to
EXPECTED = {"base": "base_tilt", "wrist_lost_motion": "backlash_j5", "frame": "measurement_frame_rotation",
            "hysteresis": "hysteresis_j1", "angle_j3": "angle_compliance_j3", "point_offset": "measured_point_offset"}
# tests/open_world_loads.py's kinds: the terms that may trace each (one of)
EXPECTED_LOADS = {"load_history": ("play_j2", "load_history_j2", "hysteresis_j2"),
                  "periodic_drift": ("drift_periodic",), "crosstalk": ("force_crosstalk",),
                  "preload": ("load_size_compliance", "load_size_compliance_j1", "load_size_compliance_j2",
                              "load_size_compliance_j3")}


def run(robot, c, noise_mm=NOISE, warnings=None):
    return diagnose(robot, c.campaign, tool_m=ow.TOOL_M, noise_mm=noise_mm, warnings=warnings)


def test_the_generator_shares_no_code_with_the_diagnosis():
    tree = ast.parse(Path(ow.__file__).read_text())
    imported = {n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)}
    imported |= {a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
    # the diagnosis (identification/diagnosis/*: candidates, dictionary, terms, selection, candidate_evaluation, ...),
    # the synthetic generator and the six-spring model
    forbidden = {"robstiff_drake.model.effects", "robstiff_drake.model.kinematics",
                 "robstiff_drake.identification.stiffness.synth",
                 "robstiff_drake.identification.stiffness.joint_stiffness"}
    shared = {m for m in imported if m in forbidden or m == "robstiff_drake.identification.diagnosis"
              or m.startswith("robstiff_drake.identification.diagnosis.")}
    assert not shared, shared
    assert "pydrake.multibody.plant" in imported


def test_drake_plant_against_the_six_springs(robot):
    # without an effect, Drake's static equilibrium is the six-spring model
    # plus the load's geometric stiffness (factor 1), which at 700 N stays
    # far below the noise once the springs are refitted
    c = ow.make_campaign("none", 3, noise_mm=0.0)
    cp = c.campaign
    J = kin.jacobian(robot.dh, np.deg2rad(cp.q_deg), ow.TOOL_M)
    tau = np.einsum("nrj,nr->nj", J, cp.wrench)
    d = np.einsum("nrj,nj->nr", J[:, :3], tau / robot.joint_stiffness_Nm_per_rad) * 1e3
    diff = np.sqrt(np.mean((d - cp.disp_mm) ** 2))
    assert 1e-4 < diff < 0.01 * np.sqrt(np.mean(d**2)), diff
    A = (J[:, :3] * tau[:, None, :]).reshape(-1, 6)[:, :5]
    y = cp.disp_mm.reshape(-1)
    coef, *_ = np.linalg.lstsq(A, y, rcond=None)
    assert np.sqrt(np.mean((y - A @ coef) ** 2)) < 0.25 * NOISE


@pytest.mark.parametrize("seed", [201, 202, 203, 204])
def test_no_effect_is_explained_and_nothing_added(robot, seed):
    d = run(robot, ow.make_campaign("none", seed))
    assert d.explains_data is True, d.verdict
    assert d.selected == [] and d.discovered == [] and d.outliers == []
    assert d.rms_after_mm <= 1.25 * NOISE


@pytest.mark.parametrize("kind", sorted(EXPECTED))
@pytest.mark.parametrize("seed", [301, 302])
def test_an_effect_outside_the_library_is_never_explained(robot, kind, seed):
    c = ow.make_campaign(kind, seed)
    assert 2 * NOISE <= c.visible_mm <= 5 * NOISE + 1e-9 or kind in ("wrist_lost_motion", "angle_j3"), c.visible_mm
    d = run(robot, c)
    assert d.explains_data is not True, (kind, d.verdict)
    assert d.rms_before_mm > 1.8 * NOISE
    names = [t["name"] for t in d.discovered]
    assert EXPECTED[kind] in names, (kind, names, d.selected)
    assert d.rms_after_mm < 0.6 * d.rms_before_mm


def test_discovered_sizes_match_the_physics(robot):
    c = ow.make_campaign("base", 311)
    t = next(t for t in run(robot, c).discovered if t["name"] == "base_tilt")
    assert t["plausible"]
    lo, hi = t["ci95"]["c (rad/(N*m))"]
    c_true = 1.0 / c.params["foundation_tilt_stiffness_Nm_per_rad"]
    assert lo * 0.9 <= c_true <= hi * 1.1, (lo, c_true, hi)
    c = ow.make_campaign("frame", 312)
    t = next(t for t in run(robot, c).discovered if t["name"] == "measurement_frame_rotation")
    phi = np.array(list(t["params"].values())) * 1e-3
    assert np.rad2deg(np.linalg.norm(phi)) == pytest.approx(c.params["angle_deg"], rel=0.1)
    c = ow.make_campaign("point_offset", 313)
    t = next(t for t in run(robot, c).discovered if t["name"] == "measured_point_offset")
    np.testing.assert_allclose(np.array(list(t["params"].values())) * 1e-3, c.params["offset_m"], atol=0.006)
    c = ow.make_campaign("hysteresis", 314)
    t = next(t for t in run(robot, c).discovered if t["name"] == "hysteresis_j1")
    w = c.params["play_half_width_rad"] * 1e6
    assert t["params"]["h_load (urad)"] == pytest.approx(w, rel=0.25)
    assert t["params"]["h_reference (urad)"] == pytest.approx(-w, rel=0.25)


@pytest.mark.parametrize("seed", [401, 402])
def test_gross_outliers_are_named_by_line(robot, seed):
    c = ow.make_campaign("outliers", seed)
    w = Warnings(quiet=True)
    d = run(robot, c, warnings=w)
    true_lines = sorted(int(c.campaign.lines[r]) for r in c.outlier_rows)
    assert sorted(o["line"] for o in d.outliers) == true_lines
    assert all(o["residual_mm"] > 0.08 for o in d.outliers)
    assert d.explains_data is True and d.discovered == [] and d.selected == []
    assert any("outlier" in m and str(true_lines[0]) in m for m in w)
    # the stiffness is the clean campaign's, not the one with the bad rows
    clean = ow.make_campaign("none", seed)
    d_clean = run(robot, clean)
    free = d.identifiable
    np.testing.assert_allclose(d.joint_stiffness_Nm_per_rad[free], d_clean.joint_stiffness_Nm_per_rad[free], rtol=0.02)


def test_floor_from_replicate_rows(robot):
    c = ow.make_campaign("none", 501, repeats=2)
    d = run(robot, c, noise_mm=None)
    assert d.floor.source == "replicates" and d.floor.replicate_dof == 60
    assert d.floor.sigma_mm == pytest.approx(NOISE, rel=0.2)
    assert d.explains_data is True, d.verdict
    d = run(robot, ow.make_campaign("base", 502, repeats=2), noise_mm=None)
    assert d.floor.source == "replicates" and d.explains_data is not True
    # stated and replicate floors are both reported
    d = run(robot, c, noise_mm=0.02)
    assert d.floor.source == "stated" and d.floor.replicate_mm == pytest.approx(NOISE, rel=0.2)


def test_without_a_floor_there_is_no_verdict(robot):
    d = run(robot, ow.make_campaign("base", 601), noise_mm=None)
    assert d.explains_data is None and d.unexplained_mm is None
    assert "cannot be said" in d.verdict
    assert [t["name"] for t in d.discovered] == ["base_tilt"]  # the search still runs


def test_sign_flipped_displacements_get_no_verdict(robot):
    c = synth.stiffness_campaign(robot, n=120, noise_mm=NOISE, seed=7).to_campaign()
    c.disp_mm = -c.disp_mm
    w = Warnings(quiet=True)
    d = diagnose(robot, c, noise_mm=NOISE, warnings=w)
    assert d.explains_data is None and d.non_physical
    assert "negative" in d.verdict and any("negative" in m for m in w)


def test_a_size_beyond_the_typical_on_decisive_evidence_is_a_finding(robot):
    # the named tool offset, sized to 0.04 mm beyond the springs, needs about 0.2 m, ten times a TCP error: the
    # evidence is decisive (it takes the residual to the noise), so it is kept, said to be beyond its typical size,
    # and named as what it implies: a tool point not declared
    c = synth.stiffness_campaign(robot, n=120, noise_mm=NOISE, seed=8, effects={"tool_offset": 0.04})
    w = Warnings(quiet=True)
    d = diagnose(robot, c.to_campaign(), noise_mm=NOISE, warnings=w)
    (t,) = d.terms
    assert t["name"] == "tool_offset" and t["beyond_typical"] is True and "beyond the typical bound" in \
        t["plausibility"]
    assert "declared tool point" in t["finding"] and "tool_mm" in t["finding"]
    assert d.rms_after_mm <= 1.25 * NOISE and d.explains_data is True and "setup finding" in d.verdict
    assert any("tool_offset" in m and "decisive" in m for m in w)
    assert all(k > 0 for k in d.joint_stiffness_Nm_per_rad)


def test_nonlinear_parameters_are_refitted_in_each_fold(robot):
    c = synth.stiffness_campaign(robot, n=120, noise_mm=NOISE, seed=9, effects={"tool_offset": 0.03}).to_campaign()
    ctx = Context(robot, c, np.zeros(3), [True] * 5 + [False])
    rows = np.arange(len(c))
    folds = splits(rows, pose_groups(c))
    term = CANDIDATES["tool_offset"]
    _, fits = held_out(ctx, [term], folds)
    full = fit_model(ctx, [term], rows).values["tool_offset"]
    per_fold = np.array([f.values["tool_offset"] for f in fits])
    for (train, _), f in zip(folds, fits):  # each fold's offset is its own training rows' fit
        np.testing.assert_allclose(f.values["tool_offset"], fit_model(ctx, [term], train).values["tool_offset"])
    assert np.min(np.linalg.norm(per_fold - full, axis=1)) > 1e-5  # none of them is the all-rows value
    # the folds never split a pose and are the same on every run
    groups = pose_groups(c)
    for train, test in folds:
        assert not set(groups[train]) & set(groups[test])
    assert all(np.array_equal(a[1], b[1]) for a, b in zip(folds, splits(rows, groups)))


def test_diagnose_twice_gives_the_same_answer(robot):
    c = ow.make_campaign("frame", 701)
    a, b = run(robot, c), run(robot, c)
    assert a.rms_after_mm == b.rms_after_mm and a.terms == b.terms


def test_cli_on_an_open_world_file(capsys, tmp_path):
    c = ow.make_campaign("outliers", 801)
    data = tmp_path / "c.csv"
    data.write_text(ow.to_csv(c))
    code = main(["diagnose", str(data), "--tool", "0,0,350", "--noise-mm", "0.01", "--json", "-"])
    out, err = capsys.readouterr()
    assert code == 0, err
    res = json.loads(out)
    assert sorted(o["line"] for o in res["outliers"]) == sorted(int(c.campaign.lines[r]) for r in c.outlier_rows)
    assert all(set(o) == {"line", "pose", "residual_mm"} for o in res["outliers"])
    assert res["explains_data"] is True and res["noise_source"] == "stated"
    assert any("outlier" in m for m in res["warnings"]) and "robstiff: warning:" in err
    k_with, k = np.array(res["joint_stiffness_with_outliers_Nm_per_rad"]), np.array(res["joint_stiffness_Nm_per_rad"])
    assert np.max(np.abs(k_with / k - 1)) > 0.005  # the bad rows would have moved it


def test_moved_tool_jacobian_matches_the_kinematics(robot):
    # the tool-offset term moves the Jacobian's point analytically; the package's
    # kinematics at the moved tool point must agree
    c = synth.stiffness_campaign(robot, n=40, seed=2).to_campaign()
    tool = np.array([0.0, 0.0, 0.35])
    ctx = Context(robot, c, tool, [True] * 5 + [False])
    for delta in ([0.01, -0.02, 0.03], [0.0, 0.0, -0.1]):
        np.testing.assert_allclose(ctx.jacobian_moved(delta), kin.jacobian(robot.dh, ctx.q, tool + np.array(delta)),
                                   atol=1e-12)


@pytest.mark.parametrize("kind", sorted(EXPECTED_LOADS))
def test_the_loads_history_clock_sensor_and_size(robot, kind):
    c = ow.make_campaign(kind, 331)
    d = run(robot, c)
    names = [t["name"] for t in d.terms]
    assert set(EXPECTED_LOADS[kind]) & set(names), (kind, names)
    assert d.explains_data is not True, d.verdict
    assert d.rms_after_mm <= 1.25 * NOISE, (kind, d.rms_after_mm)
    assert all(t["plausible"] for t in d.terms)


@pytest.mark.parametrize("seed", [341, 342])
def test_a_drift_without_seq_is_an_unexplained_trend(robot, seed):
    c = ow.make_campaign("drift_no_seq", seed)
    assert c.campaign.seq is None
    w = Warnings(quiet=True)
    d = run(robot, c, warnings=w)
    assert d.explains_data is not True, d.verdict
    assert "order" in d.verdict and "seq" in d.verdict, d.verdict
    causes = [t["name"] for t in d.terms if t["name"] not in ("order_trend", "order_periodic")]
    if causes:  # a cause kept beside the trend is said to be indistinguishable from it
        assert "trend" in d.verdict


def test_round_off_torques_carry_nothing(robot):
    # the tool on joint 6's axis: joint 6's torque is round-off; nothing is built on it, in a pure-noise campaign
    for seed in range(3):
        c = synth.stiffness_campaign(robot, n=36, loads_per_pose=3, noise_mm=NOISE, seed=900 + seed,
                                     tool_m=np.array([0.0, 0.0, 0.35]))
        d = diagnose(robot, c.to_campaign(), tool_m=np.array([0.0, 0.0, 0.35]), noise_mm=NOISE)
        assert not d.identifiable[5]
        tried = {r.name: r for rnd in d.rounds for r in rnd}
        for name in ("nonlinear_stiffness_j6", "angle_compliance_j6", "backlash_j6", "play_j6"):
            assert tried[name].status == "skipped" and "no torque" in tried[name].reason, (name, tried[name])
        assert d.explains_data is True and not d.terms, d.verdict


def test_a_floor_far_above_the_residual_is_said(robot):
    c = ow.make_campaign("none", 351)
    w = Warnings(quiet=True)
    d = run(robot, c, noise_mm=0.1, warnings=w)
    assert d.explains_data is True  # nothing contradicts the model, but the statement says little
    assert d.floor_check is not None and d.floor_check["ratio"] > 5
    assert "below the stated floor" in d.verdict and any("overstated" in m for m in w)
    assert run(robot, c).floor_check is None  # at the instrument's real noise nothing is said
