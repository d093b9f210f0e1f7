"""``robstiff simulate SCENARIO.yaml``: the closed-loop milling simulation,
without and/or with compensation; surface-error plot (like the paper's Fig. 7),
the diagram (Graphviz), CSV time series and a JSON summary.

The run folder (``--out``) holds the compensated cut as a cell records it
(wrench_log.csv, joint_log.csv, compensator.yaml, scan.csv: the formats of
docs/run_files.md, written by identification/runs/files.py) and the
simulation's own files, named ``sim_*`` (the scenario with its plant, the
actual tool path, the true surface): the truth that ``robstiff
diagnose-run`` never reads.  ``--compensator SETTINGS.yaml`` runs the
scenario's machine with another compensator (a verification cut)."""

import copy
from pathlib import Path

import numpy as np

# Drake comes with the diagrams' modules, imported where they are used: a
# bad argument is refused before that import (as fast as --help).
from robstiff_drake.diagrams.plant_step import step_choice
from robstiff_drake.diagrams.job_checks import job_warnings, worse_reason
from robstiff_drake.diagrams.run_checks import WORSE_FACTOR, WORSE_PREFIX, run_warnings
from robstiff_drake.diagrams.run_vibration import vibration_summary, vibration_warnings
from robstiff_drake.errors import InputError
from robstiff_drake.identification.runs.logs import joint_reference_text
from robstiff_drake.identification.runs.settings import read_settings
from robstiff_drake.identification.runs.tables import SIM_PREFIX
from robstiff_drake.io import RunFolder, Warnings, check_outputs, emit_json, json_text, write_atomic
from robstiff_drake.model.feed_plan import check_rewritable
from robstiff_drake.progress import info, wrote
from robstiff_drake.commands.simulation_files import (  # noqa: F401  (imported from here too)
    label,
    plot_surfaces,
    scenario_text,
    surface_csv,
    timeseries_csv,
    write_diagram,
)

MODES = {"on": (True,), "off": (False,), "both": (False, True)}
# A tolerance must be at least this many times the scan's noise (1 sigma)
# to be verifiable by the scan (the 2-sigma band of one point).
TOLERANCE_NOISE_FACTOR = 2.0


def summary(results, sc, warnings=()):
    out = {"scenario": sc.source, "name": sc.name, "robot": results[0].cell.robot.name, "surface_error_mm": {},
           "warnings": list(warnings)}
    res0 = results[0]
    for res in results:
        out["surface_error_mm"][label(res.compensation)] = res.surface_error_mm
    out["sim_seconds"] = sum(r.sim_seconds for r in results)
    out["wall_seconds"] = sum(r.wall_seconds for r in results)
    out["realtime_factor"] = out["sim_seconds"] / out["wall_seconds"]
    out["runs"] = [{"compensation": r.compensation, "sim_seconds": r.sim_seconds, "wall_seconds": r.wall_seconds,
                    "realtime_factor": r.realtime_factor,
                    "rejected_sensor_samples": int(r.logs["rejected"][1][-1, 0]), "spindle": r.spindle}
                   for r in results]
    out["spindle_power_W"] = max(r.spindle["power_W_max"] for r in results)
    out["spindle_rating_W"] = sc.cutter.spindle_rating_W
    mid = mid_pass_wrench(res0.logs["cutting_wrench"][1])
    out["cutting_wrench_at_mid_pass"] = {"force_N": mid[:3], "moment_Nm": mid[3:]}
    out["natural_frequencies_hz"] = res0.cell.natural_frequencies_hz  # motors held
    f, z = res0.cell.closed_loop_modes  # the arm's first three (the drives' own modes are above them)
    out["drives_closed_modes"] = [{"frequency_hz": float(a), "damping_ratio": float(b)} for a, b in zip(f[:3], z[:3])]
    out["plant_time_step_s"] = res0.cell.plant_time_step_s
    out["plant_time_step_choice"] = step_choice(sc)  # why the station took it (None: the scenario gave it)
    out["transport_delay_s"] = res0.cell.transport_delay_s
    # the regenerative chip's stability at the cut's sampled poses (diagrams/chatter_check.py; None: not
    # checked: the tooth-resolved mode or no cut)
    out["chatter_check"] = getattr(sc, "_chatter_check", None)
    # the tool's in-plane vibration each run had (diagrams/run_vibration.py; null: a run that never cut)
    vib = getattr(sc, "_vibration", None)
    out["vibration"] = vib if vib is not None else vibration_summary(results)
    errs = out["surface_error_mm"]
    out["compensation_made_it_worse"] = (bool(errs["compensated"]["rms"] > WORSE_FACTOR * errs["uncompensated"]["rms"])
                                         if len(errs) == 2 else None)
    return out


def mid_pass_wrench(cw, in_cut_N=1.0):
    """The cutting wrench (6,) at mid-pass from its log ``cw`` (N, 6): the
    log's middle sample when the cutter is in the material there (force
    above ``in_cut_N``), else the middle of the samples where it is (a job
    with turns may be between passes at its middle)."""
    cw = np.asarray(cw, dtype=float)
    if len(cw) == 0:
        return np.zeros(6)
    mid = cw[len(cw) // 2]
    if np.linalg.norm(mid[:3]) <= in_cut_N:
        cutting = np.flatnonzero(np.linalg.norm(cw[:, :3], axis=1) > in_cut_N)
        if cutting.size:
            mid = cw[cutting[len(cutting) // 2]]
    return mid


def format_table(summ):
    lines = [f"{summ['name']}: surface error (mm, + = cut more)",
             "                  mean      rms   max|e|       PV"]
    for name, s in summ["surface_error_mm"].items():
        lines.append(f"  {name:14s} {s['mean']:+7.3f}  {s['rms']:7.3f}  {s['max_abs']:7.3f}  {s['pv']:7.3f}")
    f = [int(round(float(v))) for v in summ["cutting_wrench_at_mid_pass"]["force_N"]]  # (no "-0")
    lines.append(f"cutting force at mid-pass (N, base frame): ({f[0]}, {f[1]}, {f[2]}); spindle power up "
                 f"to {summ['spindle_power_W'] / 1e3:.2f} kW (rating {summ['spindle_rating_W'] / 1e3:.2f} kW)")
    lines.append("first natural frequencies at the start pose (Hz): "
                 + ", ".join(f"{v:.1f}" for v in summ["natural_frequencies_hz"]) + " (motors held); with the drives "
                 "closed " + ", ".join(f"{m['frequency_hz']:.1f} ({100 * m['damping_ratio']:.1f} %)"
                                       for m in summ["drives_closed_modes"]))
    if summ.get("plant_time_step_choice"):
        lines.append(summ["plant_time_step_choice"])
    lines.append(simulated_line(summ["runs"]))
    return "\n".join(lines)


def simulated_line(runs):
    """'simulated 12.55 s per run (uncompensated, compensated) in 0.64 + 0.63 s wall (19.8x real time)':
    each run's simulated time, not their sum."""
    names = ", ".join(label(r["compensation"]) for r in runs)
    sims = {round(r["sim_seconds"], 2) for r in runs}
    sim = (f"{runs[0]['sim_seconds']:.2f} s" if len(sims) == 1 else
           " / ".join(f"{r['sim_seconds']:.2f}" for r in runs) + " s")
    wall = " + ".join(f"{r['wall_seconds']:.2f}" for r in runs)
    factor = sum(r["sim_seconds"] for r in runs) / max(sum(r["wall_seconds"] for r in runs), 1e-9)
    per = "per run " if len(runs) > 1 else ""
    return f"simulated {sim} {per}({names}) in {wall} s wall ({factor:.1f}x real time)"


def load_for_run(scenario, robot, *, compensator=None, noise_seed=None, toolpath=None, work_offset=None, stock=None):
    """The scenario to simulate: from its file (its path replaced by the
    G-code program ``toolpath`` when given, placed by ``work_offset``,
    "X,Y,Z[,ROT_DEG]", its workpiece replaced by ``stock``, "X0,X1,Y0,Y1,TOP"),
    with the compensator of a settings file
    (``compensator``) and the sensor's and scanner's noise seeds set to
    ``noise_seed`` (a repeated cut: new noise) when given."""
    from robstiff_drake.diagrams import user_model as user_models
    from robstiff_drake.diagrams.cell_record import check_same_robot, scenario_with_compensator
    from robstiff_drake.diagrams.milling_cell import planned_path as cell_path
    from robstiff_drake.diagrams.scenario import load_scenario
    from robstiff_drake.diagrams.scenario_step import plant_step_s

    sc = load_scenario(scenario, toolpath=toolpath, work_offset=work_offset, stock=stock)
    if compensator is not None:
        _, settings = read_settings(compensator)
        # another robot's compensator is refused before the path and the model are computed (was 50 s)
        check_same_robot(settings, robot, settings.path or "compensator settings")
        _, _, q_ref = cell_path(sc, robot, robot.tool_point(where="the closed loop"))
        user_models.resolve(sc, robot, q_ref[0])  # (the run's own model: its payload calibration)
        sc = scenario_with_compensator(sc, settings, robot)
    if noise_seed is not None:
        sc.sensor.seed = sc.scan.seed = int(noise_seed)
    plant_step_s(sc, robot)  # (not given: the step the station takes for this arm, said once, before the run)
    return sc


def simulate(*, scenario, compensation="both", robot=None, robot_yaml=None, warnings=None, compensator=None,
             noise_seed=None, toolpath=None, work_offset=None, progress=False, tolerance_mm=None, extras=None,
             stock=None):
    """Load and run; returns (scenario, results).  The robot: ``robot`` (a
    RobotModel), else --robot's ``robot_yaml``, else the scenario's own.
    Warnings about the settings and the result go to ``warnings`` (an
    io.Warnings) if given.  ``compensator``, ``noise_seed``, ``toolpath``, ``work_offset``, ``stock``: see
    load_for_run;
    ``progress``: a bar over simulated time (experiment.run_cut).  With a
    tolerance (``tolerance_mm``, else the scenario's path.tolerance_mm), the
    compensated cut runs on the feed planner's path (diagrams/feed_plan.py);
    ``extras`` (a dict) gets the plan under "feed_plan" and the compensated
    scenario under "compensated_scenario"."""
    if compensation not in MODES:
        raise InputError(f"simulate: --compensation must be on, off or both, got {compensation!r}")
    from robstiff_drake.diagrams import user_model as user_models
    from robstiff_drake.diagrams.experiment import run_cut
    from robstiff_drake.diagrams.feed_plan import plan_feeds
    from robstiff_drake.diagrams.milling_cell import planned_path as cell_path
    from robstiff_drake.diagrams.scenario import load_scenario, scenario_robot
    from robstiff_drake.diagrams.chatter_check import check_job
    from robstiff_drake.diagrams.scenario_models import scenario_warnings

    robot = robot or scenario_robot(load_scenario(scenario, toolpath=toolpath, work_offset=work_offset, stock=stock),
                                    robot_yaml)
    sc = load_for_run(scenario, robot, compensator=compensator, noise_seed=noise_seed, toolpath=toolpath,
                      work_offset=work_offset, stock=stock)
    if tolerance_mm is not None:
        check_tolerance(sc, tolerance_mm, "--tolerance-mm")
        sc.path.tolerance_mm = float(tolerance_mm)
    _, _, q_ref = cell_path(sc, robot, robot.tool_point(where="the closed loop"))
    user_models.resolve(sc, robot, q_ref[0])  # the compensator's model (for the warnings too)
    # the plant's step, before the feed planner's runs on the compensator's twin (stable where the plant may not
    # be: a KR 210 job at 1 ms was refused only after them)
    from robstiff_drake.diagrams.milling_cell import check_plant_step

    check_plant_step(sc, robot)
    if warnings is not None:
        warnings.extend_from(scenario_warnings(sc, robot) + job_warnings(sc))
        # would the real cut chatter? (the plant leaves the regenerative chip out; diagrams/chatter_check.py)
        sc._chatter_check = check_job(sc, robot, warnings)
    sc_comp = sc
    if sc.path.tolerance_mm > 0 and True in MODES[compensation]:
        plan = plan_feeds(sc, robot)
        if plan.adopted:  # only a plan predicted to improve on the program as written slows the cut
            sc_comp = copy.deepcopy(sc)
            sc_comp._feed_overrides = plan.overrides
        if extras is not None:
            extras["feed_plan"] = plan
        if warnings is not None:
            warnings.extend_from(plan.notes)
    if extras is not None:
        extras["compensated_scenario"] = sc_comp
    results = [run_cut(sc_comp if c else sc, robot, compensation=c, progress=progress) for c in MODES[compensation]]
    # did the run itself vibrate? (its own logged signals, every plant mode: diagrams/run_vibration.py)
    sc._vibration = vibration_summary(results)
    if warnings is not None:
        warnings.extend_from([w + worse_reason(sc, getattr(sc, "_program", None)) if w.startswith(WORSE_PREFIX) else w
                              for w in run_warnings(results, sc)])
        warnings.extend_from(vibration_warnings(sc._vibration, sc))
    return sc, results


def check_tolerance(sc, tolerance_mm, where):
    """Refuse a tolerance the scan cannot verify (InputError, one line)."""
    floor = TOLERANCE_NOISE_FACTOR * sc.scan.noise_mm
    if 0 < tolerance_mm < floor:
        raise InputError(f"{where}: a tolerance of {tolerance_mm:g} mm is below what the scan can verify: twice its "
                         f"noise, {TOLERANCE_NOISE_FACTOR:g} x scan.noise_mm = {floor:g} mm (a surface within it "
                         "could not be told from one outside it)")


def write_outputs(sc, results, robot, run, warnings=()):
    """Every file of a run into ``run`` (an io.RunFolder), each stamped with
    its run id; returns the names written.  The compensated cut's cell files
    (docs/run_files.md), the simulation's truth (``sim_*``) and the inputs the
    run was made with (``inputs/``: diagrams/run_inputs.py)."""
    from robstiff_drake.diagrams.cell_record import cell_files
    from robstiff_drake.diagrams.run_inputs import INPUTS_DIR, kept_inputs, write_kept

    kept = kept_inputs(sc, robot)
    write_kept(run, kept)
    written = []
    for res in results:
        if res.compensation:
            for name, text in cell_files(sc, res, robot, run.run_id, robot_ref=kept.robot).items():
                run.write(name, text)
                written.append(name)
    run.write(f"{SIM_PREFIX}scenario.yaml", scenario_text(sc, run.run_id, kept))
    written.append(f"{SIM_PREFIX}scenario.yaml")
    run.save_figure("surface_error.png", plot_surfaces(results, sc), dpi=110)
    written.append("surface_error.png")
    written += write_diagram(results[-1].cell, run)
    for res in results:
        name = f"{SIM_PREFIX}timeseries_{label(res.compensation)}.csv"
        run.write(name, timeseries_csv(res, robot, run.run_id))
        written.append(name)
        name = f"{SIM_PREFIX}surface_{label(res.compensation)}.csv"
        run.write(name, surface_csv(res, run.run_id))
        written.append(name)
    cell = results[0].cell
    run.write("joint_reference.csv", joint_reference_text(
        cell.robot, cell.q_ref_times, cell.q_ref, run.run_id,
        [f"robstiff simulate: the joint references of {cell.scenario.source}'s path (IK every "
         f"{cell.scenario.path.reference_period_ms:g} ms; controller degrees), for `robstiff compensate --reference`"],
        period_s=cell.scenario.controller.period_ms / 1e3))
    written.append("joint_reference.csv")
    run.write("summary.json", json_text(dict(summary(results, sc, warnings), run_id=run.run_id)))
    written.append("summary.json")
    written.append(f"{INPUTS_DIR}/ ({', '.join(Path(n).name for n in kept.names.values())})")
    return written


def model_description(sc, robot):
    """What the compensator's model was (JSON): its source and, identified,
    the numbers and seeds it came from."""
    from robstiff_drake.diagrams.scenario_models import plant_stiffness, user_model_of

    um = user_model_of(sc)
    out = {"source": sc.model.source}
    if um is not None:
        out.update(um.describe(plant_stiffness(sc, robot)))
    return out


def format_feed_plan(plan, advise):
    """The feed plan's summary (and, with ``advise``, the advice table:
    each row's block number N when the program has them, and its line)."""
    inc = plan.cycle_time_s / plan.program_cycle_time_s - 1.0
    if plan.adopted or not plan.windows and plan.converged:
        lines = [f"feed plan (tolerance {plan.tolerance_mm:g} mm, predicted on the compensator's model): "
                 f"{plan.predicted_max_abs_mm:.3f} mm predicted as programmed, {plan.predicted_after_max_abs_mm:.3f} "
                 f"mm adapted; cycle time {plan.program_cycle_time_s:.2f} s -> {plan.cycle_time_s:.2f} s "
                 f"({100 * inc:+.1f} %)"]
    else:
        lines = [f"feed plan (tolerance {plan.tolerance_mm:g} mm, predicted on the compensator's model): "
                 f"{plan.predicted_max_abs_mm:.3f} mm predicted as programmed; no slower feed predicted better: "
                 f"not used (the program's own feeds, cycle time {plan.program_cycle_time_s:.2f} s)"]
    if advise:
        if not plan.advice:
            lines.append("advice: no program line's predicted surface error exceeds the tolerance")
        else:
            head = ("advice: program lines whose predicted surface error exceeds the tolerance" if plan.adopted else
                    "advice: program lines whose predicted surface error exceeds the tolerance (no slower feed "
                    "helps: the feed column is the program's)")
            lines.append(head)
            lines.append("  block (line)   error (mm)   cause      feed (mm/min)   programmed")
            for a in plan.advice:
                where = f"{a['block']} ({a['line']})" if a.get("block") else f"({a['line']})"
                lines.append(f"  {where:12s}   {a['error_mm']:9.3f}    {a['cause']:9s}  {a['feed_mm_per_min']:10.0f}"
                             f"      {a['programmed_feed_mm_per_min']:8.0f}")
    return "\n".join(lines)


def run(*, scenario, compensation="both", json_out=None, out="robstiff-out", compensator=None, noise_seed=None,
        robot_yaml=None, toolpath=None, work_offset=None, replay=None, progress=None, advise=False, advise_out=None,
        budget=False, budget_metric="rms", budget_split="ordered", tolerance_mm=None, stock=None):
    check_outputs(inputs=[scenario, compensator, toolpath], files={"--json": json_out, "--replay": replay,
                                                                  "--advise-out": advise_out},
                  folders={"--out": out})
    if (advise or advise_out or budget) and compensation == "off":
        raise InputError(f"{'--budget' if budget else '--advise'} is about the compensated cut: run with "
                         "--compensation on or both")
    if replay is not None and not Path(replay).exists():  # a new file: its name now, before Drake's import
        from robstiff_drake.commands.preflight import check_replay_name

        check_replay_name(replay)
    from robstiff_drake.diagrams import replay as replay_3d

    from robstiff_drake.diagrams import budget as budgets
    from robstiff_drake.diagrams.feed_plan import advised_program
    from robstiff_drake.diagrams.scenario import load_scenario, resolve, scenario_robot

    sc0 = load_scenario(scenario, toolpath=toolpath, work_offset=work_offset, stock=stock)
    if tolerance_mm is not None:
        check_tolerance(sc0, tolerance_mm, "--tolerance-mm")
    tol = tolerance_mm if tolerance_mm is not None else sc0.path.tolerance_mm
    if (advise or advise_out) and not tol > 0:
        raise InputError("--advise: no tolerance to hold: set path.tolerance_mm in the scenario or give --tolerance-mm")
    if advise_out is not None:
        if not sc0.toolpath.program:
            raise InputError("--advise-out: the scenario's path is not a G-code program (toolpath.program or --toolpath)")
        program = resolve(sc0, sc0.toolpath.program)
        try:
            check_rewritable(program.read_bytes().decode("utf-8-sig", errors="replace"), sc0._program.moves)
        except ValueError as e:
            raise InputError(f"--advise-out: {program}: {e}") from None
    robot = scenario_robot(sc0, robot_yaml)
    if replay is not None:  # an existing file: after the scenario's inputs are known (it may be one of them)
        replay_3d.check_replay_path(replay)
    meshcat = None
    if replay is not None:  # Meshcat needs its server: refuse before the simulation when it cannot start
        meshcat = replay_3d.start_meshcat()
    warnings = Warnings()
    extras = {}
    sc, results = simulate(scenario=scenario, compensation=compensation, robot=robot, warnings=warnings,
                           compensator=compensator, noise_seed=noise_seed, toolpath=toolpath, work_offset=work_offset,
                           progress=progress, tolerance_mm=tolerance_mm, extras=extras, stock=stock)
    summ = summary(results, sc, warnings)
    summ["compensator_model"] = model_description(sc, robot)
    summ["cycle_time_s"] = {label(r.compensation): r.cell.path.duration_s for r in results}
    plan = extras.get("feed_plan")
    if plan is not None:
        summ["feed_plan"] = plan.as_dict()
        summ["cycle_time_s"]["program"] = plan.program_cycle_time_s
    if advise:
        summ["advice"] = plan.advice
    budget_result = None
    if budget:
        budget_result = budgets.error_budget(extras["compensated_scenario"], robot, metric=budget_metric,
                                             ordered=budget_split == "ordered", progress=info if progress else None)
        summ["error_budget_mm"] = budgets.budget_json(budget_result)
        summ["error_budget_one_at_a_time_mm"] = dict(budget_result["contributions"],
                                                     interaction=budget_result["interaction"])
        if budget_result.get("ringing"):
            summ["error_budget_ringing"] = dict(budget_result["ringing"])
        summ["error_budget"] = budget_result
    if advise_out is not None:
        write_atomic(advise_out, advised_program(sc, plan))
    with RunFolder(out) as run_folder:
        written = write_outputs(sc, results, robot, run_folder, warnings)
    summ["run_id"] = run_folder.run_id
    summ["outputs"] = [str(Path(out) / w.split(" ")[0]) for w in written]
    if replay is not None:
        html, shown = replay_3d.replay_html(meshcat, sc, results, robot)
        write_atomic(replay, html)
        summ["replay"] = dict(shown, file=str(replay), bytes=len(html.encode()))
    if json_out is not None:
        emit_json(summ, json_out)
    if json_out != "-":
        print(format_table(summ))
        if plan is not None:
            print(format_feed_plan(plan, advise))
        if budget_result is not None:
            print(budgets.format_budget(budget_result))
    stderr = json_out == "-"  # the JSON has standard output
    wrote(out, ", ".join(written), folder=True, to_stderr=stderr)
    if advise_out is not None:
        wrote(advise_out, "the program with the advised feeds", to_stderr=stderr)
    if replay is not None:
        wrote(replay, f"3D replay, deflection magnified {shown['magnification']:g}x "
                      f"({summ['replay']['bytes'] / 1e6:.1f} MB; opens in a browser without a server)", to_stderr=stderr)
    wrote(json_out, "the summary", to_stderr=stderr)
    return 0
