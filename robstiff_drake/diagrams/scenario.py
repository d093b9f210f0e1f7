"""Scenario files (diagrams/*.yaml): dataclasses read with Drake's
``yaml_load_typed``, after a check of the file against the schema written
next to each field (range and unit: diagrams/schema.py), so that an unknown,
duplicated, mistyped or out-of-range key is one line naming the file, line,
key and allowed range; then checked for what depends on several keys and
for the size of the run, before anything is built.

Units are in the key names.  Paths to other files (an identification JSON,
a payload-calibration YAML) are relative to the scenario file.  Every file
the scenario names is noted as an input of the command when the scenario is
loaded (io.note_input: no output may overwrite or contain it), and read
through user_files (bounded, no YAML aliases).
"""

from pathlib import Path

import numpy as np

from robstiff_drake.command import note_input
from robstiff_drake.diagrams import toolpath as program_setup
from robstiff_drake.diagrams.scenario_schema import Scenario, ToolpathConfig
from robstiff_drake.diagrams.schema import check_object, validate
from robstiff_drake.errors import InputError
from robstiff_drake.model.path import PathError, PlannedPath
from robstiff_drake.model.program_path import program_pieces
from robstiff_drake.user_files import read_user_text


# Cross-key limits.  A face mill's tooth pitch pi D / n: the densest
# (extra-close pitch) face mills in insert makers' catalogues have about
# 8-10 mm; below 6 mm there is no room for an insert and its chip pocket.
MIN_TOOTH_PITCH_MM = 6.0
# Sizes a run may take: at about 0.2 ms of wall time per plant step (the
# averaged block pass), 2e6 steps is about 7 minutes; the logs then hold
# about 20 floats per step.  Beyond these a typo (a feed of 1e-6 mm/s, a
# dwell of 1e9 s) would allocate for hours before failing.
MAX_PLANT_STEPS = 2_000_000
MAX_SENSOR_SAMPLES = 10_000_000
MAX_REFERENCE_SAMPLES = 1_000_000
MAX_TOOTH_SAMPLES_PER_STEP = 2000
MAX_FILTER_TAPS = 5000
MAX_SCAN_POINTS = 2_000_000


def load_scenario(path, toolpath=None, work_offset=None, stock=None):
    """Read and check a scenario file; InputError (one line naming the file,
    line, key and allowed range) on anything wrong, before anything is built.
    ``toolpath``: a G-code program that replaces the scenario's path (the
    command line's --toolpath, relative to the working folder);
    ``work_offset``: the command line's --work-offset "X,Y,Z[,ROT_DEG]"
    (mm, deg), replacing toolpath.work_offset_mm (and work_rotation_deg);
    ``stock``: the command line's --stock "X0,X1,Y0,Y1,TOP" (mm, base
    frame), one box replacing workpiece.boxes_mm."""
    from pydrake.common.yaml import yaml_load_typed

    path = Path(path)
    text_ = read_user_text(path, "scenario file")
    try:
        lines = validate(Scenario, path, text_)
    except InputError as e:
        if "plant.damping_ratio: unknown key" in str(e):  # the key before the damping was modal
            raise InputError(str(e).split(": unknown key")[0] + ": replaced by plant.modal_damping_ratio (one "
                             "ratio for every mode) or plant.damping_ratios (one per mode): the plant's damping "
                             "is modal now, not stiffness-proportional") from None
        if "model.damping_ratio: unknown key" in str(e):  # preview's key before its damping was modal
            raise InputError(str(e).split(": unknown key")[0] + ": replaced by model.damping_ratios (the modal "
                             "damping ratio of each mode, or one for every mode; empty: the plant section's "
                             "stated ratios)") from None
        raise
    try:
        sc = yaml_load_typed(schema=Scenario, data=text_) if text_.strip() else Scenario()
    except (RuntimeError, ValueError, TypeError) as e:  # validate() lets nothing through that gets here
        msg = " ".join(str(e).split())
        raise InputError(f"{path}: {msg}") from None
    sc.source = str(path)
    sc._key_lines = lines
    if ("cutter", "spindle_rating_W") not in lines:  # the spindle-power check's rating, not invented silently
        from robstiff_drake.command import input_note

        input_note(SPINDLE_RATING_NOT_STATED.format(path=path, rating_kW=sc.cutter.spindle_rating_W / 1e3))
    if toolpath is not None:
        note_input(toolpath, "--toolpath")
        sc.toolpath.program = str(Path(toolpath).resolve())
        sc._program_label = str(toolpath)  # (its messages name it as given)
        sc.path.waypoints_mm = []
    if work_offset is not None:
        offset, rotation = program_setup.parse_work_offset(work_offset, ToolpathConfig)
        sc.toolpath.work_offset_mm = offset
        if rotation is not None:
            sc.toolpath.work_rotation_deg = rotation
    if stock is not None:
        from robstiff_drake.diagrams.scenario_schema import MAX_COORD_MM

        sc.workpiece.boxes_mm = [program_setup.parse_stock(stock, MAX_COORD_MM)]
    sc._work_offset_given = work_offset is not None
    for key, named in named_files(sc).items():
        note_input(named, f"{key} of {path}")
    apply_program(sc)
    check_scenario(sc)
    return sc


# A scenario without cutter.spindle_rating_W gets the schema's default (scenario_schema.CutterConfig): the paper's
# spindle, which every run's spindle-power check then uses; said in a note (text and the JSON's 'notes').
SPINDLE_RATING_NOT_STATED = ("{path}: cutter.spindle_rating_W not stated: the spindle-power check assumes "
                             "{rating_kW:.2f} kW, the paper's spindle (SETCO 5 HP, its Table 3); state your "
                             "spindle's rated power (W) there")


def named_files(sc):
    """{key: path} of the files the scenario names (its program, robot file,
    identification JSON, payload calibration), resolved against its folder."""
    out = {}
    for key, value in (("toolpath.program", sc.toolpath.program), ("model.identified_json", sc.model.identified_json),
                       ("model.payload_yaml", sc.model.payload_yaml)):
        if value:
            out[key] = resolve(sc, value)
    spec = robot_spec(sc)
    if spec is not None and spec == str(resolve(sc, sc.robot)):
        out["robot"] = Path(spec)
    return out


def _program(sc):
    """The scenario's G-code program (model/gcode.Program), read once."""
    p = resolve(sc, sc.toolpath.program)
    if not p.is_file():
        _fail(sc, "toolpath.program", f"no such G-code program {p}" if not p.exists() else f"{p} is not a file")
    return program_setup.read_program(sc, p)


def _dominant(values_by_length):
    """The value covering the most length: {value: length}."""
    return max(values_by_length.items(), key=lambda kv: kv[1])[0] if values_by_length else None


def apply_program(sc):
    """With a toolpath program: read it (InputError naming its line and
    word) and take the cutting feed (F, the one over most of the cutting
    length) and spindle speed (S) from it for the force model."""
    if not sc.toolpath.program:
        return
    if sc.path.waypoints_mm:
        _fail(sc, "toolpath.program", "give path.waypoints_mm or toolpath.program, not both")
    feeds, speeds = program_setup.feeds_and_speeds(_program(sc))
    if feeds:
        sc.path.feed_mm_per_s = _dominant(feeds) / 60.0
    if speeds:
        sc.cutter.spindle_rpm = float(_dominant(speeds))


def bounding_step_s(sc):
    """The plant step the checks of a scenario's size take before the arm
    is built: the step given, or when none is, the largest the station
    could take (diagrams/plant_step.DEFAULT_MAX_STEP_S, a tooth-resolved
    force's TOOTH_STEPS_PER_PASS bound; a gear's play may ask for less)."""
    from robstiff_drake.diagrams import plant_step

    h = float(sc.plant_config.time_step)
    if h > 0:
        return h
    if sc.cutting.mode == "tooth":
        tooth_hz = sc.cutter.spindle_rpm / 60.0 * sc.cutter.n_teeth
        return min(plant_step.DEFAULT_MAX_STEP_S,
                   plant_step.step_on_grid_s(1.0 / (plant_step.TOOTH_STEPS_PER_PASS * tooth_hz)))
    return plant_step.DEFAULT_MAX_STEP_S


def _fail(sc, key, what):
    lines = getattr(sc, "_key_lines", {})
    line = lines.get(tuple(key.split(".")))
    where = f"{sc.source or 'scenario'}:{line}" if line else (sc.source or "scenario")
    raise InputError(f"{where}: {key}: {what}")


def check_scenario(sc):
    """Every key against its range (the schema), then what depends on
    several keys; refused before any simulation starts."""
    check_object(Scenario, sc, sc.source or "scenario", getattr(sc, "_key_lines", {}))
    c, ctl, sen = sc.cutter, sc.controller, sc.sensor
    pitch = np.pi * c.diameter_mm / c.n_teeth
    if pitch < MIN_TOOTH_PITCH_MM:
        _fail(sc, "cutter.n_teeth", f"{c.n_teeth} teeth on a {c.diameter_mm:g} mm cutter is a tooth pitch of "
                                    f"{pitch:.1f} mm; at most {int(np.pi * c.diameter_mm / MIN_TOOTH_PITCH_MM)} "
                                    f"(pitch >= {MIN_TOOTH_PITCH_MM:g} mm)")
    if ctl.filter.kind == "lowpass" and not ctl.filter.cutoff_hz < 0.5 * sen.rate_hz:
        _fail(sc, "controller.filter.cutoff_hz",
              f"{ctl.filter.cutoff_hz:g} Hz must be between 0 and half the sensor rate ({0.5 * sen.rate_hz:g} Hz)")
    if ctl.filter.kind == "revolution_average":
        taps = sen.rate_hz * 60.0 / c.spindle_rpm
        if taps > MAX_FILTER_TAPS:
            _fail(sc, "controller.filter.kind", f"a revolution average at {c.spindle_rpm:g} rpm and "
                                                f"{sen.rate_hz:g} Hz needs {taps:.0f} taps (at most {MAX_FILTER_TAPS})")
    if sc.cutting.chip == "regenerative" and sc.cutting.mode != "tooth":
        _fail(sc, "cutting.chip", "regenerative needs cutting.mode: tooth (each tooth's chip from the tool's own "
                                  "motion over a tooth period), got cutting.mode: " + sc.cutting.mode)
    step_ms = bounding_step_s(sc) * 1e3
    if ctl.period_ms < step_ms - 1e-9:
        _fail(sc, "controller.period_ms", f"{ctl.period_ms:g} ms is below the plant step ({step_ms:g} ms)")
    for i, b in enumerate(sc.workpiece.boxes_mm):
        if not (b[0] < b[1] and b[2] < b[3]):
            _fail(sc, "workpiece.boxes_mm", f"box {i + 1}: expected [x0, x1, y0, y1, top] with x0 < x1 and "
                                            f"y0 < y1, got {b}")
    if not sc.toolpath.program and len(sc.path.waypoints_mm) < 2:
        _fail(sc, "path.waypoints_mm", f"expected at least 2 waypoints (or a toolpath.program), got "
                                       f"{len(sc.path.waypoints_mm)}")
    tol, floor = sc.path.tolerance_mm, 2.0 * sc.scan.noise_mm
    if 0 < tol < floor:
        _fail(sc, "path.tolerance_mm", f"{tol:g} mm is below what the scan can verify: twice its noise, 2 x "
                                       f"scan.noise_mm = {floor:g} mm (a surface within it could not be told from "
                                       "one outside it)")
    if sc.model.joint_stiffness_Nm_per_rad and sc.model.identified_json:
        _fail(sc, "model.identified_json", "give model.joint_stiffness_Nm_per_rad or model.identified_json, not both")
    if sc.toolpath.program:
        program_setup.check_tool(sc, _program(sc), lambda key, what: _fail(sc, key, what))
    path = _check_sizes(sc)
    _check_engagement(sc, path)
    if sc.toolpath.program:
        program_setup.check_stock(sc, _program(sc))


def _path_key(sc):
    return "toolpath.program" if sc.toolpath.program else "path.waypoints_mm"


def _check_engagement(sc, path):
    """Refuse an air cut: the commanded cutter (a disc of the cutter's
    radius at the tool point) must come below the top of some box while
    over it, or there is no machined surface to measure."""
    R = sc.cutter.diameter_mm / 2.0
    step = max(R / 10.0, 1e-3) / 1e3
    n = int(min(np.ceil(path.total_length / step), 1_000_000)) + 1
    pts = np.array([path.point_at(x) for x in np.linspace(0.0, path.total_length, n)]) * 1e3
    for x0, x1, y0, y1, top in sc.workpiece.boxes_mm:
        dx = np.maximum(np.maximum(x0 - pts[:, 0], pts[:, 0] - x1), 0.0)
        dy = np.maximum(np.maximum(y0 - pts[:, 1], pts[:, 1] - y1), 0.0)
        if np.any((dx * dx + dy * dy < R * R) & (pts[:, 2] < top)):
            return
    if sc.toolpath.program:
        raise InputError(program_setup.placement_message(sc, _program(sc)))
    _fail(sc, _path_key(sc), f"the cutter ({sc.cutter.diameter_mm:g} mm) never comes below the top of a "
                             "workpiece box while over it: an air cut leaves no surface to measure")


def _check_sizes(sc):
    """Time and memory a run would take, before anything is allocated; the
    path itself (built here: cheap) checked too.  Returns the path."""
    p = sc.path
    if not sc.toolpath.program:
        wp = np.asarray(p.waypoints_mm, dtype=float)
        seg = np.linalg.norm(np.diff(wp, axis=0), axis=1)
        if np.any(seg <= 0):
            i = int(np.argmax(seg <= 0))
            _fail(sc, "path.waypoints_mm", f"waypoints {i + 1} and {i + 2} are the same point")
    try:
        path = planned_path(sc)
    except PathError as e:
        _fail(sc, _path_key(sc), str(e))
    duration_s = path.duration_s
    length_mm = path.total_length * 1e3
    checks = (
        ("plant_config.time_step", duration_s / bounding_step_s(sc), MAX_PLANT_STEPS, "plant steps"),
        ("sensor.rate_hz", duration_s * sc.sensor.rate_hz, MAX_SENSOR_SAMPLES, "sensor samples"),
        ("path.reference_period_ms", duration_s / (p.reference_period_ms / 1e3), MAX_REFERENCE_SAMPLES,
         "joint-reference (IK) samples"),
    )
    for key, n, limit, what in checks:
        if n > limit:
            _fail(sc, key, f"the pass takes {duration_s:.4g} s ({length_mm:.4g} mm, dwell {p.dwell_s:g} s): "
                           f"{n:.3g} {what}, more than the {limit:.0e} a run may take; shorten the path or raise "
                           "the feed")
    if sc.cutting.mode == "tooth":
        per_step = bounding_step_s(sc) * sc.cutter.spindle_rpm / 60.0 * sc.cutter.n_teeth * sc.cutting.samples_per_tooth
        if per_step > MAX_TOOTH_SAMPLES_PER_STEP:
            _fail(sc, "cutting.samples_per_tooth", f"{per_step:.3g} force samples per plant step (at most "
                                                   f"{MAX_TOOTH_SAMPLES_PER_STEP}); lower the spindle speed, the "
                                                   "samples per tooth or the plant step")
    boxes = np.asarray(sc.workpiece.boxes_mm, dtype=float)
    n_lines = max(len(sc.scan.lines_y_mm), len(boxes))
    n_scan = (boxes[:, 1].max() - boxes[:, 0].min()) / sc.scan.resolution_mm * n_lines
    if n_scan > MAX_SCAN_POINTS:
        _fail(sc, "scan.resolution_mm", f"{n_scan:.3g} scan points (at most {MAX_SCAN_POINTS:.0e}); "
                                        "use a coarser resolution")
    n_path_scan = path.total_length * 1e3 / sc.scan.resolution_mm * max(1, len(sc.scan.offsets_mm))
    if n_path_scan > MAX_SCAN_POINTS:
        _fail(sc, "scan.resolution_mm", f"{n_path_scan:.3g} scan points along the path (at most "
                                        f"{MAX_SCAN_POINTS:.0e}); use a coarser resolution")
    return path


def resolve(sc, relative):
    return (Path(sc.source).parent / relative) if sc.source else Path(relative)


def planned_path(sc):
    """The scenario's tool path (PlannedPath, SI units): through its
    waypoints, or along its G-code program; PathError if it is malformed."""
    p = sc.path
    overrides = getattr(sc, "_feed_overrides", None)  # the feed planner's (diagrams/feed_plan.py)
    if sc.toolpath.program:
        tp = sc.toolpath
        prog = _program(sc)
        elements, speeds, stops, dwells, moves = program_pieces(prog.moves, tp.rapid_mm_per_s / 1e3,
                                                                program_setup.work_transform(tp))
        return PlannedPath.from_elements(elements, speeds, np.deg2rad(p.yaw_deg), p.dwell_s + prog.dwell_before_s,
                                         p.ramp_s, p.zone_mm / 1e3, stops=stops, dwells_s=dwells,
                                         tags=[f"{prog.path}:{m.line}" for m in moves],
                                         speed_overrides=overrides, lines=[m.line for m in moves])
    return PlannedPath(np.asarray(p.waypoints_mm, dtype=float) / 1e3, p.feed_mm_per_s / 1e3, np.deg2rad(p.yaw_deg),
                       p.dwell_s, p.ramp_s, p.zone_mm / 1e3, speed_overrides=overrides)


def robot_spec(sc):
    """The scenario's ``robot:`` as load_robot takes it (a library name, or
    its file resolved against the scenario's folder); None when empty."""
    if not sc.robot:
        return None
    from robstiff_drake.paths import library_robots

    if sc.robot in library_robots():
        return sc.robot
    return str(resolve(sc, sc.robot))


def scenario_robot(sc, override=None):
    """The RobotModel that runs scenario ``sc``: ``override`` (--robot) or
    the scenario's ``robot:`` (default: the IRB6400).  InputError, naming
    both, when the two are given and name different robots."""
    from robstiff_drake.model.robot import load_robot, same_robot_file

    spec = robot_spec(sc)
    if override is not None and spec is not None and not same_robot_file(spec, override):
        raise InputError(f"--robot {override} disagrees with the robot of {sc.source or 'the scenario'} "
                         f"(robot: {sc.robot}); drop --robot or edit the scenario")
    return load_robot(override if override is not None else spec)
