"""The preview compensator on top of a program corrected offline
(systems/preview_correction.PreviewCorrection with ``offline=True``): the
program already holds the model's feed-forward at scale one, so the block
sends only what its scale estimate adds; with an exact model it sends
(almost) nothing, where the preview on a program as written sends the
whole correction.  The table is the real-time cell's preview plan of a
short job (cell/preview_job.py), the deflection model the project's."""

import numpy as np
import pytest

from robstiff_drake.cell.preview_job import build_plan, load_job
from robstiff_drake.model.compensator import DeflectionModel
from robstiff_drake.model.filters import lowpass_coefficients
from robstiff_drake.model.realtime import DeflectionPredictor
from robstiff_drake.systems.preview_correction import PreviewCorrection

from test_cell_preview import SHORT

T, RATE_HZ = 0.004, 1000.0


@pytest.fixture(scope="module")
def plan():
    sc, robot = load_job(SHORT, None, period_s=T)
    ba = lowpass_coefficients(2.0, RATE_HZ)
    p = build_plan(sc, robot, robot.joint_stiffness_Nm_per_rad * 0.9, period_s=T, filter_ba=ba, rate_hz=RATE_HZ,
                   delay_steps=1)
    tool = robot.payload.tool_point_m
    model = DeflectionModel(DeflectionPredictor(robot.dh, robot.joint_stiffness_Nm_per_rad * 0.9, tool), tool)
    return p, ba, model


def _run(p, ba, model, *, offline, learn=True, tangential=1.0):
    """(dq (n, 6) rad, the final scales) of the block fed the model's own
    filtered wrench (its tangential group times ``tangential``) at the
    plan's joint references, cycle by cycle."""
    block = PreviewCorrection(table=(p.u, p.c, p.sensor), deflection=model, filter_ba=ba, rate_hz=RATE_HZ,
                              period_s=T, lead_s=p.lead_s, lag_s=p.lag_s, learn=learn, offline=offline)
    ctx = block.CreateDefaultContext()
    w_port, q_port = block.GetInputPort("process_wrench"), block.GetInputPort("q")
    state = block.AllocateDiscreteVariables()
    weights = np.array([[tangential], [1.0], [1.0], [1.0]])
    out, steady = [], []
    for k in range(len(p.u) - 3):
        ctx.SetTime(k * T)
        w_port.FixValue(ctx, (p.replica[k] * weights).sum(axis=0))
        q_port.FixValue(ctx, np.radians(p.q_ref_deg[min(k, len(p.q_ref_deg) - 1)]))
        block._update(ctx, state)
        ctx.SetDiscreteState(state)
        out.append(block.GetOutputPort("dq").Eval(ctx).copy())
        steady.append(block._steady(k * T))
    _run.steady = np.array(steady)  # where the offline block hears its bracket (the model's force steady)
    return np.array(out), block.GetOutputPort("scales").Eval(ctx).copy()


def test_on_a_corrected_program_an_exact_model_sends_no_second_correction(plan):
    p, ba, model = plan
    full, _ = _run(p, ba, model, offline=False)
    on_top, scales = _run(p, ba, model, offline=True)
    size = float(np.max(np.abs(full)))
    print(f"largest correction: on the program as written {size * 1e6:.1f} urad, on top of the corrected program "
          f"{np.max(np.abs(on_top)) * 1e6:.2f} urad (mean {np.abs(on_top.mean(axis=0)).max() * 1e6:.3f}); scales "
          f"{np.round(scales, 4)}")
    assert size > 100e-6  # the preview's own correction is there to be sent twice
    assert np.max(np.abs(on_top)) < 0.02 * size
    assert np.abs(on_top.mean(axis=0)).max() < 0.005 * np.abs(full).mean(axis=0).max()
    assert np.allclose(scales, 1.0, atol=0.01)


def test_on_top_it_sends_the_preview_less_the_programs_feed_forward(plan):
    """Scales held at one: where the model's force is steady the two blocks
    differ by the table's whole feed-forward (the force groups' and the
    inertia's parts) at the lead; where it is not, the block on top sends
    nothing (its bracket is not heard there)."""
    p, ba, model = plan
    full, _ = _run(p, ba, model, offline=False, learn=False, tangential=1.2)
    on_top, _ = _run(p, ba, model, offline=True, learn=False, tangential=1.2)
    u = np.arange(len(full)) * T + p.lead_s
    ff = np.array([[np.interp(x, p.u, p.c[:, :, j].sum(axis=1)) for j in range(6)] for x in u])
    steady = _run.steady
    assert np.max(np.abs(ff)) > 100e-6
    assert 0.2 < steady.mean() < 0.95  # both kinds of tick are there to be tested
    # where the model's force is steady the block hears its bracket: the two differ by the feed-forward
    assert np.allclose((on_top - full)[steady], ff[steady], atol=1e-3 * np.max(np.abs(ff)))
    # where it is not (an entry: the cut's timing, not its coefficients), nothing is sent on top
    assert np.allclose(on_top[~steady], 0.0, atol=1e-12)
    assert np.max(np.abs(on_top[steady])) > 1e-6  # what the model misses (the 20 % stronger cut) is still corrected


def test_on_top_a_stronger_cut_is_learned_and_its_surplus_sent(plan):
    p, ba, model = plan
    on_top, scales = _run(p, ba, model, offline=True, tangential=1.15)
    print(f"scales {np.round(scales, 4)}")
    assert abs(scales[0] - 1.15) < 0.03 and np.allclose(scales[1:], 1.0, atol=0.03)
    assert np.max(np.abs(on_top)) > 1e-6


def test_the_plans_table_is_put_on_the_corrected_programs_clock():
    """model/program_correction.clock_on: a table on the planned path's
    times moved to the times the corrected program's path (here the same
    corners 0.3 mm lower and run faster, after a longer dwell) passes the
    same points."""
    from robstiff_drake.model.path import PlannedPath
    from robstiff_drake.model.program_correction import clock_on

    pts = np.array([[0.0, 0.0, 0.0], [0.05, 0.0, 0.0], [0.05, 0.04, 0.0], [0.0, 0.04, 0.0]])
    plan = PlannedPath(pts, 0.02, dwell_s=0.2, ramp_s=0.05)
    corrected = PlannedPath(pts - [0.0, 0.0, 3e-4], 0.025, dwell_s=0.5, ramp_s=0.05)
    u = np.arange(0.0, plan.duration_s + 0.3, 0.004)
    t = clock_on(plan, corrected, u)
    assert np.all(np.diff(t) > 0)
    moving = np.array([0.0 < x < plan.duration_s and plan.speed(x) > 1e-6 for x in u])
    s_plan = np.array([plan.arc_length(x) for x in u[moving]])
    s_corr = np.array([corrected.arc_length(x) for x in t[moving]])
    assert np.max(np.abs(s_plan - s_corr)) < 1e-4  # the same point along the path (within 0.1 mm)
    assert abs(t[moving][-1] - u[moving][-1]) > 0.5  # the clocks differ: the mapping is not the identity
    same = clock_on(plan, plan, u)
    assert np.max(np.abs(same[moving] - u[moving])) < 0.003


# ---------------------------------------------------------------- the feed planner's feeds in the corrected program


def _plan(adopted, line_ranges):
    from types import SimpleNamespace

    return SimpleNamespace(adopted=adopted, line_ranges=line_ranges, tolerance_mm=0.05, notes=[])


def _feeds_along(path):
    """[(end point mm, feed mm/min)] of the program's feed moves, read back."""
    from robstiff_drake.model.gcode.program import read_program

    back = read_program(path.read_text(), "c.nc")
    assert back.warnings == []
    return [(np.asarray(m.end_mm), m.feed_mm_per_min) for m in back.moves if m.kind != "rapid"]


def test_the_corrected_program_carries_the_planned_feeds(tmp_path, monkeypatch):
    """compensate-program --advise: where the feed planner lowers the feed
    (here a plan that slows the last 6 mm of the closing G1 Y70. to F600),
    the corrected program's F words are the plan's, everywhere else the
    program's own; a plan that lowers nothing leaves the program's feeds."""
    import json

    from robstiff_drake.commands import compensate_program
    from robstiff_drake.commands.main import main
    from test_compensate_program import short_job

    job = short_job(tmp_path / "job")
    line = next(n for n, ln in enumerate((tmp_path / "job" / "short.nc").read_text().splitlines(), 1)
                if ln.startswith("N80"))
    monkeypatch.setattr(compensate_program, "plan_feeds",
                        lambda sc, robot: _plan(True, {line: [(0.0, 4.0, 1200.0), (4.0, 10.0, 600.0)]}))
    out = tmp_path / "slowed"
    assert main(["compensate-program", str(job), "--out", str(out), "--no-simulate", "--refine-rounds", "0",
                 "--advise", "--json", str(tmp_path / "s.json")]) == 0
    summary = json.loads((tmp_path / "s.json").read_text())
    assert summary["feed_plan"]["adopted"] and summary["feed_plan"]["lowered"] == {str(line): [[0.0, 4.0, 1200.0],
                                                                                              [4.0, 10.0, 600.0]]}
    text = (out / "short_compensated.nc").read_text()
    assert "FEEDS LOWERED" in text
    feeds = _feeds_along(out / "short_compensated.nc")
    # (block ends within the correction, < 1 mm, of the programmed ones)
    slowed = [f for p, f in feeds if abs(p[0] - 60.0) < 1.0 and p[1] > 65.0]  # the last 6 mm of G1 Y70.
    assert slowed and set(slowed) == {600.0}
    assert {f for p, f in feeds if p[1] < 63.0} == {1200.0}  # the rest at the program's own feed

    monkeypatch.setattr(compensate_program, "plan_feeds", lambda sc, robot: _plan(False, {}))
    kept = tmp_path / "kept"
    assert main(["compensate-program", str(job), "--out", str(kept), "--no-simulate", "--refine-rounds", "0",
                 "--advise"]) == 0
    text = (kept / "short_compensated.nc").read_text()
    assert "FEEDS LOWERED" not in text
    assert {f for _, f in _feeds_along(kept / "short_compensated.nc")} == {1200.0}
    # the same program as without --advise
    plain = tmp_path / "plain"
    assert main(["compensate-program", str(job), "--out", str(plain), "--no-simulate", "--refine-rounds", "0"]) == 0
    strip = [ln for ln in text.splitlines() if "ROBSTIFF" not in ln]
    assert strip == [ln for ln in (plain / "short_compensated.nc").read_text().splitlines() if "ROBSTIFF" not in ln]


def test_in_the_closed_loop_the_preview_on_top_sends_almost_nothing_with_an_exact_model(tmp_path):
    """The cell's wiring (diagrams/milling_cell.build_milling_cell with
    ``offline_plan``): the short job on the compensator's own model as the
    plant (offline_refinement.model_twin: the nominal model's stiffness,
    damping, servo and linear cutting law), its program taken as the
    corrected one and the plan as the one it was corrected for: the preview
    on top sends a small fraction of what the preview on the program as
    written sends (its whole feed-forward)."""
    import copy

    from robstiff_drake.diagrams import user_model as user_models
    from robstiff_drake.diagrams.experiment import run_cut
    from robstiff_drake.diagrams.milling_cell import build_milling_cell, planned_path
    from robstiff_drake.diagrams.offline_refinement import model_twin
    from robstiff_drake.diagrams.scenario import load_scenario, scenario_robot
    from test_compensate_program import short_job

    sc = load_scenario(short_job(tmp_path / "job"))
    robot = scenario_robot(sc)
    plan = planned_path(sc, robot, robot.tool_point(where="test"))
    user_models.resolve(sc, robot, plan[2][0])
    twin = model_twin(sc, robot)
    twin.controller.mode = "preview"
    sizes = {}
    for offline in (None, plan):
        run_sc = copy.deepcopy(twin)
        cell = build_milling_cell(run_sc, robot, compensation=True, offline_plan=offline)
        res = run_cut(run_sc, robot, compensation=True, cell=cell)
        t, dq = res.logs["dq"]
        sizes[offline is not None] = float(np.mean(np.abs(dq), axis=0).max())
    print(f"mean |dq|, largest joint: preview {sizes[False] * 1e6:.1f} urad, on top {sizes[True] * 1e6:.2f} urad")
    assert sizes[False] > 20e-6
    assert sizes[True] < 0.1 * sizes[False]
