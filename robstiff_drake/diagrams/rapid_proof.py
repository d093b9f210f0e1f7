"""The RAPID module of a corrected program run on the plant: read back by
the project's own reader (model/rapid_reader.py) and run as the robot
controller would run it, its positions along the planned path of the
program it was written from (the blocks with the preview's correction:
each target's position is one block's end, checked here) and its
orientation turned from target to target (a spherical interpolation along
the path's arc length, as a controller's linear or circular move turns
the tool), each reference sample solved by the project's IK.  Zones are
those of the program's plan."""

import copy

import numpy as np

from robstiff_drake.model import kinematics as kin


def rapid_reference(sc, robot, module_text, program_file, tool_m):
    """(times s, (N, 6) rad): the joint references of the RAPID module
    ``module_text`` written from the program ``program_file`` of job
    ``sc``.  ValueError when the module's targets are not that program's
    blocks."""
    from scipy.spatial.transform import Rotation, Slerp

    from robstiff_drake.diagrams.milling_cell import planned_path
    from robstiff_drake.diagrams.offline_compensation import work_rotation
    from robstiff_drake.diagrams.scenario import load_scenario
    from robstiff_drake.diagrams.toolpath import work_transform_mm
    from robstiff_drake.model import ik
    from robstiff_drake.model.rapid_reader import read_moves, rotation

    moves = read_moves(module_text)
    sc2 = load_scenario(sc.source, toolpath=program_file)
    program = sc2._program
    if len(moves) != len(program.moves) + 1:
        raise ValueError(f"the module has {len(moves)} motions, the program {len(program.moves)} blocks (+1)")
    path, t_ref, q_ref = planned_path(sc2, robot, tool_m)
    to_base = work_transform_mm(sc2.toolpath)
    R_w = work_rotation(sc2)
    keys_p, keys_R = [], []
    for rm, m in zip(moves, [None] + list(program.moves)):
        end = np.asarray(program.moves[0].start_mm if m is None else m.end_mm, dtype=float)
        if np.max(np.abs(rm.targets[-1][0] - end)) > 2e-3:
            raise ValueError(f"module line {rm.line}: its target is not the program's block end {end}")
        for p, q in rm.targets:
            keys_p.append(to_base(p) / 1e3)
            keys_R.append(R_w @ rotation(q))
    s_keys, s = [], 0.0
    for p in keys_p:  # where each target lies along the plan, in order
        s = path.project(p, s, max_step_m=0.05, iterations=50)
        s_keys.append(s)
    s_keys = np.maximum.accumulate(np.asarray(s_keys))
    keep = np.r_[True, np.diff(s_keys) > 1e-9]
    slerp = Slerp(s_keys[keep], Rotation.from_matrix(np.asarray(keys_R)[keep]))
    s_t = np.clip([path.arc_length(t) for t in t_ref], s_keys[keep][0], s_keys[keep][-1])
    R_t = slerp(s_t).as_matrix()
    q_out, q_prev = [], q_ref[0]
    for k in range(len(t_ref)):
        T = kin.tool_pose(robot.dh, q_ref[k], tool_m)
        T[:3, :3] = R_t[k]
        q_prev = ik.solve_for(robot, T, tool_m, q_ref_rad=q_prev)
        q_out.append(q_prev)
    return np.asarray(t_ref), np.asarray(q_out)


def rapid_run(sc, robot, module_text, program_file, prediction, *, progress=None, plant_reads="programmed"):
    """The plant's floor error (mm stats) of the RAPID module, scanned
    against the programmed surface (no online compensation).

    ``plant_reads``: the path the plant reads the chip's direction and feed
    off (systems/milling_force.motion: the path's direction and the tool's
    progress along it at the tool's nearest point): "programmed", the job's
    program as written (where the corrected tool goes, as for the joint
    reference's proof), or "module", the corrected program's own path (off
    the tool's by the correction: where the correction turns quickly, its
    short blocks turn the plant's chip direction though the tool does not
    turn; measured on face_and_contour, the same joint reference run with
    the plant reading the corrected program's path leaves +0.038 / 0.083 mm
    against -0.007 / 0.025, the difference all in the dip where the cutter
    leaves the plate)."""
    from robstiff_drake.diagrams.experiment import run_cut
    from robstiff_drake.diagrams.milling_cell import build_milling_cell
    from robstiff_drake.diagrams.offline_compensation import _short, scanned_against_program
    from robstiff_drake.diagrams.scenario import load_scenario

    if plant_reads not in ("programmed", "module"):
        raise ValueError(f"plant_reads: 'programmed' or 'module', not {plant_reads!r}")
    ref = rapid_reference(sc, robot, module_text, program_file, prediction.tool_m)
    run_sc = copy.deepcopy(load_scenario(sc.source, toolpath=program_file) if plant_reads == "module" else sc)
    cell = build_milling_cell(run_sc, robot, compensation=False, q_reference=ref)
    res = run_cut(run_sc, robot, compensation=False, cell=cell, progress=progress)
    return _short(scanned_against_program(res, prediction.path))
