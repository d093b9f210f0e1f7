"""``robstiff compensate-program JOB.yaml --out DIR``: offline compensation
for a cell with no wrist force sensor and no real-time interface.  The
compensator's model (the job's: identified, as a user has it) predicts the
deflection along the job's G-code program (diagrams/offline_compensation.py)
and the command writes, into DIR (all or nothing):

* ``<program>_compensated.nc``: the program in its own words, the cutting
  moves' coordinates corrected (model/gcode/writer.py);
* ``joint_reference.csv``: the path's joint references with the full
  (six-axis) correction, for cells that stream a reference
  (``robstiff compensate --reference``);
* ``<program>_compensated.mod``: an ABB RAPID module (model/rapid_writer.py)
  whose targets carry the corrected orientation too.

Then (unless ``--no-simulate``) the proof: the program as written and the
corrected one on the job's plant, surface error before and after, and the
corrected program with online compensation on top (plain, hearing the
measured wrench less the model's; preview, sending only what its scale
estimate adds to the program's correction)."""

import datetime
import sys
import tempfile
from pathlib import Path

import numpy as np

from robstiff_drake.commands.options import PROGRAM_MAX_CORRECTION_MM
from robstiff_drake.errors import InputError
from robstiff_drake.io import RunFolder, check_outputs, emit_json
from robstiff_drake.progress import info, progress, wrote


def _say(text):
    info(f"robstiff: compensate-program: {text}", file=sys.stderr)


def run(*, job, out, json_out=None, chord_mm=0.005, max_correction_mm=PROGRAM_MAX_CORRECTION_MM, robot_yaml=None,
        simulate=True, online=("plain", "preview"), show_progress=None, rounds=2, advise=False):
    """The command (module docstring); ``advise``: lower the feeds where
    ``simulate --advise`` would (the feed planner, diagrams/feed_plan.py)
    and correct the program with those feeds."""
    with tempfile.TemporaryDirectory(prefix="robstiff-compensate-program-") as tmp:
        return _run(job=job, out=out, json_out=json_out, chord_mm=chord_mm, max_correction_mm=max_correction_mm,
                    robot_yaml=robot_yaml, simulate=simulate, online=online, show_progress=show_progress,
                    rounds=rounds, advise=advise, tmp=Path(tmp))


def plan_feeds(sc, robot):
    """The feed plan of job ``sc`` as ``simulate --advise`` makes it."""
    import copy

    from robstiff_drake.diagrams.feed_plan import plan_feeds as planner

    return planner(copy.deepcopy(sc), robot)


def advised(sc, robot, text, program_file, folder):
    """(scenario, program, text, plan summary): the job with its program's
    feeds lowered where the feed planner lowers them (its program written
    into ``folder`` under its own name), or the job as it is when the plan
    lowers nothing (a plan is used only when it is predicted to improve on
    the program as written)."""
    from robstiff_drake.diagrams.scenario import load_scenario
    from robstiff_drake.model.feed_plan import check_rewritable, rewrite_program

    if not sc.path.tolerance_mm > 0:
        raise InputError(f"{sc.source}: --advise: no tolerance to hold: set path.tolerance_mm in the job")
    try:
        check_rewritable(text, sc._program.moves)
    except ValueError as e:
        raise InputError(f"--advise: {program_file}: {e}") from None
    _say("the feed planner (as simulate --advise): the job on the compensator's model")
    plan = plan_feeds(sc, robot)
    summary = {"adopted": bool(plan.adopted), "tolerance_mm": plan.tolerance_mm,
               "lowered": {str(line): [[a, b, v] for a, b, v in parts] for line, parts in plan.line_ranges.items()},
               "notes": list(plan.notes)}
    if not (plan.adopted and plan.line_ranges):
        return sc, sc._program, text, summary
    new_text = rewrite_program(text, sc._program.moves, plan.line_ranges)
    path = Path(folder) / program_file.name
    path.write_text(new_text)
    sc2 = load_scenario(sc.source, toolpath=path)
    # (messages name the user's program; their line numbers are those of the program with the planner's feeds)
    sc2._program.path = f"{program_file} (with the feed planner's feeds)"
    return sc2, sc2._program, new_text, summary


def _run(*, job, out, json_out, chord_mm, max_correction_mm, robot_yaml, simulate, online, show_progress, rounds,
         advise, tmp):
    from robstiff_drake.paths import find_scenario, unknown_scenario

    found = find_scenario(job)
    if found is None:
        raise InputError(unknown_scenario(job))
    job = str(found)
    check_outputs(inputs=[job], files={"--json": json_out}, folders={"--out": out})
    from robstiff_drake.diagrams import offline_compensation as oc
    from robstiff_drake.diagrams import offline_refinement
    from robstiff_drake.diagrams.scenario import load_scenario, resolve, scenario_robot
    from robstiff_drake.model.gcode.writer import ProgramWriteError, rewrite_corrected
    from robstiff_drake.model.program_correction import CorrectionError

    sc = load_scenario(job)
    if not sc.toolpath.program:
        raise InputError(f"{job}: the job has no G-code program (toolpath.program): compensate-program corrects a "
                         "program")
    program_file = resolve(sc, sc.toolpath.program)
    program = sc._program
    if program.warnings:
        raise InputError(f"{program.warnings[0]} (compensate-program writes a program the reader takes without a "
                         "warning: fix the input first)")
    text = program_file.read_bytes().decode("utf-8-sig")
    robot = scenario_robot(sc, robot_yaml)
    feeds = None
    if advise:
        sc, program, text, feeds = advised(sc, robot, text, program_file, tmp)

    # would the cut chatter? (the program's correction leaves the forces as they are; the proof runs' plant leaves
    # the regenerative chip out: diagrams/chatter_check.py) -- before the long computation
    from robstiff_drake.diagrams.chatter_check import check_job
    from robstiff_drake.io import Warnings

    warnings = Warnings()
    chatter = check_job(sc, robot, warnings)
    # a plant step unstable for the arm's modes (a user's robot file without motor inertias can have a wrist mode
    # the copied scenario's 2 ms does not hold) is refused here, not after the preview in the first refinement
    # round (23 s later on a KR 210 file): the step of what will run, the compensator's model of the cell (its
    # twin: every round and the predicted errors) and, with the proof runs, the plant (their stabilities differ:
    # the KR 210's plant needs 0.5 ms, stable to 0.79 ms, where its twin runs at 1 ms)
    from robstiff_drake.diagrams import user_model as user_models
    from robstiff_drake.diagrams.milling_cell import check_plant_step, planned_path

    _, _, q_plan = planned_path(sc, robot, robot.tool_point(where="the closed loop"))
    user_models.resolve(sc, robot, q_plan[0])  # (the identified model: predict takes the same)
    if simulate:  # the plant's own step first: its refusal is simulate's, word for word
        check_plant_step(sc, robot)
    # whose modes: `simulate` runs only the plant, and may have advised this step
    check_plant_step(offline_refinement.model_twin(sc, robot), robot,
                     whose="for the compensator's model of the cell (its twin: the identified stiffness, its damping "
                           "and the drives, which compensate-program runs and `simulate` does not; the plant may be "
                           "stable at this step)")

    def bar(total):
        return progress(total, show_progress, "preview along the program", unit="cycle")

    prediction = oc.predict(sc, robot, bar=bar, say=_say)
    history = []
    try:
        corrections = oc.move_corrections(sc, program, prediction, chord_mm=chord_mm,
                                          max_correction_mm=max_correction_mm)
        preview_corrections = corrections  # the RAPID module's positions (its targets carry the orientation too)
        if rounds > 0:  # the floor refined on the compensator's model (diagrams/offline_refinement.py)
            prediction, history = offline_refinement.refine(sc, robot, program, text, prediction, rounds=rounds,
                                                            chord_mm=chord_mm, max_correction_mm=max_correction_mm,
                                                            progress=show_progress, say=_say)
            corrections = oc.move_corrections(sc, program, prediction, chord_mm=chord_mm,
                                              max_correction_mm=max_correction_mm)
    except CorrectionError as e:
        raise InputError(str(e)) from None
    from robstiff_drake.diagrams.scenario_models import model_origin

    model = model_origin(sc)  # where the model came from: the user's files by their path, the seed of the rest
    try:
        plain_text, added = rewrite_corrected(text, program.moves, corrections)
    except ProgramWriteError as e:
        raise InputError(f"{program.path}:{e.line}: {str(e).split(': ', 1)[1]}") from None
    back = check_round_trip(plain_text, program, corrections, max_correction_mm, chord_mm, sc)
    # the RAPID module turns the tool too, so its targets take the preview's six-axis correction as it is (the
    # floor's refinement makes up for the 3-axis program's lost wrist share and would count it twice there)
    preview_text = plain_text if preview_corrections is corrections else \
        rewrite_corrected(text, program.moves, preview_corrections)[0]
    rapid_back = back if preview_corrections is corrections else check_round_trip(
        preview_text, program, preview_corrections, max_correction_mm, chord_mm, sc)
    # (InputError: a point out of reach)
    targets = oc.rapid_targets(sc, robot, program, preview_corrections, prediction, rapid_back.moves)
    with tempfile.TemporaryDirectory(prefix="robstiff-compensate-program-") as tmp:
        draft = Path(tmp) / program_file.name
        draft.write_text(plain_text)
        written_round = offline_refinement.best_round(history) if history else None
        before, after = offline_refinement.predicted_errors(sc, robot, prediction, draft, progress=show_progress,
                                                            say=_say,
                                                            after=history[written_round] if history else None)
    if written_round is not None and written_round != len(history) - 1:
        warnings.add(f"the floor's refinement did not converge: its last round leaves a largest predicted error of "
                     f"{history[-1]['max_abs']:.3f} mm on the compensator's model, round {written_round} "
                     f"{history[written_round]['max_abs']:.3f} mm; the program written is round {written_round}'s "
                     "(0: the preview's correction as written)")
    if after["max_abs"] > before["max_abs"]:
        warnings.add(f"the corrected program is predicted to cut worse than the program as written (largest error "
                     f"{after['max_abs']:.3f} mm against {before['max_abs']:.3f} mm, mean {after['mean']:+.3f} "
                     f"against {before['mean']:+.3f} mm, on the compensator's model): do not run it as it is; "
                     "check the job's model (its robot file, model.identified_json) and the chatter warning, if any")
    header = [f"ROBSTIFF COMPENSATE-PROGRAM {datetime.date.today().isoformat()}: {program_file.name} corrected for "
              f"the arm's deflection predicted by the {model} of {Path(job).name}",
              f"PREDICTED SURFACE ERROR MM ON THAT MODEL: BEFORE MEAN {before['mean']:+.3f} MAX "
              f"{before['max_abs']:.3f}, AFTER MEAN {after['mean']:+.3f} MAX {after['max_abs']:.3f}; CHORD "
              f"{chord_mm:g} MM"]
    if feeds is not None and feeds["lowered"]:
        header.append("FEEDS LOWERED WHERE THE FEED PLANNER (SIMULATE --ADVISE) LOWERS THEM, TOLERANCE "
                      f"{feeds['tolerance_mm']:g} MM")
    corrected_text, _ = rewrite_corrected(text, program.moves, corrections, header)
    stem = program_file.stem
    names = {"program": f"{stem}_compensated.nc", "rapid": f"{stem}_compensated.mod",
             "reference": "joint_reference.csv"}
    largest = max((c.max_correction_mm for c in corrections.values()), default=0.0)
    summary = {"program": str(Path(out) / names["program"]), "model": model,
               "rapid_module": str(Path(out) / names["rapid"]),
               "joint_reference": str(Path(out) / names["reference"]),
               "predicted_error_mm": {"before": _two(before), "after": _two(after)},
               "predicted_error_by_round_mm": [_two(h) for h in history],
               "refinement_round_written": written_round,
               "refinement_rounds": int(rounds),
               "segments_added": int(added), "corrected_moves": len(corrections),
               "max_correction_mm": float(largest), "chord_mm": chord_mm,
               "prediction_seconds": float(prediction.seconds), "simulated": None, "feed_plan": feeds,
               "chatter_check": chatter, "warnings": []}
    with RunFolder(out) as folder:
        folder.write(names["program"], corrected_text)
        folder.write(names["reference"], oc.reference_text(robot, prediction, folder.run_id, job, model,
                                                             period_s=sc.controller.period_ms / 1e3))
        module = oc.rapid_text(sc, robot, stem, targets, header)
        folder.write(names["rapid"], module)
        if simulate:
            summary["simulated"] = oc.proof_runs(sc, robot, folder.file(names["program"]), prediction,
                                                 modes=("off",) + tuple(online), progress=show_progress, say=_say)
            from robstiff_drake.diagrams.rapid_proof import rapid_run

            _say("proof: the RAPID module read back and run on the plant, no online compensation")
            with tempfile.TemporaryDirectory(prefix="robstiff-compensate-program-") as tmp:
                source = Path(tmp) / program_file.name
                source.write_text(preview_text)
                summary["simulated"]["RAPID module (read back)"] = rapid_run(sc, robot, module, source, prediction,
                                                                             progress=show_progress)
    summary["run_id"] = folder.run_id
    note = rapid_note(robot, names["rapid"])
    if note:
        warnings.add(note)
    summary["warnings"] = list(warnings)
    if json_out is not None:
        emit_json(summary, json_out)
    stderr = json_out == "-"
    show = (lambda t: print(t, file=sys.stderr)) if stderr else print
    show(f"predicted surface error on the compensator's model (mm): before mean {before['mean']:+.3f} max "
         f"{before['max_abs']:.3f}; after mean {after['mean']:+.3f} max {after['max_abs']:.3f}")
    if history:
        show("the floor refined on the model, its predicted error by round (mm): " + "; ".join(
            f"mean {h['mean']:+.3f} max {h['max_abs']:.3f}" + (" (written)" if k == written_round
                                                               and k != len(history) - 1 else "")
            for k, h in enumerate(history)))
    show(f"{len(corrections)} cutting moves corrected (largest correction {largest:.3f} mm), {added} blocks added "
         f"for the chord tolerance {chord_mm:g} mm")
    if summary["simulated"]:
        show("surface error on the plant, scanned against the programmed surface (mm):")
        for label, st in summary["simulated"].items():
            show(f"  {label:<34} mean {st['mean']:+.3f}  rms {st['rms']:.3f}  max {st['max_abs']:.3f}")
    wrote(out, ", ".join(names.values()), folder=True, to_stderr=stderr)
    wrote(json_out, "the summary", to_stderr=stderr)
    return 0


def _two(stats):
    return {"mean": float(stats["mean"]), "max_abs": float(stats["max_abs"])}


def check_round_trip(text, program, corrections, max_correction_mm, chord_mm, sc):
    """The written program read back by the project's reader: no warning,
    the same number of motion blocks as written, rapids unchanged, and
    every corrected point within the clamp of the path the controller runs
    (InputError otherwise: a bug, reported as such rather than written)."""
    from robstiff_drake.model.gcode.program import read_program

    tp = sc.toolpath
    back = read_program(text, f"{program.path} (corrected)", decimal_point=tp.decimal_point,
                        block_delete=tp.block_delete)
    if back.warnings:
        raise InputError(f"the corrected program reads with a warning: {back.warnings[0]}")
    # a rapid's words are not touched; an axis it does not name stays where the corrected cut left it
    rapids = [m for m in program.moves if m.kind == "rapid"]
    rapids_back = [m for m in back.moves if m.kind == "rapid"]
    largest = max((c.max_correction_mm for c in corrections.values()), default=0.0)
    if len(rapids) != len(rapids_back) or any(
            np.max(np.abs(np.subtract(a.end_mm, b.end_mm))) > largest + chord_mm + 1e-3
            for a, b in zip(rapids, rapids_back)):
        raise InputError("the corrected program's rapids differ from the input's (a bug: please report it)")
    expected = len(program.moves) + sum(len(c.pieces) - 1 for c in corrections.values())
    if len(back.moves) != expected:
        raise InputError(f"the corrected program reads as {len(back.moves)} moves, {expected} written (a bug)")
    return back


__all__ = ["run", "check_round_trip"]


def rapid_note(robot, rapid_name):
    """For a robot not made by ABB: one line saying that the RAPID module
    is ABB's and what runs on this robot instead (no FANUC TP / KRL
    program is written); None for an ABB."""
    maker = str(robot.manufacturer).strip()
    if maker.upper() == "ABB":
        return None
    who = maker if maker and maker != "-" else "this"
    return (f"{rapid_name} is an ABB RAPID module, for an IRC5; on this {who} robot ({robot.name}) run the corrected "
            "G-code through the cell's own CAM-to-robot path, or stream joint_reference.csv with `compensate "
            "--reference-is-corrected` (no FANUC TP or KUKA KRL program is written)")
