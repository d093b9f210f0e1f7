"""What a scenario says the machine and its compensator are: the plant's
and the compensator's stiffness and damping, the cutting-force models, the
payload calibration (its file, the identified model's, or the exact one)
and the warnings for legal settings likely not meant (diagrams/scenario.py
reads and checks the file)."""

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from robstiff_drake.diagrams import toolpath as program_setup
from robstiff_drake.diagrams.scenario import _fail, resolve
from robstiff_drake.diagrams.schema import num, text, validate, vec
from robstiff_drake.errors import InputError, excerpt
from robstiff_drake.model.milling import Cutter, CuttingCoefficients, MillingForceModel, Workpiece
from robstiff_drake.model.payload import PayloadCalibration
from robstiff_drake.model.plant_cutting import PlantCuttingLaw, PlantCuttingPhysics
from robstiff_drake.model.robot_file import STIFFNESS_RANGE_NM_PER_RAD
from robstiff_drake.model.servo import ServoParameters
from robstiff_drake.user_files import load_json, load_yaml, read_user_text

def user_model_of(sc):
    """The identified model a run resolved for ``sc`` (diagrams/user_model.py
    sets it before the compensator is built), or None (``model.source:
    nominal``, or not resolved: then the nominal parts stand in)."""
    return getattr(sc, "_user_model", None) if sc.model.source == "identified" else None


def model_stiffness(sc, robot):
    """The compensator's joint stiffness (N*m/rad): the scenario's explicit
    model keys, else the identified model's, else the robot file's nominal."""
    if sc.model.joint_stiffness_Nm_per_rad:
        return np.asarray(sc.model.joint_stiffness_Nm_per_rad, dtype=float)
    if sc.model.identified_json:
        p = resolve(sc, sc.model.identified_json)
        named_by = f"model.identified_json of {sc.source or 'the scenario'}"
        doc = load_json(read_user_text(p, "JSON file", named_by=named_by), p)
        if not isinstance(doc, dict) or "joint_stiffness_Nm_per_rad" not in doc:
            _fail(sc, "model.identified_json", f"{p} has no joint_stiffness_Nm_per_rad (write it with `robstiff "
                                               "identify DATA.csv --json OUT`)")
        return checked_joint_stiffness(doc["joint_stiffness_Nm_per_rad"], where=str(p))
    um = user_model_of(sc)
    if um is not None:
        return um.joint_stiffness_Nm_per_rad
    return robot.joint_stiffness_Nm_per_rad


def identified_parts(sc):
    """Where the compensator's identified model (``model.source:
    identified``) takes each part from, as a phrase: the stiffness from
    the scenario's model.joint_stiffness_Nm_per_rad or model.identified_json
    when it gives one (model_stiffness), else a simulated stiffness campaign;
    the payload from model.payload_yaml, else a simulated calibration; the
    servo from a simulated step test."""
    stiffness = ("the stiffness of model.joint_stiffness_Nm_per_rad" if sc.model.joint_stiffness_Nm_per_rad else
                 f"the stiffness of {sc.model.identified_json} (model.identified_json)" if sc.model.identified_json
                 else "a simulated stiffness campaign")
    payload = (f"the payload of {sc.model.payload_yaml} (model.payload_yaml)" if sc.model.payload_yaml
               else "a simulated payload calibration")
    return f"{stiffness}, {payload}, a simulated servo step test"


def checked_joint_stiffness(value, *, where):
    """``value`` as six finite joint stiffnesses (N*m/rad) within
    STIFFNESS_RANGE_NM_PER_RAD, or an InputError that names ``where``."""
    lo, hi = STIFFNESS_RANGE_NM_PER_RAD
    k = numbers(value)
    if k is None or k.shape != (6,) or not np.all(np.isfinite(k)) or np.any((k < lo) | (k > hi)):
        raise InputError(f"{where}: joint_stiffness_Nm_per_rad: expected six finite stiffnesses in "
                         f"[{lo:g}, {hi:g}] N*m/rad, got {excerpt(value)}")
    return k


def numbers(value):
    """``value`` as a flat float array when it is a list of plain numbers
    (no text, bool, list or dict in it), else None."""
    if not isinstance(value, (list, tuple)) or not all(isinstance(v, (int, float)) and not isinstance(v, bool)
                                                        for v in value):
        return None
    return np.asarray(value, dtype=float)


def plant_damping_ratios(sc):
    """The plant's damping ratio of each mode (6,), lowest frequency first."""
    if sc.plant.damping_ratios:
        return np.asarray(sc.plant.damping_ratios, dtype=float)
    return np.full(6, float(sc.plant.modal_damping_ratio))


def model_damping_ratios(sc):
    """(6,) the modal damping ratios the compensator's preview assumes
    (model.damping_ratios; empty: the scenario's stated plant ratios)."""
    r = sc.model.damping_ratios
    if r:
        return np.broadcast_to(np.asarray(r, dtype=float), (6,)).copy()
    return plant_damping_ratios(sc)


def plant_stiffness(sc, robot):
    if sc.plant.joint_stiffness_Nm_per_rad:
        return np.asarray(sc.plant.joint_stiffness_Nm_per_rad, dtype=float)
    return robot.joint_stiffness_Nm_per_rad


def cutting_setup(sc, scale=1.0, factors=None, groups=None):
    """(cutter, force model, workpiece) of the scenario; ``scale`` multiplies
    every coefficient (a compensator's model that is off by that factor),
    ``factors`` ({coefficient name: factor}) each one; ``groups``: keep
    only these coefficients (names), the others 0 (a group's share)."""
    cutter = Cutter(sc.cutter.diameter_mm / 1e3, int(sc.cutter.n_teeth), sc.cutter.spindle_rpm)
    c = sc.cutting
    s, sa = c.tangential_radial_scale * scale, c.axial_scale * scale
    f = dict(factors or {})
    values = {"Ktc_N_per_mm2": c.Ktc_N_per_mm2 * s, "Krc_N_per_mm2": c.Krc_N_per_mm2 * s,
              "Kac_N_per_mm2": c.Kac_N_per_mm2 * sa, "Kte_N_per_mm": c.Kte_N_per_mm * s,
              "Kre_N_per_mm": c.Kre_N_per_mm * s, "Kae_N_per_mm": c.Kae_N_per_mm * sa}
    values = {k: v * f.get(k, 1.0) * (1.0 if groups is None or k in groups else 0.0) for k, v in values.items()}
    coeffs = CuttingCoefficients(**values)
    model = MillingForceModel(cutter, coeffs, sc.path.feed_mm_per_s / 1e3)
    workpiece = Workpiece.from_boxes(np.asarray(sc.workpiece.boxes_mm, dtype=float) / 1e3)
    return cutter, model, workpiece


def plant_cutting_setup(sc):
    """(cutter, the plant's cutting law, workpiece): the scenario's linear
    coefficients as the anchor of the plant's richer law
    (model/plant_cutting.py; cutting.plant_law)."""
    cutter, linear, workpiece = cutting_setup(sc)
    c = sc.cutting
    if c.plant_law == "linear":
        physics = PlantCuttingPhysics.linear()
    else:
        physics = PlantCuttingPhysics(chip_exponent=c.chip_exponent, runout_m=c.runout_mm / 1e3,
                                      runout_angle_rad=float(np.deg2rad(c.runout_angle_deg)),
                                      flank_wear_m=c.flank_wear_mm / 1e3, flank_wear_per_m=c.flank_wear_mm_per_m / 1e3)
    return cutter, PlantCuttingLaw(linear, physics), workpiece


# The force model's coefficients by group (preview mode scales each group
# by what the cut shows): tangential, radial, axial.
COEFFICIENT_GROUPS = (("Ktc_N_per_mm2", "Kte_N_per_mm"), ("Krc_N_per_mm2", "Kre_N_per_mm"),
                      ("Kac_N_per_mm2", "Kae_N_per_mm"))


def model_cutting_setup(sc, groups=None):
    """(cutter, force model, workpiece) as the compensator models the cut:
    the scenario's coefficients times model.force_model_scale and, with an
    identified model, each coefficient's error factor."""
    um = user_model_of(sc)
    return cutting_setup(sc, scale=sc.model.force_model_scale,
                         factors=um.coefficient_factors if um is not None else None, groups=groups)


def exact_payload_calibration(sc, robot):
    """The true payload (robot file) and the scenario's sensor bias: a perfect calibration."""
    return PayloadCalibration(mass_kg=robot.payload.mass_kg, com_mm=list(robot.payload.com_m * 1e3),
                              force_bias_N=list(sc.sensor.force_bias_N), torque_bias_Nm=list(sc.sensor.torque_bias_Nm),
                              sensor_mount_rpy_deg=[0.0, 0.0, 0.0])


@dataclass
class PayloadCalibrationSchema:
    """The block `robstiff calibrate-payload --yaml` writes, with its ranges."""

    # the heaviest robot payloads are about 1.3 t; below 0.1 kg there is no spindle
    mass_kg: float = num(0.0, 0.1, 2000.0, "kg")
    com_mm: list[float] = vec([0.0, 0.0, 0.0], (3,), -2000.0, 2000.0, "mm")
    force_bias_N: list[float] = vec([0.0, 0.0, 0.0], (3,), -5000.0, 5000.0, "N")
    torque_bias_Nm: list[float] = vec([0.0, 0.0, 0.0], (3,), -500.0, 500.0, "N*m")
    sensor_mount_rpy_deg: list[float] = vec([0.0, 0.0, 0.0], (3,), -360.0, 360.0, "deg")
    # the robot file it was computed with (written since calibrate-payload named it; older files lack it)
    robot: str = text("", max_length=200, one_line=True)


@dataclass
class PayloadCalibrationFile:
    payload_calibration: PayloadCalibrationSchema = field(default_factory=PayloadCalibrationSchema)


def read_payload_calibration(path, named_by=None):
    """A payload-calibration YAML, checked against its ranges (InputError);
    ``named_by``: the file and key that name it (for the output check)."""
    path = Path(path)
    text_ = read_user_text(path, "payload calibration", named_by=named_by)
    validate(PayloadCalibrationFile, path, text_)
    doc = load_yaml(text_, path)[0] or {}
    if "payload_calibration" not in doc or "mass_kg" not in (doc["payload_calibration"] or {}):
        raise InputError(f"{path}: payload_calibration.mass_kg: missing (write the file with "
                         "`robstiff calibrate-payload DATA.csv --yaml OUT.yaml`)")
    block = doc["payload_calibration"]
    return PayloadCalibration(**{k: (float(v) if k == "mass_kg" else str(v) if k == "robot" else
                                     [float(x) for x in v]) for k, v in block.items()})


def payload_calibration(sc, robot):
    """The gravity-removal parameters: from the scenario's payload_yaml, or
    the identified model's, or the exact payload and sensor bias (an error
    budget's run with the arm's masses scaled keeps the real payload's:
    ``_payload_calibration_override``, diagrams/budget.py)."""
    override = getattr(sc, "_payload_calibration_override", None)
    if override is not None:
        return override
    if sc.model.payload_yaml:
        p = resolve(sc, sc.model.payload_yaml)
        if not p.is_file():
            _fail(sc, "model.payload_yaml", f"no such file {p}")
        return read_payload_calibration(p, f"model.payload_yaml of {sc.source or 'the scenario'}")
    um = user_model_of(sc)
    if um is not None:
        return um.calibration
    return exact_payload_calibration(sc, robot)


# How far the compensator's model may stray from the robot file before a
# run says so: a factor of 2 in a joint stiffness, 25 % in the payload's
# mass, 50 mm in its centre of mass (a calibration that far off is more
# likely of another tool or in other units than a real change).
MODEL_STIFFNESS_FACTOR = 2.0


PAYLOAD_MASS_REL = 0.25


PAYLOAD_COM_MM = 50.0


def scenario_warnings(sc, robot):
    """Legal settings whose results are likely implausible (one line each)."""
    out = []
    k_model, k_robot = model_stiffness(sc, robot), robot.joint_stiffness_Nm_per_rad
    ratio = k_model / k_robot
    for j in np.flatnonzero((ratio > MODEL_STIFFNESS_FACTOR) | (ratio < 1 / MODEL_STIFFNESS_FACTOR)):
        out.append(f"model: joint {j + 1}'s stiffness {k_model[j]:.3g} N*m/rad is {ratio[j]:.2g} times the robot "
                   f"file's nominal {k_robot[j]:.3g}")
    if sc.model.payload_yaml:
        cal = payload_calibration(sc, robot)
        if cal.robot and cal.robot != robot.name:
            out.append(f"model.payload_yaml: calibrated with the robot {str(cal.robot)[:80]!r}, not the scenario's "
                       f"{robot.name!r}: its gravity directions came from another arm's kinematics (calibrate-payload "
                       f"--robot)")
        m, m0 = cal.mass_kg, robot.payload.mass_kg
        if abs(m - m0) > PAYLOAD_MASS_REL * m0:
            out.append(f"model.payload_yaml: calibrated payload {m:.3g} kg is far from the robot file's {m0:.3g} kg "
                       "(another tool, or forces in other units?)")
        dc = np.linalg.norm(np.asarray(cal.com_mm or [0, 0, 0]) - robot.payload.com_m * 1e3)
        if dc > PAYLOAD_COM_MM:
            out.append(f"model.payload_yaml: calibrated centre of mass is {dc:.0f} mm from the robot file's")
    out += program_setup.program_warnings(sc)
    if sc.cutting.mode == "tooth":
        tooth_hz = sc.cutter.spindle_rpm / 60.0 * sc.cutter.n_teeth
        if sc.sensor.rate_hz < 2.0 * tooth_hz:
            out.append(f"sensor.rate_hz: {sc.sensor.rate_hz:g} Hz samples below twice the tooth-passing frequency "
                       f"({tooth_hz:g} Hz) in tooth-resolved mode: the tooth force aliases into the loop")
    return out


def servo_parameters(sc):
    """The scenario's controller servo (model/servo.ServoParameters)."""
    s = sc.servo
    return ServoParameters(position_gain_per_s=s.position_gain_per_s, velocity_bandwidth_hz=s.velocity_bandwidth_hz,
                           velocity_feedforward=s.velocity_feedforward,
                           interpolator_delay_s=s.interpolator_delay_ms / 1e3,
                           velocity_integral_hz=s.velocity_integral_hz, integral_rule=s.velocity_integral)
