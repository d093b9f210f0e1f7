"""The scenario's path and the joint references along it: the planned
path (model/path.PlannedPath), its IK every reference period once per
process (and on disk: diagrams/reference_cache.py), a controller's
references with its own kinematic error, and a feed planner's retiming."""

import numpy as np

from robstiff_drake.diagrams import reference_cache
from robstiff_drake.diagrams.scenario import planned_path as scenario_path
from robstiff_drake.errors import InputError
from robstiff_drake.model import kinematics as kin
from robstiff_drake.model.path import PathError

_REFERENCES = {}  # IK along a path, reused by the runs of a sweep in one process


def planned_path(sc, robot, tool):
    """(PlannedPath, times, joint references) of the scenario's path; the IK
    is done once per process for a given path, robot file and tool, and
    kept on disk (diagrams/reference_cache.py)."""
    p = sc.path
    try:
        path = scenario_path(sc)
        if path.speed_overrides:  # the feed planner's: the same geometry, other timing
            base, t_base, q_base = planned_path_without_overrides(sc, robot, tool)
            return path, *retimed_references(base, t_base, q_base, path, p.reference_period_ms / 1e3)
        key = (path.signature(), p.reference_period_ms, robot.source, tuple(np.round(tool, 12)),
               robot.q_lower_rad.tobytes(), robot.q_upper_rad.tobytes())
        if key not in _REFERENCES:
            _REFERENCES[key] = reference_cache.joint_references(path, robot, tool, p.reference_period_ms / 1e3)
    except PathError as e:  # (a program's path: its file:line, the first that leaves the robot's reach or limits)
        raise InputError(f"{e.where or f'{sc.source}: path'}: {e} (robot {robot.name})") from None
    t_ref, q_ref = _REFERENCES[key]
    ctrl = getattr(sc, "_controller_robot", None)
    if ctrl is not None:  # a controller whose kinematic model is not the arm's (diagrams/budget.py)
        ckey = key + (ctrl.dh.home_rad.tobytes(), ctrl.dh.a_m.tobytes(), ctrl.dh.d_m.tobytes(),
                      ctrl.dh.alpha_rad.tobytes())
        if ckey not in _REFERENCES:
            _REFERENCES[ckey] = (t_ref, references_with_kinematic_error(path, t_ref, robot, ctrl, tool))
        t_ref, q_ref = _REFERENCES[ckey]
    return path, t_ref, q_ref


def references_with_kinematic_error(path, t_ref, robot, ctrl, tool):
    """The joint references a controller with the kinematic model ``ctrl``
    (its own DH, e.g. joint zeros off by a mastering error) sends along the
    path, the work offset touched off with the real arm at the path's
    first point (so the part starts where it is commanded; the error grows
    over the part, as path accuracy does)."""
    from robstiff_drake.model import ik, ik_path

    qs = np.empty((len(t_ref), 6))
    if not len(t_ref):
        return qs
    p = path.positions(t_ref)
    q0 = ik.solve_for(ctrl, ik.tool_down_pose(p[0], path.yaw), tool)
    shift = kin.tool_pose(robot.dh, q0, tool)[:3, 3] - p[0]  # the real arm's offset at the first point
    qs[0] = ik.solve_for(ctrl, ik.tool_down_pose(p[0] - shift, path.yaw), tool, q_ref_rad=q0)
    # the rest warm-started sample by sample from there (model/ik_path: the same answers, vectorised)
    qs[1:] = ik_path.solve_path(ctrl, ik_path.tool_down_poses(p[1:] - shift, path.yaw), tool, qs[0])
    return qs


def planned_path_without_overrides(sc, robot, tool):
    """planned_path of the scenario's program as written (no feed overrides)."""
    saved = getattr(sc, "_feed_overrides", None)
    sc._feed_overrides = None
    try:
        return planned_path(sc, robot, tool)
    finally:
        sc._feed_overrides = saved


def retimed_references(base, t_base, q_base, path, dt_s):
    """Joint references of ``path`` (the geometry of ``base``, other speeds)
    every dt_s: the base path's IK solutions as a function of arc length (a
    C2 cubic spline through them), at the new path's arc length."""
    from scipy.interpolate import CubicSpline

    s = np.array([base.arc_length(t) for t in t_base])
    keep = np.r_[True, np.diff(s) > 1e-12]
    spline = CubicSpline(s[keep], q_base[keep], axis=0)
    ts = np.arange(0.0, path.duration_s + 0.5 * dt_s, dt_s)
    return ts, spline(np.array([path.arc_length(t) for t in ts]))
