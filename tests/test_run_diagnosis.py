"""diagnose-run on run folders (docs/run_files.md): a compensated cut whose
plant has an effect the compensator lacks (or whose loop lags) is traced
from the cell's files with 3 um of scan noise, each candidate fix is cut
again on the same simulated machine, and the decision reads only the
cuts' settings and scans (every ``sim_*`` truth file is deleted first).
Runs whose compensator is the plant name no cause.  The bulk of the
no-cause runs is studies/run_diagnosis_no_cause.py (18 runs)."""

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from robstiff_drake.commands.diagnose_run import run_robot
from robstiff_drake.commands.main import main
from robstiff_drake.diagrams.run_arm import ArmModel
from robstiff_drake.errors import InputError
from robstiff_drake.identification.runs import files as rf
from robstiff_drake.identification.runs import logs as rl
from robstiff_drake.identification.runs import settings as rs
from robstiff_drake.identification.runs import tables as rt
from robstiff_drake.identification.runs import verification as rv
from robstiff_drake.identification.runs import scan_statistics as ss
from robstiff_drake.identification.runs.diagnosis import run_signals

ROOT = Path(__file__).parents[1]
SHORT = (ROOT / "tests" / "data" / "short_block.yaml").read_text()  # plain compensation: its loop lags
PREDICTIVE = SHORT.replace("controller:\n", "controller:\n  mode: predictive\n", 1)  # the lag predicted away
# along y where joint 2 carries almost none of the arm's weight (tests/data/balanced_y_pass.yaml)
BALANCED = (ROOT / "tests" / "data" / "balanced_y_pass.yaml").read_text().replace(
    "controller:\n", "controller:\n  mode: predictive\n", 1)


def with_plant(text, line):
    return text.replace("plant:\n", f"plant:\n  {line}\n", 1)


def simulate(folder, text, name, *extra):
    sc = folder / f"{name}.yaml"
    sc.write_text(text)
    out = folder / name
    assert main(["simulate", str(sc), "--compensation", "on", "--out", str(out), *extra]) == 0
    return out


def diagnose(run_dir, capsys, *extra):
    capsys.readouterr()
    code = main(["diagnose-run", str(run_dir), "--json", "-", *extra])
    out, err = capsys.readouterr()
    assert code == 0, err
    return json.loads(out)


def verify(tmp_path, run_dir, rep, capsys):
    """Cut each candidate fix on the run's simulated machine (new noise),
    delete every truth file, and decide from the cuts."""
    cuts = []
    for i, c in enumerate(c for c in rep["candidates"] if "settings" in c):
        cut = tmp_path / f"{run_dir.name}_cut{i}"
        assert main(["simulate", str(run_dir / "sim_scenario.yaml"), "--compensation", "on", "--compensator",
                     str(run_dir / "diagnosis" / c["settings"]), "--noise-seed", str(100 + i), "--out", str(cut)]) == 0
        cuts.append(cut)
    for folder in [run_dir, *cuts]:
        for f in folder.glob(f"{rt.SIM_PREFIX}*"):
            f.unlink()
    return diagnose(run_dir, capsys, "--verify", *map(str, cuts))


def verified_causes(fix):
    """The causes whose fix the verification cuts confirmed."""
    return fix.get("verified_causes") or (fix["candidate"] or "").split(" + ")


def after(verified):
    """The best verification cut's surface figures."""
    v = verified["verification"]
    return next(r["surface_error_mm"] for r in v["cuts"] if r["candidate"] == v["best"])


def round_of(rep, name, i=0):
    return next(r for r in rep["rounds"][i] if r["name"] == name)


def test_a_softer_joint_is_traced_and_its_fix_verified(tmp_path, capsys):
    # joint 3 is 20 % stiffer in the model than in the plant
    run_dir = simulate(tmp_path, with_plant(PREDICTIVE, "joint_stiffness_Nm_per_rad: [1.5e6, 1.1e6, 6.4e5, 3.0e5, "
                                                        "3.0e5, 2.0e5]"), "soft_j3")
    rep = diagnose(run_dir, capsys)
    first = rep["causes"][0]
    assert first["name"] == "stiffness_error_j3"
    assert 18 < first["params"]["r3 (%)"] < 32  # the truth: compliance 25 % higher
    assert rep["noise_floor_mm"] == pytest.approx(0.003)
    # a fit that extends a model starts from its solution: never worse than it
    chosen = min((r for r in rep["rounds"][0] if r.get("named")), key=lambda r: r["rms_mm"])
    for rnd in rep["rounds"][1:]:
        assert all(r["rms_mm"] <= chosen["rms_mm"] * (1 + 1e-9) for r in rnd if r["status"] == "ok")
    # the loop's own tracking error, predicted from the logs, is in the model at its predicted size
    assert 0.8 < rep["loop_lag"]["params"]["a (x predicted)"] < 1.25
    verified = verify(tmp_path, run_dir, rep, capsys)
    fix = verified["fix"]
    assert fix["status"].startswith("verified")
    assert "stiffness_error_j3" in verified_causes(fix)
    b, a = verified["surface_error_before_mm"], after(verified)
    assert b["mean"] > 0.04
    assert abs(a["mean"]) < 0.5 * b["mean"] and a["rms"] < 0.5 * b["rms"]
    assert (run_dir / "diagnosis" / "diagnosis.png").exists()


def test_gear_play_is_traced_with_the_hysteretic_law(tmp_path, capsys):
    """150 urad of play (a dead zone) in joint 2 on a pass where its gear's
    total torque crosses zero: the link crosses the gap, the face is off by
    tenths of a millimetre, and diagnose-run's lost_motion cause, the
    compensator's hysteretic law (the gear on its flank until the torque
    passes the friction, 18 N*m, the other way; the link crossing with its
    inertia), names it with b2 near the truth (127 urad when written; the
    smooth law it replaced named nothing, p = 0.28) and writes it into the
    candidate compensator's lost_motion_rad (studies/play_diagnosis.py has
    20-300 urad)."""
    run_dir = simulate(tmp_path, with_plant(BALANCED, "lost_motion_rad: [0.0, 1.5e-4, 0.0, 0.0, 0.0, 0.0]"),
                       "play")
    # the physics the test relies on, from the controller's model and the logs (independent of the diagnosis)
    files = rf.load_run_files(run_dir)
    robot = run_robot(run_dir)
    sig = run_signals(files, robot, ArmModel(robot))
    total = sig.tau_static_Nm + sig.tau_inertia_Nm - sig.tau_Nm  # what the gears carry
    assert total[:, 1].min() < -20.0 and total[:, 1].max() > 20.0  # joint 2's changes sign past 18 N*m
    rep = diagnose(run_dir, capsys)
    assert rep["rms_before_mm"] > 0.1
    assert [c["name"] for c in rep["causes"]] == ["lost_motion"]
    b2 = rep["causes"][0]["params"]["b2 (urad)"]
    assert b2 == pytest.approx(150.0, rel=0.25)
    assert rep["rms_after_mm"] < 0.3 * rep["rms_before_mm"]
    _, fixed = rs.read_settings(run_dir / "diagnosis" / rep["fix"]["settings"])
    assert fixed.lost_motion_rad[1] == pytest.approx(b2 * 1e-6, rel=1e-3)
    assert not any("catalogued" in w for w in rep["warnings"])  # 150 urad is within 1 arcmin


def test_lost_motion_in_gears_that_carry_the_weight_is_not_named(tmp_path, capsys):
    """Joints 2 and 3 carry kN*m of the arm's weight at the block test's pose:
    40 urad of play in them is never taken up by a few hundred N*m of cut,
    leaves the face as it was, and is not named (no data in this run)."""
    rep = diagnose(simulate(tmp_path, with_plant(PREDICTIVE, "lost_motion_rad: [0.0, 4.0e-5, 4.0e-5, 0.0, 0.0, 0.0]"),
                            "loaded"), capsys)
    assert rep["causes"] == []
    assert round_of(rep, "lost_motion")["status"].startswith("no data")


def test_the_loops_lag_is_traced_to_predictive_compensation(tmp_path, capsys):
    run_dir = simulate(tmp_path, SHORT, "lag")  # plain compensation: a 2 Hz filter at 60 mm/s
    rep = diagnose(run_dir, capsys)
    assert rep["causes"] == []
    lag = rep["loop_lag"]
    assert lag["significant"] and 0.8 < lag["params"]["a (x predicted)"] < 1.3
    assert lag["fix"] == "mode: plain -> predictive"
    assert 80 < rep["loop_lag_ms"] < 300  # the 2 Hz filter's lag and the servo's
    verified = verify(tmp_path, run_dir, rep, capsys)
    assert verified["fix"]["status"] == "verified"
    assert verified["fix"]["changes"][0].startswith("mode: plain -> predictive")
    b, a = verified["surface_error_before_mm"], after(verified)
    assert a["rms"] < 0.75 * b["rms"]


@pytest.mark.parametrize("text, mode, seed, noise_mm", [
    (PREDICTIVE, "predictive", 1, 0.003), (PREDICTIVE, "predictive", 2, 0.001), (PREDICTIVE, "predictive", 3, 0.010),
    (SHORT, "plain", 4, 0.003), (BALANCED, "predictive", 5, 0.003)])
def test_no_cause_when_the_compensator_is_the_plant(tmp_path, capsys, text, mode, seed, noise_mm):
    text = text.replace("scan:\n", f"scan:\n  noise_mm: {noise_mm}\n", 1)
    rep = diagnose(simulate(tmp_path, text, "exact", "--noise-seed", str(seed)), capsys)
    assert rep["causes"] == [], rep["causes"]
    # the loop's own tracking error is real and known: only the plain loop gets a fix for it
    assert rep["loop_lag"].get("fix") == ("mode: plain -> predictive" if mode == "plain" else None)
    assert [c["name"] for c in rep["candidates"]] == ([] if mode == "predictive" else ["loop_lag"])
    assert rep["noise_estimated_mm"] == pytest.approx(noise_mm, rel=0.3)
    assert rep["explains_data"] or rep["unexplained_mm"] < noise_mm


@pytest.fixture(scope="module")
def exact_run(tmp_path_factory):
    """A compensated cut whose compensator is the plant (predictive loop)."""
    return simulate(tmp_path_factory.mktemp("exact"), PREDICTIVE, "run")


def test_the_known_part_is_what_the_machine_did(exact_run):
    """The arm's motion error and the loop's tracking error that diagnose-run
    predicts from the logs (the controller's model of the arm, the servo's
    settings, the logged corrections and loads) against the tool path of
    the simulated machine (Drake's plant with its gears, servo and
    interpolator; a file diagnose-run never reads)."""
    robot = run_robot(exact_run)
    sig = run_signals(rf.load_run_files(exact_run), robot, ArmModel(robot))
    lines = [ln for ln in (exact_run / "sim_timeseries_compensated.csv").read_text().splitlines()
             if not ln.startswith("#")]
    cols = lines[0].split(",")
    data = np.array([[float(v) for v in ln.split(",")] for ln in lines[1:]])
    t, dz = data[:, cols.index("t_s")], data[:, cols.index("tool_z_mm")] - data[:, cols.index("commanded_z_mm")]
    truth = np.interp(sig.t_s, t, dz)
    predicted = (sig.dz_motion_m + sig.dz_loop_m) * 1e3
    assert np.abs(truth).max() > 0.1  # the ramps' motion error: a tenth of a millimetre
    assert np.sqrt(np.mean((predicted - truth) ** 2)) < 0.1 * np.sqrt(np.mean(truth**2))


def test_the_lost_motion_law_takes_each_joints_take_up_torque(exact_run):
    """diagnose-run's smooth lost-motion law (what a smooth compensator's
    model predicts) takes each joint's take-up torque, the compensator's
    fallback from the model's compliance (18 N*m on joint 2, 3.3 N*m on
    joint 6), not 50 N*m for every joint; the lost_motion cause's columns
    are the hysteretic law's (the compensator's default), each joint's gear
    switching flanks where its total torque passes its friction (the same
    fallback, 1.5 % of the rated torque: 3.3 N*m on joint 6)."""
    from robstiff_drake.identification.runs.causes import candidates
    from robstiff_drake.model import play_hysteresis, transmission

    robot = run_robot(exact_run)
    files = rf.load_run_files(exact_run)
    files.settings.lost_motion_rad = [0.0, 1e-4, 0.0, 0.0, 0.0, 2e-4]
    assert files.settings.lost_motion_law == "hysteretic"  # (the scenario's default, as the run's compensator.yaml logs it)
    files.settings.lost_motion_law = "smooth"  # (the hysteretic law's prediction: tests/test_run_diagnosis_play_law.py)
    sig = run_signals(files, robot, ArmModel(robot))
    take_up = transmission.fallback_take_up_Nm(sig.compliance)
    assert take_up[1] == pytest.approx(18.15) and take_up[5] == pytest.approx(3.3)
    b = np.asarray(files.settings.lost_motion_rad)
    law = transmission.static_deflection(sig.tau_static_Nm, sig.tau_Nm, sig.compliance, b, 0.0, take_up)
    old = transmission.static_deflection(sig.tau_static_Nm, sig.tau_Nm, sig.compliance, b)  # 50 N*m
    np.testing.assert_allclose(sig.model_dq_rad, law, rtol=0, atol=1e-12)
    assert np.abs(sig.model_dq_rad - old).max() > 1e-7
    lost = next(c for c in candidates(sig) if c.name == "lost_motion")
    carried = sig.tau_static_Nm + sig.tau_inertia_Nm - sig.tau_Nm
    friction = transmission.gap_friction_Nm(1.0 / sig.compliance)
    assert friction[5] == pytest.approx(3.3)
    j = 5  # joint 6's column per unit b (b -> 0: the relay): -(p(t) - p(touch-off)) along the tool's vertical
    unit = np.eye(6)[j]
    p = p0 = play_hysteresis.start(sig.tau_touch_off_Nm, unit)
    relay = []
    for tau in carried:
        p = play_hysteresis.step(p, tau, unit, friction)
        relay.append(p[j])
    col = -sig.Jz[:, j] * (np.array(relay) - p0[j])
    np.testing.assert_allclose(lost.columns[:, j], col, rtol=1e-9, atol=1e-15)


def test_only_the_cell_files_are_read(exact_run, tmp_path, capsys):
    bare = tmp_path / "cell"  # what a real cell has: the four files and the run id
    bare.mkdir()
    for name in (*rt.CELL_FILES, "RUN_ID"):
        shutil.copy(exact_run / name, bare / name)
    a, b = diagnose(exact_run, capsys), diagnose(bare, capsys)
    assert a["rms_after_mm"] == b["rms_after_mm"] and a["causes"] == b["causes"] == []
    # what the logs predict (the arm's motion error, the loop's tracking error) explains the face to the noise
    assert a["rms_before_mm"] > 4 * a["noise_floor_mm"] and a["explains_data"] is True


def test_settings_without_the_servo_are_refused(exact_run, tmp_path, capsys):
    old = tmp_path / "old"
    shutil.copytree(exact_run, old)
    s = old / rt.SETTINGS
    text = s.read_text()
    s.write_text(text[:text.index("  # the robot controller's joint servo")])
    _, settings = rs.read_settings(s)  # a file written before the servo section is still read
    assert settings.servo is None
    err = _error_line(capsys, "diagnose-run", str(old))
    assert "compensator.yaml: compensator: no 'servo' section" in err and "interpolator_delay_ms" in err
    s.write_text(text.replace("    velocity_feedforward: 1.0", "    velocity_feedforward: 1.5"))
    assert "velocity_feedforward: expected a number from 0 to 1" in _error_line(capsys, "diagnose-run", str(old))


def test_the_servo_integral_corner_is_logged_and_read(exact_run, tmp_path):
    """The run's compensator.yaml carries the velocity loop's integral corner (the plant's drives are PI:
    diagnose-run's arm response needs it); a file written before it was logged reads the documented default."""
    from robstiff_drake.identification.runs.diagnosis import servo_of
    from robstiff_drake.model.servo import ServoParameters

    s = Path(exact_run) / rt.SETTINGS
    text = s.read_text()
    # the corner the plant's drives got (chosen below the arm's first antiresonance: about 1.2 Hz here)
    line = next(ln for ln in text.splitlines(keepends=True) if ln.startswith("    velocity_integral_hz: "))
    logged = float(line.split(":")[1])
    assert 0.5 < logged < 7.5, line
    _, settings = rs.read_settings(s)
    assert servo_of(settings).velocity_integral_hz == logged
    old = tmp_path / rt.SETTINGS
    old.write_text(text.replace(line, "    velocity_integral_hz: 12.0\n"))
    assert servo_of(rs.read_settings(old)[1]).velocity_integral_hz == 12.0
    old.write_text(text.replace(line, ""))
    assert servo_of(rs.read_settings(old)[1]).velocity_integral_hz == ServoParameters.velocity_integral_hz


def _error_line(capsys, *args):
    capsys.readouterr()
    code = main(list(args))
    _, err = capsys.readouterr()
    assert code == 2, err
    assert len(err.strip().splitlines()) == 1, err
    return err


def test_a_mixed_run_folder_is_refused(exact_run, tmp_path, capsys):
    mixed = tmp_path / "mixed"
    shutil.copytree(exact_run, mixed)
    scan = mixed / rt.SCAN
    scan.write_text(scan.read_text().replace("# run_id: ", "# run_id: 0", 1))
    err = _error_line(capsys, "diagnose-run", str(mixed))
    assert "scan.csv, line 1" in err and "mixes files of different runs" in err
    (mixed / "RUN_ID").unlink()
    assert "no RUN_ID file" in _error_line(capsys, "diagnose-run", str(mixed))


def test_bad_cell_files_get_one_line_with_file_line_and_column(exact_run, tmp_path, capsys):
    bad = tmp_path / "bad"
    shutil.copytree(exact_run, bad)
    w = bad / rt.WRENCH_LOG
    lines = w.read_text().splitlines()
    header = next(i for i, ln in enumerate(lines) if ln.startswith("t_s"))
    cells = lines[header + 3].split(",")
    cells[2] = "abc"
    lines[header + 3] = ",".join(cells)
    w.write_text("\n".join(lines) + "\n")
    err = _error_line(capsys, "diagnose-run", str(bad))
    assert f"wrench_log.csv, line {header + 4}, column 3" in err and "'abc' is not a number" in err
    shutil.copy(exact_run / rt.WRENCH_LOG, w)
    s = bad / rt.SETTINGS
    text = s.read_text()
    s.write_text(text.replace("    cutoff_hz:", "    cutof_hz:"))
    n = next(i for i, ln in enumerate(text.splitlines(), 1) if "cutoff_hz" in ln)
    err = _error_line(capsys, "diagnose-run", str(bad))
    assert f"compensator.yaml, line {n}, column 5" in err and "unknown key 'cutof_hz'" in err
    s.write_text(text.replace("  period_ms: ", "  period_ms: -"))
    assert "compensator.period_ms: must be > 0" in _error_line(capsys, "diagnose-run", str(bad))
    s.write_text(text + "plant:\n  damping_ratio: 0.1\n")
    assert "unknown top-level key 'plant'" in _error_line(capsys, "diagnose-run", str(bad))
    shutil.copy(exact_run / rt.SETTINGS, s)
    (bad / rt.JOINT_LOG).unlink()
    assert "missing joint_log.csv" in _error_line(capsys, "diagnose-run", str(bad))
    assert "no such run folder" in _error_line(capsys, "diagnose-run", str(tmp_path / "nope"))


def test_a_verification_cut_must_run_a_candidate(exact_run, tmp_path, capsys):
    _, settings = rs.read_settings(exact_run / rt.SETTINGS)
    settings.joint_stiffness_Nm_per_rad = [v * 1.1 for v in settings.joint_stiffness_Nm_per_rad]
    other = tmp_path / "other.yaml"
    other.write_text(rs.settings_text(settings, "x"))
    cut = simulate(tmp_path, PREDICTIVE, "cut", "--compensator", str(other), "--noise-seed", "7")
    err = _error_line(capsys, "diagnose-run", str(exact_run), "--verify", str(cut), "--out", str(tmp_path / "d"))
    assert "none of the candidate fixes" in err
    settings.tool_point_mm = [0.0, 0.0, 300.0]
    other.write_text(rs.settings_text(settings, "x"))
    assert "tool point" in _error_line(capsys, "simulate", str(exact_run / "sim_scenario.yaml"), "--compensator",
                                       str(other), "--out", str(tmp_path / "never"))
    settings.tool_point_mm = rs.read_settings(exact_run / rt.SETTINGS)[1].tool_point_mm
    settings.robot = "kr240_r2900"  # another robot's compensator, on this robot's run: refused, not run
    other.write_text(rs.settings_text(settings, "x"))
    err = _error_line(capsys, "simulate", str(exact_run / "sim_scenario.yaml"), "--compensator", str(other),
                      "--out", str(tmp_path / "never"))
    assert "compensator.robot is kr240_r2900" in err and "not the simulated robot irb6400" in err
    assert not (tmp_path / "never").exists()


# ---------------------------------------------------------------- formats and statistics, no simulation


def test_the_writers_and_readers_round_trip(tmp_path):
    rng = np.random.default_rng(3)
    t = np.arange(50) * 1e-3
    w = rng.normal(size=(50, 6)) * 100
    w[7] = np.nan  # a dropout
    settings = rs.CompensatorSettings(
        [1.5e6, 1.1e6, 8e5, 3e5, 3e5, 2e5], {"mass_kg": 40.0, "com_mm": [0.0, 0.0, 180.0],
                                             "force_bias_N": [3.0, -2.0, 5.0], "torque_bias_Nm": [0.2, -0.1, 0.05],
                                             "sensor_mount_rpy_deg": [0.0, 0.0, 1e-5]}, [0.0, 0.0, 350.0], 75.0,
        mode="predictive", delay_steps=2, lost_motion_rad=[1e-5, 0, 0, 0, 0, 0], coupling_c23_rad_per_Nm=-3e-8,
        servo={"interpolator_delay_ms": 18.0, "position_gain_per_s": 60.0, "velocity_bandwidth_hz": 30.0,
               "velocity_feedforward": 1.0})
    scan = rl.Scan(np.arange(30.0), np.full(30, 15.0), np.full(30, 700.0), 700.0 + rng.normal(size=30) * 3e-3, 0.003)
    files = {rt.WRENCH_LOG: rl.wrench_log_text(rl.WrenchLog(t, w), "r1"),
             rt.JOINT_LOG: rl.joint_log_text(rl.JointLog(t, rng.normal(size=(50, 6)), rng.normal(size=(50, 6))), "r1"),
             rt.SETTINGS: rs.settings_text(settings, "r1"), rt.SCAN: rl.scan_text(scan, "r1")}
    for name, text in files.items():
        (tmp_path / name).write_text(text)
    (tmp_path / "RUN_ID").write_text("r1\n")
    got = rf.load_run_files(tmp_path)
    assert got.run_id == "r1" and got.settings.same_as(settings) and got.settings.delay_steps == 2
    assert got.settings.servo["interpolator_delay_ms"] == 18.0
    settings.servo = None  # a file without the servo section reads back without it, and is not the same
    assert not got.settings.same_as(settings) and rs.read_settings(_written(tmp_path, settings))[1].servo is None
    assert np.isnan(got.wrench.wrench[7]).all() and np.allclose(got.wrench.wrench[8], w[8], rtol=1e-6)
    assert got.scan.noise_mm == 0.003 and np.allclose(got.scan.height_mm, scan.height_mm, atol=1e-6)
    # times must increase: the error names the row
    (tmp_path / rt.JOINT_LOG).write_text(files[rt.JOINT_LOG].replace("\n0.002,", "\n0.0005,", 1))
    with pytest.raises(InputError, match=r"joint_log.csv, line \d+, column 1: t_s 0.0005 is not after"):
        rf.load_run_files(tmp_path)


def _written(folder, settings):
    p = folder / "settings_only.yaml"
    p.write_text(rs.settings_text(settings, "r1"))
    return p


def test_scan_lines_along_y_and_along_a_path():
    """Pieces of a scan in any direction: a line along y, the same line
    scanned back, and a gap; lengths and the edges measured along them."""
    rng = np.random.default_rng(4)
    y = np.arange(-60.0, 60.0, 0.5)
    x = np.full_like(y, 1109.5)
    xs, ys = np.r_[x, x + 5.0, x], np.r_[y, y[::-1], y + 200.0]  # along y, back, then after a gap
    segs = ss.segments(xs, ys)
    assert [len(g) for g in segs] == [y.size] * 3
    assert ss.scan_length_mm(xs, ys, segs) == pytest.approx(3 * np.ptp(y))
    e = rng.normal(0, 0.003, xs.size)
    assert ss.noise_from_scan(e, segs) == pytest.approx(0.003, rel=0.15)
    e[:3] = 0.1  # a dip at the start of the first line: an edge along y
    st = ss.surface_stats(xs, ys, e, segs, 75.0)
    assert st["edges_max_abs"] == pytest.approx(0.1) and st["steady_max_abs"] < 0.02


def test_the_noise_floor_and_the_effective_points_of_a_scan():
    rng = np.random.default_rng(11)
    x = np.arange(0.0, 150.0, 0.5)  # mm
    face = 0.05 * np.sin(x / 20.0) + 0.02 * np.tanh((x - 40) / 5)  # a face that changes over millimetres
    sigma = 0.003
    segs = ss.segments(x, np.zeros_like(x))
    est = [ss.noise_from_scan(face + rng.normal(0, sigma, x.size), segs) for _ in range(20)]
    assert np.mean(est) == pytest.approx(sigma, rel=0.05) and np.std(est) < 0.1 * sigma
    white = rng.normal(0, sigma, x.size)
    n_eff, _ = ss.effective_points(white, segs, 150.0, 75.0)
    assert n_eff > 0.6 * x.size
    smooth = np.convolve(rng.normal(0, sigma, x.size + 99), np.ones(100) / 10, mode="valid")  # 50 mm correlation
    n_eff, _ = ss.effective_points(smooth, segs, 150.0, 75.0)
    assert 2.0 <= n_eff < x.size / 20
    two_lines = ss.segments(np.r_[x, x], np.r_[np.zeros_like(x), np.ones_like(x)])
    assert len(two_lines) == 2


def test_the_mean_square_difference_has_the_noise_standard_error():
    # Monte Carlo of two scans of the same face: the spread of the difference of their mean squares
    rng = np.random.default_rng(5)
    face, sigma = 0.01 * np.sin(np.arange(300) / 30.0), 0.003
    diffs = [ss.mean_square_difference(face + rng.normal(0, sigma, 300), face + rng.normal(0, sigma, 300), sigma)
             for _ in range(2000)]
    assert np.std([d for d, _ in diffs]) == pytest.approx(np.mean([s for _, s in diffs]), rel=0.1)


def _scan(error_mm, rng, sigma=0.003):
    x = np.arange(0.0, 120.0, 0.5)
    e = np.broadcast_to(error_mm, x.shape) + rng.normal(0, sigma, x.size)
    return rl.Scan(x, np.zeros_like(x), np.full(x.size, 700.0), 700.0 - e)


def test_the_cuts_decide_only_beyond_the_noise():
    rng = np.random.default_rng(8)
    before = _scan(0.05, rng)
    v = rv.decide(before, [("A", _scan(0.0, rng)), ("B", _scan(0.02, rng))], 0.003, 75.0)
    assert v["chosen"] == "A" and v["decided"]
    v = rv.decide(before, [("A", _scan(0.0, rng)), ("B", _scan(0.001, rng))], 0.003, 75.0)
    assert v["chosen"] is None and not v["decided"] and set([v["best"], *v["tied_with"]]) == {"A", "B"}
    v = rv.decide(_scan(0.001, rng), [("A", _scan(0.0, rng))], 0.003, 75.0)
    assert v["chosen"] is None and not v["vs_first_cut"]["better"]


def test_a_fix_whose_cut_is_worse_than_the_first_is_not_verified():
    """One candidate, cut once, worse than the first cut: the verdict is
    "no fix better than the first cut", never "verified" (not even in part)."""
    from robstiff_drake.identification.runs.diagnosis import _verified_fix

    report = {"candidates": [{"name": "lost_motion", "params": {"lost_motion": {}}, "changes": ["x"],
                              "settings": "candidates/lost_motion/compensator.yaml"}]}
    verdict = {"chosen": None, "decided": False, "best": "lost_motion", "tied_with": [],
               "vs_first_cut": {"better": False}, "reason": "no candidate's cut is better than the first cut"}
    assert _verified_fix(report, verdict)["status"] == "no fix better than the first cut"
    verdict["vs_first_cut"]["better"] = True
    verdict["tied_with"] = ["stiffness_error_j3"]
    report["candidates"].append({"name": "stiffness_error_j3", "params": {"lost_motion": {}, "x": {}}})
    assert _verified_fix(report, verdict)["status"].startswith("verified in part: lost_motion")
