"""Offline compensation on the face-and-contour job
(diagrams/face_and_contour.yaml + .nc): the program corrected by the
compensator's identified model (robstiff compensate-program), and its
proof on the plant (the plant's own physics), against the program as
written and the online compensators of docs/results.md.

Prints the table of docs/offline_compensation.md and writes
docs/offline_compensation_path.png: the corrected path against the
programmed one (the correction magnified), and the correction along the
path.

    python studies/offline_compensation.py     # about 7 minutes on a 2-core machine
"""

import sys
import tempfile
from pathlib import Path

import numpy as np

from robstiff_drake.commands.compensate_program import check_round_trip
from robstiff_drake.diagrams import offline_compensation as oc
from robstiff_drake.diagrams.scenario import load_scenario, resolve, scenario_robot
from robstiff_drake.model.gcode.program import read_program
from robstiff_drake.model.gcode.writer import rewrite_corrected

ROOT = Path(__file__).resolve().parents[1]
JOB = ROOT / "diagrams" / "face_and_contour.yaml"
FIGURE = ROOT / "docs" / "offline_compensation_path.png"
MAGNIFY = 30.0
ROUNDS = 2  # the floor's refinement on the model (compensate-program's --refine-rounds default)


def work_frame(sc):
    """base frame mm (n, 3) -> the program's frame mm."""
    R = oc.work_rotation(sc)
    offset = np.asarray(sc.toolpath.work_offset_mm, dtype=float)
    return lambda p: (np.asarray(p, dtype=float) - offset) @ R


def figure(sc, program, back, prediction, path_png, first=None):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from robstiff_drake.model import program_correction as pc

    fig, (ax, bx) = plt.subplots(1, 2, figsize=(12, 5))
    frac = np.linspace(0.0, 1.0, 200)
    for m in program.moves:
        p = pc.move_points(m, frac)
        ax.plot(p[:, 0], p[:, 1], color="0.6" if m.kind == "rapid" else "k", lw=1.0,
                ls=":" if m.kind == "rapid" else "-")
    # the planned path (corners blended) moved by the predicted correction, magnified; the written blocks' ends
    # placed on it by their nearest point of the planned path, their offset magnified alike
    to_work = work_frame(sc)
    planned = to_work(np.array([prediction.path.point_at(x) for x in prediction.s_m]) * 1e3)
    d = prediction.delta_mm @ oc.work_rotation(sc)
    cut = np.abs(d).max(axis=1) > 1e-4
    moved = planned + MAGNIFY * d
    ax.plot(np.where(cut, moved[:, 0], np.nan), np.where(cut, moved[:, 1], np.nan), color="tab:red", lw=0.8,
            label=f"corrected path (offset x{MAGNIFY:g})")
    ends = np.array([b.end_mm for b in back.moves if b.kind != "rapid"])
    j = np.array([int(np.argmin(np.linalg.norm(planned - e, axis=1))) for e in ends])
    pts = planned[j] + MAGNIFY * (ends - planned[j])
    ax.plot(pts[:, 0], pts[:, 1], "o", color="tab:red", ms=2.5, label="written block ends (offset alike)")
    ax.plot([], [], color="k", label="programmed (G1/G2/G3)")
    ax.plot([], [], color="0.6", ls=":", label="rapids (untouched)")
    ax.set_aspect("equal")
    ax.set_xlabel("X (mm, program)")
    ax.set_ylabel("Y (mm, program)")
    ax.set_title("corrected path against the programmed one")
    ax.legend(loc="lower right", fontsize=8)
    s = prediction.s_m * 1e3
    for j, name in enumerate("XYZ"):
        bx.plot(s, d[:, j], label=f"{name}" + (" (floor refined)" if j == 2 and first is not None else ""))
    if first is not None:
        bx.plot(s, (first.delta_mm @ oc.work_rotation(sc))[:, 2], color="0.5", lw=0.8, ls="--",
                label="Z, the preview's correction")
    bx.set_xlabel("distance along the planned path (mm)")
    bx.set_ylabel("correction (mm, program frame)")
    bx.set_title("the correction along the path (before the chord split)")
    bx.grid(alpha=0.3)
    bx.legend()
    fig.tight_layout()
    fig.savefig(path_png, dpi=110)
    plt.close(fig)


def position_only(sc, robot, prediction):
    """The plant's surface error (mm) with the six-axis correction turned
    into tool-point positions at the planned (vertical) tool orientation by
    the IK, streamed as the joint reference at its own times: what a 3-axis
    correction can do at best, with no program in between."""
    import copy

    from robstiff_drake.diagrams.experiment import run_cut
    from robstiff_drake.diagrams.milling_cell import build_milling_cell
    from robstiff_drake.model import ik
    from robstiff_drake.model import kinematics as kin

    t, q6 = oc.corrected_reference(prediction)
    q_ref, tool = prediction.q_ref_rad, prediction.tool_m
    qs = []
    for k in range(len(t)):
        T = kin.tool_pose(robot.dh, q6[k], tool)
        T[:3, :3] = kin.tool_pose(robot.dh, q_ref[k], tool)[:3, :3]
        qs.append(ik.solve_for(robot, T, tool, q_ref_rad=q_ref[k]))
    run_sc = copy.deepcopy(sc)
    cell = build_milling_cell(run_sc, robot, compensation=False, q_reference=(t, np.array(qs)))
    return run_cut(run_sc, robot, compensation=False, cell=cell).surface_error_mm


def tilt_share(res, path):
    """The run's floor error (mm stats) with the tool's actual tilt left out
    (a level face at the actual tool point): how much of the floor's error
    is the tool's tilt (the wrist's share a 3-axis program cannot carry)."""
    from dataclasses import replace

    from robstiff_drake.diagrams.experiment import scan_along_path
    from robstiff_drake.model import kinematics as kin
    from robstiff_drake.model.surface import surface_error_stats

    cell = replace(res.cell, path=path)
    t, x = res.logs["state"]
    T6 = kin.frames(cell.robot.dh, x[:, :6])[:, 6]
    p = T6[:, :3, 3] + T6[:, :3, :3] @ cell.tool_m
    up = np.tile([0.0, 0.0, 1.0], (len(t), 1))
    lines = scan_along_path(cell, path.positions(t), up, p, up, cell.force_model.cutter.radius_m)
    st = surface_error_stats(np.concatenate([ln.error_m[np.isfinite(ln.error_m)] for ln in lines]))
    return {k: st[k] for k in ("mean", "rms", "max_abs")}


def reference_reading(sc, robot, program_file, prediction):
    """The plant's floor error (mm stats) of the corrected joint reference
    with the plant reading the chip's direction and feed off the corrected
    program ``program_file``'s path instead of the programmed one (the
    RAPID module's proof with the plant reading the module's own path)."""
    import copy

    from robstiff_drake.diagrams.experiment import run_cut
    from robstiff_drake.diagrams.milling_cell import build_milling_cell

    run_sc = copy.deepcopy(load_scenario(sc.source, toolpath=program_file))
    cell = build_milling_cell(run_sc, robot, compensation=False, q_reference=oc.corrected_reference(prediction))
    return oc._short(oc.scanned_against_program(run_cut(run_sc, robot, compensation=False, cell=cell),
                                                prediction.path))


def rapid_against_reference(sc, robot, module, program_file, prediction):
    """The RAPID module's joint references against the corrected joint
    reference's at the same times, where the model's cutting force is on
    (above 10 N) and the plan is level: the largest height difference of the tool point (mm),
    the largest turn between the tool's orientations (mrad), the range of
    their horizontal distance (mm); and the plant's floor error (mm stats)
    of the joint reference played on the corrected path's clock (each
    planned point when the corrected program's path passes it)."""
    import copy

    from scipy.spatial.transform import Rotation

    from robstiff_drake.diagrams.experiment import run_cut
    from robstiff_drake.diagrams.milling_cell import build_milling_cell, planned_path
    from robstiff_drake.diagrams.rapid_proof import rapid_reference
    from robstiff_drake.model import kinematics as kin
    from robstiff_drake.model.program_correction import clock_on

    tool = prediction.tool_m
    t_r, q_r = rapid_reference(sc, robot, module, program_file, tool)
    t_j, q_j = oc.corrected_reference(prediction)
    q_same = np.column_stack([np.interp(t_r, t_j, q_j[:, j]) for j in range(6)])
    force = np.interp(t_r, prediction.u_s, np.linalg.norm(prediction.sensor_wrench[:, :3], axis=1))
    z = np.array([prediction.path.position(t)[2] for t in t_r])
    on = (force > 10.0) & (np.abs(np.gradient(z, t_r)) < 1e-4)  # cutting, the plan level (not the plunge, the lift)
    T_r = np.array([kin.tool_pose(robot.dh, q, tool) for q in q_r[on]])
    T_j = np.array([kin.tool_pose(robot.dh, q, tool) for q in q_same[on]])
    d = (T_r[:, :3, 3] - T_j[:, :3, 3]) * 1e3
    turn = [np.linalg.norm(Rotation.from_matrix(a[:3, :3].T @ b[:3, :3]).as_rotvec()) * 1e3 for a, b in zip(T_j, T_r)]
    horizontal = np.hypot(d[:, 0], d[:, 1])
    corrected, _, _ = planned_path(load_scenario(sc.source, toolpath=program_file), robot, tool)
    q_late = np.column_stack([np.interp(t_r, clock_on(prediction.path, corrected, t_j), q_j[:, j]) for j in range(6)])
    run_sc = copy.deepcopy(load_scenario(sc.source, toolpath=program_file))
    cell = build_milling_cell(run_sc, robot, compensation=False, q_reference=(t_r, q_late))
    late = oc._short(oc.scanned_against_program(run_cut(run_sc, robot, compensation=False, cell=cell),
                                                prediction.path))
    return {"height_mm": float(np.abs(d[:, 2]).max()), "turn_mrad": float(max(turn)),
            "along_mm": (float(np.percentile(horizontal, 5)), float(horizontal.max()))}, late


def double_correction(sc, robot, program_file, prediction):
    """The plant's floor error (mm stats) with online plain compensation
    on top of the corrected program hearing the whole measured wrench (not
    the measured less the model's): the deflection the program already
    corrects is corrected again."""
    import copy

    from robstiff_drake.diagrams import user_model as user_models
    from robstiff_drake.diagrams.experiment import run_cut

    run_sc = copy.deepcopy(load_scenario(sc.source, toolpath=program_file))
    run_sc.controller.mode = "plain"
    user_models.resolve(run_sc, robot, prediction.q_ref_rad[0])
    res = run_cut(run_sc, robot, compensation=True)
    return oc._short(oc.scanned_against_program(res, prediction.path))


def main():
    from robstiff_drake.diagrams.experiment import run_cut
    from robstiff_drake.diagrams import offline_refinement
    from robstiff_drake.diagrams.offline_refinement import refine
    from robstiff_drake.diagrams.rapid_proof import rapid_run

    sc = load_scenario(JOB)
    robot = scenario_robot(sc)
    program = sc._program
    text = resolve(sc, sc.toolpath.program).read_text()
    prediction = oc.predict(sc, robot)
    corr0 = oc.move_corrections(sc, program, prediction, chord_mm=0.005, max_correction_mm=1.0)
    refined, history = refine(sc, robot, program, text, prediction, rounds=ROUNDS, chord_mm=0.005,
                              max_correction_mm=1.0)
    corr = oc.move_corrections(sc, program, refined, chord_mm=0.005, max_correction_mm=1.0)
    written, added = rewrite_corrected(text, program.moves, corr)
    check_round_trip(written, program, corr, 1.0, 0.005, sc)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        draft0 = Path(tmp) / "round0" / "face_and_contour_compensated.nc"
        draft0.parent.mkdir()
        draft0.write_text(rewrite_corrected(text, program.moves, corr0)[0])
        draft = Path(tmp) / "face_and_contour_compensated.nc"
        draft.write_text(written)
        before, after = offline_refinement.predicted_errors(sc, robot, refined, draft,
                                                            after=history[offline_refinement.best_round(history)])
        print("  predicted on the model: done", file=sys.stderr, flush=True)
        res0 = run_cut(load_scenario(sc.source, toolpath=draft0), robot, compensation=False)
        plant0 = oc._short(oc.scanned_against_program(res0, prediction.path))
        proof = oc.proof_runs(sc, robot, draft, refined, modes=("off", "plain", "preview"))
        res1 = run_cut(load_scenario(sc.source, toolpath=draft), robot, compensation=False)
        double = double_correction(sc, robot, draft, refined)
        back0 = check_round_trip(draft0.read_text(), program, corr0, 1.0, 0.005, sc)
        module = oc.rapid_text(sc, robot, "face_and_contour",
                               oc.rapid_targets(sc, robot, program, corr0, prediction, back0.moves), ["study"])
        rapid = rapid_run(sc, robot, module, draft0, prediction)
        rapid_own = rapid_run(sc, robot, module, draft0, prediction, plant_reads="module")
        reading = reference_reading(sc, robot, draft0, prediction)
        against, late = rapid_against_reference(sc, robot, module, draft0, prediction)
    rows.append(("program as written", "compensator's model (twin)", before))
    for k, h in enumerate(history):
        name = "corrected program, the preview's correction as written" if k == 0 else \
            f"corrected program, floor refined on the model, round {k}"
        rows.append((name, "compensator's model (twin)", h))
    rows.append(("uncompensated", "plant", proof.pop("uncompensated")))
    rows.append(("corrected program, the preview's correction as written", "plant", plant0))
    rows.append(("  the same, the tool's tilt left out (a level face at the tool point)", "plant",
                 tilt_share(res0, prediction.path)))
    best = offline_refinement.best_round(history)
    rows.append((f"corrected program, floor refined (round {best}, the best of {ROUNDS} on the model): the written "
                 "program", "plant",
                 proof.pop("corrected program")))
    rows.append(("  the same, the tool's tilt left out", "plant", tilt_share(res1, prediction.path)))
    for label, st in proof.items():
        if label.endswith("preview"):
            label += " (only what its scale estimate adds)"
        rows.append((label, "plant", st))
    rows.append(("corrected program + online plain on the whole measured wrench (the deflection corrected twice)",
                 "plant", double))
    rows.append(("RAPID module (read back; the preview's correction, the tool turned)", "plant", rapid))
    rows.append(("  the same, the plant reading the chip's direction off the module's own path", "plant", rapid_own))
    rows.append(("corrected joint reference, the plant reading the chip's direction off that path", "plant",
                 reading))
    rows.append(("corrected joint reference on the corrected path's clock (each point when that path passes it)",
                 "plant", late))
    rows.append(("position-only correction (no program, the tool kept vertical)", "plant",
                 position_only(sc, robot, prediction)))
    figure(sc, program, read_program(written, "c.nc"), refined, FIGURE, prediction)
    print(f"\nface_and_contour.nc, identified model: {len(corr)} cutting moves corrected, {added} blocks added "
          f"(chord 0.005 mm), largest correction {max(c.max_correction_mm for c in corr.values()):.3f} mm; "
          f"prediction {prediction.seconds:.1f} s\n")
    print("| run | where | mean (mm) | RMS (mm) | max abs (mm) |")
    print("|---|---|---|---|---|")
    for label, where, st in rows:
        print(f"| {label} | {where} | {st['mean']:+.3f} | {st['rms']:.3f} | {st['max_abs']:.3f} |")
    print(f"\nthe RAPID module's joint references against the joint reference's at the same times, while the model's "
          f"force is on and the plan level: height within {against['height_mm']:.4f} mm, orientation within {against['turn_mrad']:.3f} "
          f"mrad, {against['along_mm'][0]:.2f} to {against['along_mm'][1]:.2f} mm apart horizontally (5th percentile "
          "to largest)")
    print(f"\nwrote {FIGURE.relative_to(ROOT)}")


if __name__ == "__main__":
    main()
