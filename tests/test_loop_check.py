"""`robstiff compensate`'s loop check (model/loop_check.py, cell/loop_guard.py):
the linear loop model's stable/unstable verdict against a short run of the
Drake cell (a plant the model does not share: the multibody arm, its
discrete scheme, the Drake compensator), its constants against the scenario
they come from, and the refusal and the override as a user meets them."""

import json
import os
import socket
import sys

import numpy as np
import pytest

from robstiff_drake.model import loop_check
from robstiff_drake.model.filters import lowpass_coefficients

sys.path.insert(0, os.path.dirname(__file__))
import cell_helpers as h  # noqa: E402


@pytest.fixture(scope="module")
def block():
    from robstiff_drake.diagrams.scenario import load_scenario, scenario_robot
    from robstiff_drake.paths import DIAGRAMS_DIR

    sc = load_scenario(DIAGRAMS_DIR / "block_milling.yaml")
    return sc, scenario_robot(sc, None)


def test_the_nominal_process_stiffness_is_the_block_pass(block):
    from robstiff_drake.diagrams.loop_prediction import mid_pass_process_stiffness

    Kp = mid_pass_process_stiffness(block[0])
    np.testing.assert_allclose(loop_check.NOMINAL_PROCESS_STIFFNESS_N_PER_M, np.round(Kp / 1e3, 1) * 1e3, atol=1e-9)
    # turned to a feed along +y: the feed's column goes with it
    Ky = loop_check.process_stiffness_along([0.0, 1.0])
    np.testing.assert_allclose(Ky[1, 2], loop_check.NOMINAL_PROCESS_STIFFNESS_N_PER_M[0, 2], rtol=1e-12)


def test_the_numpy_arm_is_drakes(block):
    """The check's mass matrix and weight stiffness (arm_dynamics, numpy)
    are those of Drake's plant at the block's start pose."""
    from robstiff_drake.diagrams.compliant_arm import controller_model, gravity_stiffness
    from robstiff_drake.diagrams.loop_prediction import scenario_loop_setup

    sc, robot = block
    setup = scenario_loop_setup(sc, robot)
    jm, _, _ = setup.arm(0.05)
    plant = controller_model(robot)
    ctx = plant.CreateDefaultContext()
    G = gravity_stiffness(plant, ctx, setup.q_rad)
    plant.SetPositions(ctx, setup.q_rad)
    np.testing.assert_allclose(jm.M, plant.CalcMassMatrix(ctx), rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(jm.G, G, rtol=1e-6, atol=1e-3)


def test_the_model_verdict_agrees_with_the_drake_cell(block):
    """At 2 Hz the model's loop (the plant's 5 % damping, on the
    drives-closed modes) is stable and at 20 Hz unstable; the Drake cell
    held in air and kicked decays at 2 Hz and grows at 20 Hz, at rates
    within 0.2 1/s of the model's ln(radius) / T (measured: -1.70 against
    -1.69, +0.11 against +0.13; with the damping stated on the motors-held
    modes and the integral corner at 7.5 Hz, 10 Hz grew at +0.27)."""
    from robstiff_drake.diagrams.hold_response import hold_response
    from robstiff_drake.diagrams.loop_prediction import scenario_loop_setup
    from robstiff_drake.diagrams.scenario_models import plant_damping_ratios

    sc, robot = block
    setup = scenario_loop_setup(sc, robot)
    T = sc.controller.period_ms / 1e3
    for f, unstable in ((2.0, False), (20.0, True)):
        ba = lowpass_coefficients(f, sc.sensor.rate_hz, sc.controller.filter.order)
        radius = setup.radius(ba, np.zeros((3, 3)), plant_damping_ratios(sc))
        assert (radius > 1.0) == unstable, (f, radius)
        run = hold_response(sc, robot, f, seconds=3.0)
        assert run.grows == unstable, (f, run)
        assert run.growth_per_s == pytest.approx(np.log(radius) / T, abs=0.2), (f, run, radius)
        # the envelope moved by a factor that no noise floor explains
        ratio = run.envelope_rad[-1] / run.envelope_rad[2]
        assert (ratio > 1.1) if unstable else (ratio < 0.3), (f, run.envelope_rad)


def test_the_margin_refuses_what_is_stable_only_at_the_assumed_damping(block):
    """5 Hz on the block: stable at the plant's 5 % (and in Drake, the
    study), refused by the check's 2 % margin; 2 Hz passes both."""
    from robstiff_drake.diagrams.loop_prediction import scenario_loop_setup

    sc, robot = block
    setup = scenario_loop_setup(sc, robot)
    modes = {"air": np.zeros((3, 3)), "cutting": loop_check.NOMINAL_PROCESS_STIFFNESS_N_PER_M}
    v5 = loop_check.check(setup, lowpass_coefficients(5.0, sc.sensor.rate_hz, 2), modes, cutoff_hz=5.0)
    assert max(v5.radius_assumed.values()) < 1.0 < max(v5.radius.values())
    assert v5.unstable and 3.0 <= v5.largest_stable_cutoff_hz < 5.0
    ba = lowpass_coefficients(v5.largest_stable_cutoff_hz, sc.sensor.rate_hz, 2)
    assert not loop_check.check(setup, ba, modes).unstable  # the cutoff it names passes
    assert not loop_check.check(setup, lowpass_coefficients(2.0, sc.sensor.rate_hz, 2), modes).unstable


# ------------------------------------------------------------ compensate: the refusal and the override


def _one_error_line(stderr):
    lines = [ln for ln in stderr.splitlines() if ln.startswith("robstiff")]
    errors = [ln for ln in lines if "error:" in ln]
    assert len(errors) == 1 and "Traceback" not in stderr, stderr
    return errors[0]


def test_an_unstable_loop_is_refused_before_any_socket(tmp_path, monkeypatch, capsys):
    pytest.importorskip("pynetft", reason="compensate needs pynetft (pip install '.[test]')")
    from robstiff_drake.commands.main import main
    from robstiff_drake.model.robot import load_robot

    model, payload, ref, _ = h.write_inputs(str(tmp_path), load_robot(), duration_s=0.5)

    def no_socket(*a, **kw):
        raise AssertionError("a socket was opened")

    monkeypatch.setattr(socket, "socket", no_socket)
    code = main(["compensate", "--egm-port", "6510", "--netft", "127.0.0.1:49152", "--model", model, "--payload",
                 payload, "--reference", ref, "--cutoff-hz", "10", "--log", str(tmp_path / "run")])
    err = capsys.readouterr().err
    assert code == 2
    line = _one_error_line(err)
    for words in ("UNSTABLE in air and cutting", "start pose", "reference.csv's first row", "0.00, 13.62, 21.95",
                  "spectral radius 1.00", "--cutoff-hz 10", "the largest cutoff the model finds stable is 3.",
                  "--allow-unstable-loop"):
        assert words in line, line
    assert not (tmp_path / "run").exists()
    # the cutoff it names is accepted (the check passes, then the sockets open: here refused by the stub)
    best = line.split("(--cutoff-hz ")[1].split(")")[0]
    with pytest.raises(AssertionError, match="a socket was opened"):
        main(["compensate", "--egm-port", "6510", "--netft", "127.0.0.1:49152", "--model", model, "--payload",
              payload, "--reference", ref, "--cutoff-hz", best])
    assert "the correction loop is stable at the start pose" in capsys.readouterr().err


def test_an_unstable_hold_is_refused_with_only_zero_correction_sent(tmp_path):
    """Without --reference the check runs at the hold pose off the loop's
    thread while the controller is answered with its own pose (its first
    answer within the cycle: cell/start_gate.py); its refusal ends the run
    before any correction, the earlier log folder untouched."""
    pytest.importorskip("pynetft", reason="the cell tests need pynetft (pip install '.[test]')")
    cp, stats, log = h.run_compensate_against_cell(tmp_path, duration_s=1.0, extra=["--cutoff-hz", "10"])
    assert cp.returncode == 2, cp.stderr
    line = _one_error_line(cp.stderr)
    assert "UNSTABLE" in line and "the hold pose, the controller's first message" in line, line
    assert "nothing but zero correction (the controller's own pose) was answered" in line, line
    assert not os.path.exists(log)
    q = np.asarray(stats.q_cmd)  # every command the controller followed: its start pose
    assert len(q) and np.max(np.abs(q - q[0])) < 1e-9, np.max(np.abs(q - q[0]))


def test_the_override_runs_with_a_loud_warning(tmp_path):
    pytest.importorskip("pynetft", reason="the cell tests need pynetft (pip install '.[test]')")
    cp, stats, log = h.run_compensate_against_cell(tmp_path, duration_s=1.0, stream_reference=True,
                                                   extra=["--cutoff-hz", "10", "--allow-unstable-loop"])
    assert cp.returncode == 0, cp.stderr
    warn = [ln for ln in cp.stderr.splitlines() if ln.startswith("robstiff: warning: compensate: --allow-unstable")]
    # at the start pose, then along the reference (its worst pose named by its row)
    assert len(warn) == 2 and all("UNSTABLE in air and cutting" in w for w in warn), cp.stderr
    assert "at the start pose" in warn[0] and "along --reference reference.csv at row " in warn[1], warn
    with open(os.path.join(log, "summary.json")) as f:
        summary = json.load(f)
    assert summary["loop_check"]["overridden"] is True
    assert summary["loop_check"]["unstable_modes"] == ["air", "cutting"]
    assert summary["loop_check"]["along_path"]["unstable_modes"] == ["air", "cutting"]
    assert any("--allow-unstable-loop" in w and "UNSTABLE" in w for w in summary["warnings"])
    with open(os.path.join(log, "events.csv")) as f:
        assert "--allow-unstable-loop: running anyway" in f.read()


def test_a_stable_run_logs_its_check(tmp_path):
    pytest.importorskip("pynetft", reason="the cell tests need pynetft (pip install '.[test]')")
    cp, stats, log = h.run_compensate_against_cell(tmp_path, duration_s=1.0, stream_reference=True,
                                                   extra=["--servo", "12,60,30,1", "--cutter-diameter-mm", "75"])
    assert cp.returncode == 0, cp.stderr
    assert "warning: compensate: --allow" not in cp.stderr
    with open(os.path.join(log, "summary.json")) as f:
        check = json.load(f)["loop_check"]
    assert check["unstable_modes"] == [] and check["overridden"] is False
    assert max(check["spectral_radius"].values()) < 1.0  # (the default 2 Hz cutoff)
    assert check["pose"].startswith("--reference")
    np.testing.assert_allclose(check["feed_direction_xy"], [1.0, 0.0], atol=1e-6)  # the pass runs along +x
    along = check["along_path"]  # and at poses along the reference, the last row among them
    assert along["unstable_modes"] == [] and len(along["rows_checked"]) >= 5
    assert max(along["spectral_radius"].values()) < 1.0

    # the run folder keeps its inputs, as a simulated run's does (docs/run_files.md), and names the kept robot
    from robstiff_drake.commands.diagnose_run import run_robot_and_file

    kept = sorted(os.listdir(os.path.join(log, "inputs")))
    assert kept == ["irb6400.yaml", "model.json", "payload.yaml", "reference.csv"], kept
    for name in ("model.json", "payload.yaml", "reference.csv"):
        with open(os.path.join(log, "inputs", name), "rb") as a, open(os.path.join(str(tmp_path), name), "rb") as b:
            assert a.read() == b.read(), name
    robot, robot_file = run_robot_and_file(log)
    assert robot.name == "irb6400" and os.path.samefile(robot_file, os.path.join(log, "inputs", "irb6400.yaml"))


def test_the_loop_is_checked_along_the_path_not_only_at_its_start():
    """A reference from a pose where a 3.5 Hz filter's loop is stable to one
    where it is not (the IRB 6400 reaching out: the arm's first mode lower
    and its payload's inertia larger on the sensor): the start passes, the
    path is refused in one line naming its row, time, pose and radius, and
    the override records the worst pose."""
    from robstiff_drake.cell.loop_guard import LoopGuard
    from robstiff_drake.errors import InputError
    from robstiff_drake.model.robot import load_robot

    robot = load_robot("irb6400")
    start, end = np.array([0, 13.6, 22, 0, 54, 0.0]), np.array([0, 45, -10, 0, 55, 0.0])
    rows = start + np.linspace(0.0, 1.0, 1001)[:, None] * (end - start)

    def guard(allow):
        return LoopGuard(robot=robot, k_Nm_per_rad=robot.joint_stiffness_Nm_per_rad, servo=None, sensor_rate_hz=1000.0,
                         period_s=0.004, delay_steps=0, filter_kind="lowpass",
                         filter_ba=lowpass_coefficients(3.5, 1000.0, 2), cutoff_hz=3.5, filter_order=2,
                         allow_unstable=allow)

    g = guard(False)
    assert "is stable at the start pose" in g.at(rows[0], "the test's first row")
    with pytest.raises(InputError) as e:
        g.along(rows, "the test path", 0.004)
    msg = str(e.value)
    assert "\n" not in msg and "UNSTABLE" in msg, msg
    assert "along the test path at row 1001, t = 4.00 s: 0.00, 45.00" in msg, msg
    assert "spectral radius 1.00" in msg and "--cutoff-hz" in msg and "nothing was sent" in msg, msg
    g = guard(True)
    g.at(rows[0], "the test's first row")
    assert g.along(rows, "the test path", 0.004).startswith("--allow-unstable-loop: running anyway")
    along = g.result["along_path"]
    assert along["worst_row"] == 1001 and g.result["overridden"] is True
    radii = along["spectral_radius_by_row"]
    assert radii[1001] > 1.0 > g.result["spectral_radius"]["cutting"]  # the start's own verdict: stable
    # a path that stays near its start passes and names its worst pose
    g = guard(False)
    g.at(rows[0], "the test's first row")
    assert "is stable along the short path" in g.along(rows[:50], "the short path", 0.004)
