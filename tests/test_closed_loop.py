"""The assembled closed loop: static deflection of the compliant plant, the
chain's timing, a short cut both ways, bad samples, bad scenarios."""

import copy
from pathlib import Path

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder, LeafSystem
from pydrake.systems.primitives import ConstantVectorSource

from robstiff_drake.diagrams.experiment import run_cut
from robstiff_drake.diagrams.compensator import make_compensator
from robstiff_drake.diagrams.scenario import load_scenario
from robstiff_drake.errors import InputError
from robstiff_drake.model.payload import PayloadCalibration

DATA = Path(__file__).parent / "data"
SHORT = DATA / "short_block.yaml"


class StepWrench(LeafSystem):
    """w0 before t0, w0 + step from t0 on (a function of time, no state)."""

    def __init__(self, w0, step, t0):
        super().__init__()
        self.DeclareVectorOutputPort("w", 6, lambda c, o: o.SetFromVector(w0 + (c.get_time() >= t0) * step))


@pytest.mark.parametrize("delay_steps", [0, 1, 2])
def test_chain_delay_is_what_the_design_says(robot, delay_steps):
    """A wrench step just after a sensor sample at 10.5 ms: the guard takes
    it at 11 ms, the ZOH at the 12 ms tick, then the delay block's n ticks
    and the correction's own tick: the correction first moves at
    12 + 4 (n + 1) ms."""
    T, rate = 0.004, 1000.0
    q = np.deg2rad([0.0, 13.6, 22.0, 0.0, 54.4, 0.0])
    tool = robot.payload.tool_point_m
    comp = make_compensator(rate_hz=rate, filter_ba=(np.array([1.0]), np.array([1.0])), max_jump_N=1e6, period_s=T,
                            delay_steps=delay_steps, saturation_rad=0.1, rate_limit_rad_per_s=10.0,
                            calibration=PayloadCalibration(mass_kg=0.0), model_dh=robot.dh,
                            model_stiffness_Nm_per_rad=robot.joint_stiffness_Nm_per_rad, tool_m=tool)
    builder = DiagramBuilder()
    c = builder.AddSystem(comp.diagram)
    step = builder.AddSystem(StepWrench(np.zeros(6), np.array([-300.0, 0, 0, 0, 0, 0]), 0.0105))
    builder.Connect(step.get_output_port(), c.GetInputPort("wrench"))
    qsrc = builder.AddSystem(ConstantVectorSource(q))
    builder.Connect(qsrc.get_output_port(), c.GetInputPort("position_measured"))
    diagram = builder.Build()
    sim = Simulator(diagram)
    comp.set_initial_state(sim.get_mutable_context(), np.zeros(6), q)
    first = None
    for k in range(1, 20):
        sim.AdvanceTo(k * T + T / 2)  # between ticks: the updates at k*T are done
        out = c.GetOutputPort("correction").Eval(c.GetMyContextFromRoot(sim.get_context()))
        if np.any(out != 0):
            first = k * T
            break
    assert first == pytest.approx(0.012 + T * (delay_steps + 1))
    assert comp.chain_delay_s == pytest.approx(2.0 / rate + (2 + delay_steps) * T)


@pytest.fixture(scope="module")
def short_runs():
    from robstiff_drake.model.robot import load_robot

    robot = load_robot()
    sc = load_scenario(SHORT)
    return sc, run_cut(sc, robot, compensation=False), run_cut(sc, robot, compensation=True)


def test_short_cut_cuts_more_and_compensation_fixes_it(short_runs):
    sc, off, on = short_runs
    assert 0.1 < off.surface_error_mm["mean"] < 1.2  # the paper's "cut more"
    assert abs(on.surface_error_mm["mean"]) < 0.2 * off.surface_error_mm["mean"]
    assert on.surface_error_mm["rms"] < off.surface_error_mm["rms"]
    # every block ran: the sensor saw the cut, the chain estimated it, the correction moved
    tw = on.logs["tool_wrench"][1]
    assert np.abs(tw[:, 0]).max() > 100
    assert np.abs(on.logs["correction"][1]).max() > 1e-5
    assert np.abs(off.logs["correction"][1]).max() > 1e-5  # computed, but not applied
    # the estimate follows the true cutting force (filter lag aside)
    t_c, cut = on.logs["cutting_wrench"]
    t_e, est = on.logs["tool_wrench"]
    mid = len(t_e) // 2
    np.testing.assert_allclose(est[mid, :3], cut[np.searchsorted(t_c, t_e[mid]), :3], atol=25.0)


def test_diagram_names_every_block(short_runs):
    _, _, on = short_runs
    dot = on.cell.diagram.GetGraphvizString(max_depth=2)
    for name in ("milling_station", "compensator", "plant", "joint_servo", "interpolator_hold", "gear_transmission",
                 "motor_reference_gravity", "position_reported", "path", "milling_force", "wrist_sensor",
                 "wrench_guard", "force_filter", "compensator_tick", "q_command"):
        assert name in dot, name


def test_dropouts_and_spikes_never_reach_the_plant(robot, short_runs):
    sc = load_scenario(SHORT)
    sc.sensor.dropout_probability = 0.05
    sc.sensor.spike_probability = 0.02
    sc.sensor.spike_N = 5000.0
    res = run_cut(sc, robot, compensation=True)
    assert res.logs["rejected"][1][-1, 0] > 50  # the guard caught them
    raw = res.logs["raw_wrench"][1]
    assert np.all(np.isfinite(raw))  # what leaves the guard is finite
    corr = res.logs["correction"][1]
    assert np.all(np.isfinite(corr))
    assert np.abs(corr).max() <= np.deg2rad(sc.controller.saturation_deg) + 1e-12
    assert np.all(np.isfinite(res.logs["state"][1]))
    # holding the last good sample costs little: the surface is nearly as without them
    assert abs(res.surface_error_mm["mean"] - short_runs[2].surface_error_mm["mean"]) < 0.03


def test_surface_is_converged_in_the_plant_step(short_runs):
    """The scenarios step the plant at 2 ms: the uncut surface (the loop's
    biggest signal) is the same as at 1 ms to 1 um in the mean, 5 um in PV."""
    from robstiff_drake.model.robot import load_robot

    sc, off, _ = short_runs
    fine = copy.deepcopy(sc)
    fine.plant_config.time_step = 0.001
    off1 = run_cut(fine, load_robot(), compensation=False)
    assert abs(off1.surface_error_mm["mean"] - off.surface_error_mm["mean"]) < 1e-3
    assert abs(off1.surface_error_mm["pv"] - off.surface_error_mm["pv"]) < 5e-3


def _write(tmp_path, text):
    p = tmp_path / "scenario.yaml"
    p.write_text(text)
    return p


@pytest.mark.parametrize(
    "edit, message",
    [
        (lambda s: s.replace("  period_ms: 4.0", "  period_ms: 4.0\n  perod_ms: 4.0"), "perod_ms"),
        (lambda s: s.replace("  period_ms: 4.0", "  period_ms: -4.0"), "controller.period_ms: -4 is outside the allowed range [0.1, 1000] ms"),
        (lambda s: s.replace("  diameter_mm: 75.0", "  diameter_mm: 400.0"), "cutter.diameter_mm: 400 is outside the allowed range [10, 250] mm"),
        (lambda s: s.replace("  period_ms: 4.0", "  period_ms: 1.0"), "controller.period_ms: 1 ms is below the plant step"),
        (lambda s: s.replace("    cutoff_hz: 2.0", "    cutoff_hz: 900.0"), "controller.filter.cutoff_hz: 900 Hz must be between 0 and half"),
        (lambda s: s.replace("  mode: averaged", "  mode: exact"), "cutting.mode: expected one of 'averaged', 'tooth', got 'exact'"),
        (lambda s: s.replace("  time_step: 0.002", "  time_step: 0.004"),
         "plant_config.time_step: a 4 ms plant step is unstable for the arm's 126 Hz mode"),
        # (no damping on the gears, the drives' integral corner above the first modes: the PI takes damping away)
        (lambda s: s.replace("  modal_damping_ratio: 0.05", "  modal_damping_ratio: 0.0\n  damping_on: motors_held")
         + "servo:\n  velocity_integral: stated\n",
         "plant_config.time_step: the joints' loop is unstable whatever the step"),
        # (0 stated on the drives-closed modes: the gears get none; the 126 Hz wrist mode, undamped, then grows
        # in the plant's explicit 2 ms step)
        (lambda s: s.replace("  modal_damping_ratio: 0.05", "  modal_damping_ratio: 0.0"),
         "plant_config.time_step: a 2 ms plant step is unstable for the arm's"),
        (lambda s: s.replace("  modal_damping_ratio: 0.05", "  damping_ratios: [0.05, 0.05, 0.6, 0.05, 0.05, 0.05]"),
         "plant.damping_ratios[2]: 0.6 is outside the allowed range [0, 0.5]"),
        (lambda s: s.replace("  modal_damping_ratio: 0.05", "  modal_damping_ratio: 0.05\n  damping_ratios: [0.05]"),
         "plant.damping_ratios: expected 0 or 6 numbers, got 1"),
        (lambda s: s.replace("  modal_damping_ratio: 0.05", "  damping_ratio: 0.10"),
         "plant.damping_ratio: replaced by plant.modal_damping_ratio"),
        (lambda s: s.replace("  modal_damping_ratio: 0.05", "  modal_damping_ratio: 0.05\n  lost_motion_rad: "
                                                                "[0.0, 0.005, 0.0, 0.0, 0.0, 0.0]"),
         "plant.lost_motion_rad[1]: 0.005 is outside the allowed range [0, 0.002] rad"),
        (lambda s: s.replace("    - [1702.5, 0.0, 700.0]", "    - [1702.5, 0.0, 700.0]\n    - [1702.5, 0.0, 1900.0]"),
         "outside its joint limit"),
        (lambda s: s.replace("    - [1497.5, 0.0, 700.0]\n    - [1702.5, 0.0, 700.0]",
                             "    - [413.0, -30.0, 0.0]\n    - [413.0, 30.0, 0.0]").replace(
            "    - [1540.0, 1660.0, -10.0, 40.0, 701.5]", "    - [380.0, 446.0, -10.0, 10.0, 3.0]"),
         "singularity (wrist singularity"),
        (lambda s: s.replace("700.0]", "710.0]"), "never comes below the top of a workpiece box"),
        (lambda s: s.replace("controller:", "controller:\n  period_ms: 8.0\ncontroller:", 1),
         "duplicated key 'controller'"),
        (lambda s: s.replace("  period_ms: 4.0", '  period_ms: "four"'),
         "controller.period_ms: expected a number in ms, got 'four'"),
        (lambda s: s.replace("  n_teeth: 6", "  n_teeth: 60"), "tooth pitch of 3.9 mm"),
        (lambda s: s.replace("  feed_mm_per_s: 60.0", "  feed_mm_per_s: 1e-6"), "outside the allowed range [0.1, 2000]"),
        (lambda s: s.replace("  feed_mm_per_s: 60.0", "  feed_mm_per_s: 0.1").replace("  time_step: 0.002",
                                                                                  "  time_step: 5.0e-5"),
         "plant steps, more than"),
        (lambda s: s.replace("  force_bias_N: [3.0, -2.0, 5.0]", "  force_bias_N: [3.0, -2.0]"),
         "sensor.force_bias_N: expected 3 numbers, got 2"),
        (lambda s: s.replace("  yaw_deg: 0.0", "  yaw_deg: .nan"), "path.yaw_deg: nan is not a finite number"),
        (lambda s: s.replace("  seed: 1", "  seed: -1"), "sensor.seed: -1 is outside the allowed range"),
    ],
)
def test_bad_scenarios_fail_before_simulating(tmp_path, robot, edit, message):
    from robstiff_drake.diagrams.milling_cell import build_milling_cell

    path = _write(tmp_path, edit(SHORT.read_text()))
    with pytest.raises(InputError) as err:
        build_milling_cell(load_scenario(path), robot)
    assert message in str(err.value)
    assert "\n" not in str(err.value)


def test_simulate_cli_error_is_one_line(capsys, tmp_path):
    from robstiff_drake.commands.main import main

    path = _write(tmp_path, SHORT.read_text().replace("  n_teeth: 6", "  n_teeth: 6\n  colour: red"))
    code = main(["simulate", str(path), "--out", str(tmp_path / "out")])
    _, err = capsys.readouterr()
    assert code == 2
    assert len(err.strip().splitlines()) == 1 and "colour" in err
    assert not (tmp_path / "out").exists()


def test_compensation_with_an_identified_model(robot, tmp_path, capsys):
    """The compensator holds a model identified by `robstiff identify` from a
    noisy synthetic campaign of a plant whose stiffness is not the nominal one:
    mean surface error <= 0.05 mm on the block test."""
    from robstiff_drake.commands.main import main

    k_true = robot.joint_stiffness_Nm_per_rad * np.array([0.85, 1.1, 0.9, 1.2, 0.8, 1.0])
    k_text = ",".join(f"{k:.6g}" for k in k_true)
    campaign = tmp_path / "campaign.csv"
    assert main(["synth", "stiffness", str(campaign), "--n", "120", "--noise-mm", "0.01", "--seed", "7",
                 "--tool", "0,0,350", "--stiffness", k_text]) == 0
    ident = tmp_path / "identified.json"
    assert main(["identify", str(campaign), "--tool", "0,0,350", "--json", str(ident)]) == 0
    capsys.readouterr()
    text = (Path(__file__).parents[1] / "diagrams" / "block_milling.yaml").read_text()
    text = text.replace("plant:\n", f"plant:\n  joint_stiffness_Nm_per_rad: [{k_text}]\n", 1)
    text += "model:\n  identified_json: identified.json\n"
    scenario = _write(tmp_path, text)
    sc = load_scenario(scenario)
    res = run_cut(sc, robot, compensation=True)
    assert abs(res.surface_error_mm["mean"]) <= 0.05
    # and the nominal model on the same plant is visibly worse (the model matters)
    sc_nominal = copy.deepcopy(sc)
    sc_nominal.model.identified_json = ""
    sc_nominal.model.source = "nominal"  # the robot file's stiffness (the default is the identified model)
    res_nominal = run_cut(sc_nominal, robot, compensation=True)
    assert abs(res_nominal.surface_error_mm["mean"]) > abs(res.surface_error_mm["mean"])


def test_a_reused_diagram_gives_the_same_run(robot):
    """The sensor's noise restarts with each simulation: two runs of one built
    diagram are identical to the last sample."""
    from robstiff_drake.diagrams.milling_cell import build_milling_cell

    sc = load_scenario(SHORT)
    assert sc.sensor.noise_N > 0
    cell = build_milling_cell(sc, robot, compensation=True)
    a, b = (run_cut(sc, robot, compensation=True, cell=cell) for _ in range(2))
    np.testing.assert_array_equal(a.logs["raw_wrench"][1], b.logs["raw_wrench"][1])
    assert a.surface_error_mm == b.surface_error_mm
