"""The sampling-delay study: sweep runner, Dask path, the loop model, and
predictive compensation."""

import json
from pathlib import Path

import numpy as np
import pytest

from robstiff_drake.commands.main import main
from robstiff_drake.diagrams.scenario import load_scenario
from robstiff_drake.diagrams.sweep import combinations, run_one, run_sweep
from robstiff_drake.model.loop_model import LoopModel

ROOT = Path(__file__).parents[1]
SHORT = Path(__file__).parent / "data" / "short_block.yaml"
INTERRUPTED = ROOT / "diagrams" / "interrupted_cut.yaml"


def cli(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def test_sweep_cli_rows_and_plot(capsys, tmp_path):
    out = tmp_path / "sweep.json"
    png = tmp_path / "sweep.png"
    code, text, err = cli(capsys, "sweep", SHORT, "--period-ms", "4,24", "--cutoff-hz", "5", "--mode",
                          "plain,predictive", "--workers", "2", "--json", out, "--plot", png)
    assert code == 0, err
    res = json.loads(out.read_text())
    assert res["complete"] and res["n_runs"] == 4
    # the cut checked for chatter once, before the runs (diagrams/chatter_check.py), its warning when unstable
    chk = res["chatter_check"]
    assert chk is not None and chk["poses_checked"] > 0
    assert any(w.startswith("chatter:") for w in res["warnings"]) == (not chk["stable"])
    for row in res["runs"]:
        assert {"period_ms", "delay_steps", "cutoff_hz", "mode", "surface_error_mm", "stable", "predicted"} <= set(row)
        assert {"mean", "rms", "max_abs", "pv", "entry_max_abs", "exit_max_abs"} <= set(row["surface_error_mm"])
        assert row["stable"] is True
        # the run's own vibration (simulate's check, diagrams/run_vibration.py): the default plant's, no warning
        v = row["vibration"]
        assert v["cut_s"][1] > v["cut_s"][0] and 0.0 <= v["amplitude_um"] < 0.5 * v["feed_per_tooth_um"], v
    assert not any("the simulated cut vibrated" in w for w in res["warnings"]), res["warnings"]
    plain = {r["period_ms"]: r for r in res["runs"] if r["mode"] == "plain"}
    # a longer period costs accuracy at the engagement changes
    assert plain[24.0]["surface_error_mm"]["entry_max_abs"] > plain[4.0]["surface_error_mm"]["entry_max_abs"]
    assert png.read_bytes()[:4] == b"\x89PNG"
    assert "period" in text and "predictive" in text
    # before any run, what is about to run: 2 periods x 1 delay x 1 cutoff x 2 modes on 2 processes
    first = text.splitlines()[0]
    assert first.startswith("sweep: 4 closed-loop runs (2 period(s) x 1 delay(s) x 1 cutoff(s) x 2 mode(s))"), first
    assert "on 2 local process(es)" in first


def test_the_plan_line_counts_runs_and_simulated_time():
    """The line a sweep prints before it starts: the number of runs, the
    simulated seconds each (the scenario's path and its run-out) and in
    all, and where they run."""
    from robstiff_drake.commands.sweep import plan_line
    from robstiff_drake.diagrams.experiment import RUN_OUT_S
    from robstiff_drake.diagrams.scenario import planned_path

    sc = load_scenario(SHORT)
    combos = combinations([4, 8, 16, 32], [0, 1], [2, 5], ["plain", "predictive"])
    each = planned_path(sc).duration_s + RUN_OUT_S
    line = plan_line(sc, combos, [4, 8, 16, 32], [0, 1], [2, 5], ["plain", "predictive"], 3, None)
    assert line.startswith("sweep: 32 closed-loop runs (4 period(s) x 2 delay(s) x 2 cutoff(s) x 2 mode(s)), ")
    assert f"{each:.1f} s simulated each, {32 * each / 60:.1f} min simulated in all, on 3 local process(es)" in line
    assert "on the Dask cluster at tcp://h:8786" in plan_line(sc, combos, [4], [0], [2], ["plain"], None,
                                                              "tcp://h:8786")


def test_failed_run_is_a_row(tmp_path):
    bad = tmp_path / "missing.yaml"
    row = run_one(str(bad), {"period_ms": 4.0, "delay_steps": 1, "cutoff_hz": 5.0, "mode": "plain"}, predict=False)
    assert row["stable"] is False and "no such scenario file" in row["error"]
    rows = run_sweep(SHORT, combinations([4.0], [1], [5.0], ["plain"]) + [
        {"period_ms": 4.0, "delay_steps": 1, "cutoff_hz": 5.0, "mode": "sideways"}], workers=1, predict=False)
    assert rows[0]["stable"] is True and "error" not in rows[0]
    assert rows[1]["stable"] is False and "mode" in rows[1]["error"]


@pytest.mark.parametrize(
    "argv, message",
    [
        (["--period-ms", ""], "expected a comma-separated list"),
        (["--period-ms", "4,,8"], "expected a comma-separated list"),
        (["--period-ms", "4,x"], "'x' is not a number"),
        (["--period-ms", "4,-8"], "values must be > 0"),
        (["--period-ms", "1", "--plant-step-ms", "2"], "period 1 ms is below the plant step (2 ms)"),
        (["--period-ms", "16", "--plant-step-ms", "16"], "a 16 ms plant step is unstable for the arm's 126 Hz mode"),
        (["--period-ms", "4", "--delay-steps", "1.5"], "'1.5' is not a whole number"),
        (["--period-ms", "4", "--cutoff-hz", "700"], "cutoff 700 Hz must be between 0 and half the sensor rate"),
        (["--period-ms", "4", "--mode", "plain,clever"], "expected plain and/or predictive"),
        (["--period-ms", "4", "--scheduler", "tcp://127.0.0.1:9"], "cannot reach the Dask scheduler"),
    ],
)
def test_sweep_bad_input(capsys, tmp_path, argv, message):
    out = tmp_path / "x.json"
    code, _, err = cli(capsys, "sweep", SHORT, *argv, "--json", out, "--workers", "1", "--no-predict")
    assert code == 2
    lines = err.strip().splitlines()  # one line; a refused plant step's why after it, indented (main.py)
    assert lines[0].startswith("robstiff: error: ") and message in lines[0], err
    assert all(ln.startswith("  why: " if i == 1 else "       ") for i, ln in enumerate(lines) if i), err
    assert not out.exists()  # no partial JSON presented as complete


def test_a_period_below_the_scenarios_plant_step_sets_the_step_of_every_run(capsys):
    """`sweep --period-ms 2,4,8,16` on a scenario stepped at 4 ms (docs/your_robot.md) runs every
    combination at a 2 ms plant step, and says so; an explicit --plant-step-ms is kept as given."""
    from types import SimpleNamespace

    from robstiff_drake.commands.sweep import shortest_period_step

    sc = SimpleNamespace(plant_config=SimpleNamespace(time_step=0.004))
    assert shortest_period_step(sc, [2.0, 4.0, 8.0, 16.0]) == 2.0
    assert "plant step 2 ms for every run (the scenario's 4 ms" in capsys.readouterr().out
    assert shortest_period_step(sc, [4.0, 8.0]) is None and capsys.readouterr().out == ""


def test_dask_cluster_on_loopback(tmp_path):
    import distributed  # a test dependency (pyproject's [test] extra): the Dask path must be tested
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                                  dashboard_address=None) as cluster:
        assert cluster.scheduler_address.startswith("tcp://127.0.0.1:")
        combos = combinations([4.0, 8.0], [1], [5.0], ["plain"])
        rows = run_sweep(SHORT, combos, scheduler=cluster.scheduler_address, predict=False)
    local = run_sweep(SHORT, combos[:1], workers=1, predict=False)
    assert [r["period_ms"] for r in rows] == [4.0, 8.0]
    assert all(r["stable"] for r in rows)
    # the same run gives the same answer on the cluster and locally (deterministic, seeded noise)
    assert rows[0]["surface_error_mm"] == pytest.approx(local[0]["surface_error_mm"], rel=1e-9)


def test_predictive_halves_entry_exit_error_at_24ms(robot):
    from robstiff_drake.diagrams.sweep import run_one

    common = {"period_ms": 24.0, "delay_steps": 1, "cutoff_hz": 5.0}
    plain = run_one(str(INTERRUPTED), dict(common, mode="plain"), predict=False)
    pred = run_one(str(INTERRUPTED), dict(common, mode="predictive"), predict=False)
    sp, sq = plain["surface_error_mm"], pred["surface_error_mm"]
    zone_plain = max(sp["entry_max_abs"], sp["exit_max_abs"])
    zone_pred = max(sq["entry_max_abs"], sq["exit_max_abs"])
    assert zone_plain >= 0.05  # the scenario's design: lag matters here
    assert zone_pred <= 0.5 * zone_plain
    assert sq["steady_max_abs"] <= sp["steady_max_abs"] + 0.002  # steady error no worse (2 um noise allowance)


def test_predictive_with_a_wrong_model_still_compensates(tmp_path):
    text = INTERRUPTED.read_text().replace("model:", "model_unused:") + "model:\n  force_model_scale: 1.3\n"
    path = tmp_path / "wrong_model.yaml"
    path.write_text(text)
    row = run_one(str(path), {"period_ms": 4.0, "delay_steps": 1, "cutoff_hz": 5.0, "mode": "predictive"},
                  predict=False)
    s = row["surface_error_mm"]
    assert row["stable"] and abs(s["mean"]) < 0.1  # the measured residual pulls a 30 % model error back


def _simple_loop(**kw):
    M = np.diag([50.0, 80.0, 40.0, 5.0, 3.0, 1.0])
    K = np.full(6, 1e6)
    J = np.eye(6)
    args = dict(M=M, K=K, beta_s=0.002, J=J, C_model=1.0 / K, filter_ba=(np.array([1.0]), np.array([1.0])),
                rate_hz=1000.0, period_s=0.004, delay_steps=1)
    args.update(kw)
    return LoopModel(**args)


def test_loop_model_static_compensation_is_exact():
    """With no process stiffness, a constant load and an exact model, the
    loop settles with the deflection cancelled."""
    loop = _simple_loop()
    t = np.arange(0, 3.0, loop.h)
    W = np.tile([200.0, -100.0, 50.0, 0, 0, 0], (len(t), 1))
    dev = loop.simulate(t, W, np.zeros((len(t), 3, 3)), np.zeros_like(W))
    assert np.abs(dev[:60]).max() > 1e-4  # deflected before the correction acts
    np.testing.assert_allclose(dev[-1], 0.0, atol=1e-9)
    _, radius = loop.poles(np.zeros((3, 3)))
    assert radius < 1


def test_loop_model_finds_an_unstable_loop():
    """A process stiffness that pushes the tool further into the cut than
    the arm can hold (K_p above the joint stiffness) has a pole outside."""
    loop = _simple_loop()
    _, radius_ok = loop.poles(-2e5 * np.eye(3))
    _, radius_bad = loop.poles(2e6 * np.eye(3))
    assert radius_ok < 1 < radius_bad


def test_loop_model_predicts_the_simulation(robot, tmp_path):
    """The loop model (the compensator's linear, revolution-averaged cut, its chip from the plan) against the
    simulation on the plant's own cutting law (model/plant_cutting.py: the chip from the tool's actual progress,
    Kienzle, worn edge, runout), interrupted_cut at 24 ms.  The model over-predicts the entry/exit error, as it
    must: a tool held back at a rib's entry cuts a thinner chip (a damping along the feed the model lacks), so
    the simulation's largest entry/exit error is 0.091 mm on the plant's law (0.090 on the linear law,
    ``cutting.plant_law: linear``; 0.105 with the chip from the plan) against the model's 0.120 mm.  The band:
    the model at or above the simulation, by at most 40 % (0.120 / 0.091 = 1.32)."""
    from robstiff_drake.diagrams.loop_prediction import predict

    sc = load_scenario(INTERRUPTED)
    assert sc.cutting.plant_law == "rich"
    combo = {"period_ms": 24.0, "delay_steps": 1, "cutoff_hz": 5.0, "mode": "plain"}
    p = predict(sc, robot, combo)
    row = run_one(str(INTERRUPTED), combo, predict=False)
    sim = max(row["surface_error_mm"]["entry_max_abs"], row["surface_error_mm"]["exit_max_abs"])
    model = max(p["surface_error_mm"]["entry_max_abs"], p["surface_error_mm"]["exit_max_abs"])
    assert sim <= model <= 1.4 * sim, (model, sim)  # 0.120 against 0.091 mm: the chip's damping (docstring)
    assert p["surface_error_mm"]["mean"] == pytest.approx(row["surface_error_mm"]["mean"], rel=0.25)  # 0.063 / 0.060
    assert p["first_order_lag_error_mm"] == pytest.approx(sim, rel=0.5)  # 0.118 / 0.091


def test_payload_inertia_map_is_what_drake_reports_at_the_weld(robot, rng):
    """L q'' (loop model) against Drake: a continuous plant at rest driven to
    the joint accelerations q''; the weld's reaction minus the static one is
    the payload's inertial wrench, moved to the tool point in the base frame."""
    from pydrake.multibody.plant import MultibodyPlant

    from robstiff_drake.diagrams.loop_prediction import payload_inertial_wrench_map
    from robstiff_drake.model import kinematics as kin
    from robstiff_drake.model.wrench_frames import sensor_to_tool_base
    from robstiff_drake.plant import add_irb6400

    plant = MultibodyPlant(0.0)
    add_irb6400(plant)
    plant.Finalize()
    weld = plant.GetJointByName("sensor_weld").index()
    q = np.deg2rad([10.0, 20.0, 15.0, 30.0, 40.0, -25.0])
    R = kin.frames(robot.dh, q)[6, :3, :3]

    def reading(qdd):
        ctx = plant.CreateDefaultContext()
        plant.SetPositions(ctx, q)
        tau = plant.CalcMassMatrix(ctx) @ qdd - plant.CalcGravityGeneralizedForces(ctx)
        plant.get_actuation_input_port().FixValue(ctx, tau)
        F = plant.get_reaction_forces_output_port().Eval(ctx)[weld]
        return -np.concatenate([F.translational(), F.rotational()])  # the payload on the sensor

    L = payload_inertial_wrench_map(robot, q)
    static = reading(np.zeros(6))
    for _ in range(3):
        qdd = rng.normal(0.0, 2.0, 6)
        inertial = sensor_to_tool_base(reading(qdd) - static, R, robot.payload.tool_point_m)
        np.testing.assert_allclose(inertial, L @ qdd, atol=1e-6 * max(1.0, np.abs(L @ qdd).max()))
    assert np.abs(L).max() > 10  # 40 kg: not negligible


def test_loop_model_needs_the_payload_inertia_at_a_resonance(robot, tmp_path):
    """5 % damping on every mode, 2 ms, 50 Hz: the plain compensation loop
    grows at the arm's second mode (7.5 Hz: the sensor reads the payload's
    inertia as cutting load, and the chain feeds it back); the loop model
    follows the simulation to 50 % with the inertia in its sensor, and
    without it calls the loop stable and misses the error by more than 6x
    (the compensator holding the plant's own model, as the loop model does).
    On the plant with the 5 % stated on the drives-closed modes: 0.76 mm
    simulated, 0.86 the model, 0.078 blind (9.7x); stated on the
    motors-held modes (3.6 % on the first with the drives closed) the ring
    grew faster: above 1 mm, blind more than 10x below."""
    from robstiff_drake.diagrams import loop_prediction

    path = tmp_path / "interrupted_cut.yaml"
    path.write_text((ROOT / "diagrams" / "interrupted_cut.yaml").read_text() + "model:\n  source: nominal\n")
    sc = load_scenario(path)
    combo = {"period_ms": 2.0, "delay_steps": 1, "cutoff_hz": 50.0, "mode": "plain"}
    row = run_one(str(path), combo, predict=False)
    sim = max(row["surface_error_mm"]["entry_max_abs"], row["surface_error_mm"]["exit_max_abs"])
    assert sim > 0.5  # mm: it rings (the settled cut leaves under 0.1 mm)
    p = loop_prediction.predict(sc, robot, combo)
    # a growing oscillation's size at the window's end, on the plant's own cutting law: its chip follows the
    # tool's vibration along the feed and slows the growth the model (the compensator's law, the chip from the
    # plan) predicts: 0.86 mm against 0.76 (on the plant with the damping on the motors-held modes: 4.25 mm
    # against 2.30, 1.84 on the linear law, cutting.plant_law: linear)
    model = max(p["surface_error_mm"]["entry_max_abs"], p["surface_error_mm"]["exit_max_abs"])
    assert sim / 1.5 < model < 3.0 * sim, (model, sim)
    assert p["spectral_radius"] > 1.0
    blind = loop_prediction.predict(sc, robot, combo, sensor_feels_inertia=False)
    assert blind["spectral_radius"] < 1.0
    assert max(blind["surface_error_mm"]["entry_max_abs"], blind["surface_error_mm"]["exit_max_abs"]) < sim / 6


@pytest.mark.parametrize("key, content, message", [
    ("identified_json", "q1,q2\n1,2\n", "not a JSON file"),
    ("identified_json", '{"joint_stiffness_Nm_per_rad": [1, 2]}', "expected six finite stiffnesses"),
    ("payload_yaml", "payload_calibration: [1, 2]\n", "m.txt"),
])
def test_a_broken_model_file_named_by_the_scenario_is_refused_before_any_run(capsys, tmp_path, key, content,
                                                                             message):
    """A scenario whose model.identified_json or model.payload_yaml cannot be
    read ran every combination and failed each (exit 0, a JSON of failed
    rows); it is one line and exit 2 before any run, as simulate does."""
    (tmp_path / "m.txt").write_text(content)
    sc = tmp_path / "s.yaml"
    sc.write_text(SHORT.read_text().replace("  source: nominal\n", f"  source: identified\n  {key}: m.txt\n", 1))
    out = tmp_path / "x.json"
    code, _, err = cli(capsys, "sweep", sc, "--period-ms", "4", "--json", out, "--workers", "1", "--no-predict")
    assert code == 2, err
    assert len(err.strip().splitlines()) == 1 and message in err, err
    assert not out.exists()


def test_a_stopped_pool_has_no_manager_thread_left_for_the_interpreters_exit():
    """sweep's _stop leaves the pool's manager thread ended and its wake-up
    pipe closed, so Python 3.11's exit hook (which wakes it without the pool's
    lock) cannot meet the pipe mid-close: seen once in CI as "Exception
    ignored ... OSError: [Errno 9] Bad file descriptor" after "robstiff:
    terminated".  (A race: before the fix this held or not by timing.)"""
    import time
    from concurrent.futures import ProcessPoolExecutor

    from robstiff_drake.diagrams.sweep import _stop, _worker_init

    pool = ProcessPoolExecutor(max_workers=2, initializer=_worker_init)
    futures = [pool.submit(time.sleep, 60) for _ in range(4)]
    while not any(f.running() for f in futures):
        time.sleep(0.01)
    manager, wakeup = pool._executor_manager_thread, pool._executor_manager_thread_wakeup
    _stop(pool)
    assert not manager.is_alive() and wakeup._closed
