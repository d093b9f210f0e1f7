"""Scenario files (diagrams/*.yaml): dataclasses read with Drake's
``yaml_load_typed``, so an unknown key is an error that names it, then
checked for values that make no physical sense before anything is built.

Units are in the key names.  Paths to other files (an identification JSON,
a payload-calibration YAML) are relative to the scenario file.
"""

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml

from robstiff_drake.errors import InputError
from robstiff_drake.model.path import PlannedPath
from robstiff_drake.systems.gravity_removal import PayloadCalibration


@dataclass
class PlantConfig:
    """The 'true' robot: a discrete MultibodyPlant whose joints are servo
    springs and dampers between the commanded and the link angle
    (diagrams/milling_cell.py: add_compliant_irb6400)."""

    time_step_ms: float = 2.0
    # Joint stiffness of the plant (N*m/rad); empty: the robot file's nominal.
    joint_stiffness_Nm_per_rad: list[float] = field(default_factory=list)
    # Stiffness-proportional damping D = beta * K, beta = 2 zeta / omega_1:
    # the first mode gets damping ratio zeta, higher modes more.  The step
    # must keep every mode stable: beta >= step / 2 does for any stiffness.
    damping_ratio: float = 0.05
    # Joint effects beyond the springs (systems/joint_effects.py): lost motion
    # per joint (rad, the link lags by b in the load's direction) and the
    # coupling compliance between joints 2 and 3 (rad/(N*m)).  Empty / 0: none.
    lost_motion_rad: list[float] = field(default_factory=list)
    coupling_c23_rad_per_Nm: float = 0.0


@dataclass
class CutterConfig:
    diameter_mm: float = 75.0
    n_teeth: int = 6
    spindle_rpm: float = 3600.0


@dataclass
class CuttingConfig:
    """Mechanistic force model.  Coefficients: 6082-T6 (Duan et al., Chin. J.
    Mech. Eng. 2021, Table 5), scaled as the scenario documents."""

    mode: str = "averaged"  # "averaged" (over a revolution) or "tooth" (tooth-resolved)
    samples_per_tooth: int = 20  # tooth mode: force samples per tooth pass
    Ktc_N_per_mm2: float = 631.0
    Krc_N_per_mm2: float = 99.0
    Kac_N_per_mm2: float = 273.0
    Kte_N_per_mm: float = 13.0
    Kre_N_per_mm: float = 10.0
    Kae_N_per_mm: float = 2.8
    tangential_radial_scale: float = 1.0
    axial_scale: float = 1.0
    phase_deg: float = 0.0


@dataclass
class WorkpieceConfig:
    """Uncut material: boxes [x0, x1, y0, y1, top] in mm, base frame."""

    boxes_mm: list[list[float]] = field(default_factory=list)


@dataclass
class PathConfig:
    """Tool point (centre of the cutter's bottom face) through waypoints, mm."""

    waypoints_mm: list[list[float]] = field(default_factory=list)
    feed_mm_per_s: float = 20.0
    yaw_deg: float = 0.0
    dwell_s: float = 0.2  # at the first waypoint before the feed starts
    ramp_s: float = 0.5  # cosine speed-up from rest to the feed (and slow-down at the end)
    reference_period_ms: float = 4.0  # IK samples of the joint references


@dataclass
class SensorConfig:
    rate_hz: float = 1000.0
    noise_N: float = 0.5
    noise_Nm: float = 0.05
    force_bias_N: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])
    torque_bias_Nm: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])
    dropout_probability: float = 0.0
    spike_probability: float = 0.0
    spike_N: float = 0.0
    max_jump_N: float = 1000.0  # the guard rejects a sample that jumps more than this
    seed: int = 0


@dataclass
class FilterConfig:
    kind: str = "lowpass"  # "lowpass", "revolution_average" or "none"
    cutoff_hz: float = 10.0
    order: int = 2


@dataclass
class ControllerConfig:
    # "plain": the seed's compensator (the measured force, filtered and
    # delayed); "predictive": the model's force where the correction will act,
    # plus the filtered measured residual (see systems/predictive_wrench.py)
    mode: str = "plain"
    period_ms: float = 4.0
    delay_steps: int = 1
    filter: FilterConfig = field(default_factory=FilterConfig)
    saturation_deg: float = 0.5  # largest correction per joint
    rate_limit_deg_per_s: float = 5.0


@dataclass
class ModelConfig:
    """What the compensator believes (the plant is the truth)."""

    # Joint stiffness (N*m/rad); empty: the robot file's nominal.
    joint_stiffness_Nm_per_rad: list[float] = field(default_factory=list)
    # Or the JSON that `robstiff identify --json` wrote (relative to this file).
    identified_json: str = ""
    # The YAML that `robstiff calibrate-payload --yaml` wrote; empty: the
    # exact payload and sensor bias (a perfect calibration).
    payload_yaml: str = ""
    # Predictive mode's cutting-force model: the scenario's coefficients
    # times this factor (1: exact; 1.2: the model over-predicts by 20 %).
    force_model_scale: float = 1.0
    # The compensator's own model of the joint effects (see PlantConfig):
    # what `robstiff diagnose-run` adds when it finds them.
    lost_motion_rad: list[float] = field(default_factory=list)
    coupling_c23_rad_per_Nm: float = 0.0


@dataclass
class ScanConfig:
    """Laser line scans of the machined surface along x."""

    lines_y_mm: list[float] = field(default_factory=list)  # empty: the centre line of each box
    resolution_mm: float = 0.5
    edge_margin_mm: float = 2.0  # left out at each box edge (burrs, scan edge)
    # entry / exit zones of the statistics: this far from each box's leading /
    # trailing edge (0: the cutter radius, where the engagement changes)
    zone_mm: float = 0.0
    # The scanner's height noise, 1 sigma per point (mm, >= 0), added to the
    # measured scan (scan.csv; the statistics of the simulation's own summary
    # stay those of the true surface).  ASSUMPTION, 3 um: a laser line
    # scanner's own repeatability is about 0.5-2 um (Keyence LJ-X8000,
    # Micro-Epsilon scanCONTROL 30xx data sheets), a face-milled aluminium
    # surface adds its roughness (Ra 0.8-1.6 um, sigma about 1.25 Ra) and a
    # scanner carried over the part adds its vibration: together a few um.
    noise_mm: float = 0.003
    seed: int = 0  # of the scan noise (each cut and scan line draws its own stream)


@dataclass
class Scenario:
    name: str = ""
    description: str = ""
    plant: PlantConfig = field(default_factory=PlantConfig)
    cutter: CutterConfig = field(default_factory=CutterConfig)
    cutting: CuttingConfig = field(default_factory=CuttingConfig)
    workpiece: WorkpieceConfig = field(default_factory=WorkpieceConfig)
    path: PathConfig = field(default_factory=PathConfig)
    sensor: SensorConfig = field(default_factory=SensorConfig)
    controller: ControllerConfig = field(default_factory=ControllerConfig)
    model: ModelConfig = field(default_factory=ModelConfig)
    scan: ScanConfig = field(default_factory=ScanConfig)
    source: str = ""  # set by the loader


def load_scenario(path):
    """Read and check a scenario file; InputError on anything wrong."""
    from pydrake.common.yaml import yaml_load_typed

    path = Path(path)
    if not path.exists():
        raise InputError(f"{path}: no such scenario file")
    try:
        yaml.safe_load(path.read_text())
    except yaml.YAMLError as e:
        mark = getattr(e, "problem_mark", None)
        where = f"line {mark.line + 1}, column {mark.column + 1}: " if mark else ""
        raise InputError(f"{path}: {where}invalid YAML ({getattr(e, 'problem', e)})") from None
    try:
        sc = yaml_load_typed(schema=Scenario, filename=str(path))
    except (RuntimeError, ValueError, TypeError) as e:
        msg = " ".join(str(e).split())
        raise InputError(f"{path}: {msg}") from None
    sc.source = str(path)
    check_scenario(sc)
    return sc


def _fail(sc, key, what):
    raise InputError(f"{sc.source or 'scenario'}: {key}: {what}")


def check_scenario(sc):
    """Values that make no sense, refused before any simulation starts."""
    positive = {
        "plant.time_step_ms": sc.plant.time_step_ms,
        "cutter.diameter_mm": sc.cutter.diameter_mm,
        "cutter.spindle_rpm": sc.cutter.spindle_rpm,
        "path.feed_mm_per_s": sc.path.feed_mm_per_s,
        "path.reference_period_ms": sc.path.reference_period_ms,
        "sensor.rate_hz": sc.sensor.rate_hz,
        "controller.period_ms": sc.controller.period_ms,
        "controller.saturation_deg": sc.controller.saturation_deg,
        "controller.rate_limit_deg_per_s": sc.controller.rate_limit_deg_per_s,
        "scan.resolution_mm": sc.scan.resolution_mm,
        "sensor.max_jump_N": sc.sensor.max_jump_N,
    }
    for key, v in positive.items():
        if not (isinstance(v, (int, float)) and np.isfinite(v) and v > 0):
            _fail(sc, key, f"must be a positive number, got {v}")
    if not sc.path.ramp_s >= 0 or not sc.path.dwell_s >= 0:
        _fail(sc, "path.ramp_s", "ramp_s and dwell_s must be >= 0")
    if sc.cutter.n_teeth < 1:
        _fail(sc, "cutter.n_teeth", f"must be >= 1, got {sc.cutter.n_teeth}")
    if not 10 <= sc.cutter.diameter_mm <= 250:
        _fail(sc, "cutter.diameter_mm", f"{sc.cutter.diameter_mm} mm is not a sensible face-mill diameter "
                                        "for a robot (10-250 mm)")
    if sc.cutting.mode not in ("averaged", "tooth"):
        _fail(sc, "cutting.mode", f"expected 'averaged' or 'tooth', got {sc.cutting.mode!r}")
    if sc.cutting.samples_per_tooth < 1:
        _fail(sc, "cutting.samples_per_tooth", "must be >= 1")
    if sc.controller.mode not in ("plain", "predictive"):
        _fail(sc, "controller.mode", f"expected 'plain' or 'predictive', got {sc.controller.mode!r}")
    if not sc.model.force_model_scale > 0:
        _fail(sc, "model.force_model_scale", f"must be > 0, got {sc.model.force_model_scale}")
    if sc.controller.filter.kind not in ("lowpass", "revolution_average", "none"):
        _fail(sc, "controller.filter.kind",
              f"expected 'lowpass', 'revolution_average' or 'none', got {sc.controller.filter.kind!r}")
    if sc.controller.filter.kind == "lowpass" and not 0 < sc.controller.filter.cutoff_hz < 0.5 * sc.sensor.rate_hz:
        _fail(sc, "controller.filter.cutoff_hz",
              f"{sc.controller.filter.cutoff_hz} Hz must be between 0 and half the sensor rate "
              f"({0.5 * sc.sensor.rate_hz:g} Hz)")
    if sc.controller.delay_steps < 0:
        _fail(sc, "controller.delay_steps", f"must be >= 0, got {sc.controller.delay_steps}")
    if sc.controller.period_ms < sc.plant.time_step_ms - 1e-12:
        _fail(sc, "controller.period_ms", f"{sc.controller.period_ms} ms is below the plant step "
                                          f"({sc.plant.time_step_ms} ms)")
    if not 0 <= sc.plant.damping_ratio < 1:
        _fail(sc, "plant.damping_ratio", f"must be in [0, 1), got {sc.plant.damping_ratio}")
    for key, p in (("sensor.dropout_probability", sc.sensor.dropout_probability),
                   ("sensor.spike_probability", sc.sensor.spike_probability)):
        if not 0 <= p <= 1:
            _fail(sc, key, f"must be a probability in [0, 1], got {p}")
    if not sc.workpiece.boxes_mm:
        _fail(sc, "workpiece.boxes_mm", "at least one box [x0, x1, y0, y1, top] is needed")
    for i, b in enumerate(sc.workpiece.boxes_mm):
        if len(b) != 5 or not (b[0] < b[1] and b[2] < b[3]):
            _fail(sc, f"workpiece.boxes_mm[{i}]", f"expected [x0, x1, y0, y1, top] with x0 < x1, y0 < y1, got {b}")
    if len(sc.path.waypoints_mm) < 2:
        _fail(sc, "path.waypoints_mm", "at least two waypoints [x, y, z] are needed")
    for i, w in enumerate(sc.path.waypoints_mm):
        if len(w) != 3:
            _fail(sc, f"path.waypoints_mm[{i}]", f"expected [x, y, z], got {w}")
    for key, v in (("plant.joint_stiffness_Nm_per_rad", sc.plant.joint_stiffness_Nm_per_rad),
                   ("model.joint_stiffness_Nm_per_rad", sc.model.joint_stiffness_Nm_per_rad)):
        if v and (len(v) != 6 or min(v) <= 0):
            _fail(sc, key, "expected six positive stiffnesses (N*m/rad)")
    for key, v in (("plant.lost_motion_rad", sc.plant.lost_motion_rad), ("model.lost_motion_rad", sc.model.lost_motion_rad)):
        if v and (len(v) != 6 or min(v) < 0):
            _fail(sc, key, "expected six lost-motion amplitudes >= 0 (rad)")
    if sc.model.joint_stiffness_Nm_per_rad and sc.model.identified_json:
        _fail(sc, "model", "give joint_stiffness_Nm_per_rad or identified_json, not both")


def resolve(sc, relative):
    return (Path(sc.source).parent / relative) if sc.source else Path(relative)


def model_stiffness(sc, robot):
    """The compensator's joint stiffness (N*m/rad)."""
    if sc.model.joint_stiffness_Nm_per_rad:
        return np.asarray(sc.model.joint_stiffness_Nm_per_rad, dtype=float)
    if sc.model.identified_json:
        p = resolve(sc, sc.model.identified_json)
        try:
            k = json.loads(p.read_text())["joint_stiffness_Nm_per_rad"]
        except (OSError, ValueError, KeyError) as e:
            raise InputError(f"{sc.source}: model.identified_json: cannot read stiffness from {p} ({e})") from None
        k = np.asarray(k, dtype=float)
        if k.shape != (6,) or np.any(k <= 0):
            raise InputError(f"{p}: joint_stiffness_Nm_per_rad must be six positive numbers")
        return k
    return robot.joint_stiffness_Nm_per_rad


def plant_stiffness(sc, robot):
    if sc.plant.joint_stiffness_Nm_per_rad:
        return np.asarray(sc.plant.joint_stiffness_Nm_per_rad, dtype=float)
    return robot.joint_stiffness_Nm_per_rad


def planned_path(sc):
    """The scenario's tool path (PlannedPath, SI units); PathError if it is malformed."""
    p = sc.path
    return PlannedPath(np.asarray(p.waypoints_mm, dtype=float) / 1e3, p.feed_mm_per_s / 1e3, np.deg2rad(p.yaw_deg),
                       p.dwell_s, p.ramp_s)


def exact_payload_calibration(sc, robot):
    """The true payload (robot file) and the scenario's sensor bias: a perfect calibration."""
    return PayloadCalibration(mass_kg=robot.payload.mass_kg, com_mm=list(robot.payload.com_m * 1e3),
                              force_bias_N=list(sc.sensor.force_bias_N), torque_bias_Nm=list(sc.sensor.torque_bias_Nm),
                              sensor_mount_rpy_deg=[0.0, 0.0, 0.0])


def payload_calibration(sc, robot):
    """The gravity-removal parameters: from the scenario's payload_yaml, or
    the exact payload and sensor bias."""
    if sc.model.payload_yaml:
        p = resolve(sc, sc.model.payload_yaml)
        try:
            doc = yaml.safe_load(p.read_text())["payload_calibration"]
            return PayloadCalibration(**doc)
        except (OSError, yaml.YAMLError, KeyError, TypeError) as e:
            raise InputError(f"{sc.source}: model.payload_yaml: cannot read payload_calibration from {p} ({e})") \
                from None
    return exact_payload_calibration(sc, robot)
