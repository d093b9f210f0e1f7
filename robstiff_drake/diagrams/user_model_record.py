"""The compensator's model as a user would have it (diagrams/user_model.py
makes it): the record, its JSON form, and where a computed one is kept on
disk (keyed by the inputs it depends on and the code that made it)."""

import hashlib
import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from robstiff_drake.diagrams.scenario_step import plant_step_s
from robstiff_drake.diagrams.scenario_models import plant_stiffness
from robstiff_drake.model.payload import PayloadCalibration
from robstiff_drake.model.preview import ServoModel


@dataclass
class UserModel:
    """The compensator's model as a user would have it (see module docstring)."""

    joint_stiffness_Nm_per_rad: np.ndarray
    stiffness_identifiable: np.ndarray
    calibration: PayloadCalibration
    coefficient_factors: dict  # {coefficient name: factor on the scenario's value}
    servo: ServoModel
    servo_fit_rms: float
    notes: dict = field(default_factory=dict)

    def describe(self, plant_k=None):
        """The model as JSON-ready numbers (with its ratio to the plant's stiffness)."""
        out = {"joint_stiffness_Nm_per_rad": self.joint_stiffness_Nm_per_rad.tolist(),
               "stiffness_identifiable": self.stiffness_identifiable.tolist(),
               "payload": {"mass_kg": self.calibration.mass_kg, "com_mm": list(self.calibration.com_mm),
                           "force_bias_N": list(self.calibration.force_bias_N),
                           "torque_bias_Nm": list(self.calibration.torque_bias_Nm)},
               "cutting_coefficient_factors": dict(self.coefficient_factors),
               "servo": {"dead_time_s": self.servo.dead_time_s,
                         "position_gain_per_s": self.servo.position_gain_per_s,
                         "velocity_bandwidth_hz": self.servo.velocity_bandwidth_hz,
                         "velocity_integral_hz": self.servo.velocity_integral_hz,
                         "fit_rms": self.servo_fit_rms}}
        if plant_k is not None:
            out["stiffness_over_plant"] = (self.joint_stiffness_Nm_per_rad / np.asarray(plant_k)).tolist()
        out.update(self.notes)
        return out


def _robot_file_digest(robot):
    """The robot file's content (a digest): an edited file (masses, limits,
    payload) is another arm, though its path is the same."""
    try:
        return hashlib.sha256(Path(robot.source).read_bytes()).hexdigest()[:16]
    except (OSError, ValueError):
        return None  # (a robot made in memory: its path names it)


def signature(sc, robot, q0):
    """What the user model depends on (a cache key): the scenario's plant,
    sensor, servo and identification settings, the robot file (path and
    content) and the start pose ``q0`` (rad) the bench rests and steps at."""
    ident = sc.model.identification
    motors = robot.motor_inertia_kgm2
    keys = [robot.source, _robot_file_digest(robot), tuple(np.round(np.asarray(q0, dtype=float), 12)),
            tuple(np.round(plant_stiffness(sc, robot), 6)), sc.plant.modal_damping_ratio,
            tuple(sc.plant.damping_ratios), None if motors is None else tuple(np.asarray(motors, dtype=float)),
            tuple(sc.plant.lost_motion_rad), tuple(sc.plant.gap_friction_Nm), sc.plant.coupling_c23_rad_per_Nm,
            plant_step_s(sc, robot),
            tuple(sc.sensor.force_bias_N), tuple(sc.sensor.torque_bias_Nm), sc.sensor.noise_N, sc.sensor.noise_Nm,
            sc.sensor.rate_hz, sc.servo.interpolator_delay_ms, sc.servo.interpolator_period_ms,
            sc.servo.position_gain_per_s, sc.servo.velocity_bandwidth_hz, sc.servo.velocity_feedforward,
            sc.servo.velocity_integral_hz]
    keys += [(f.name, getattr(ident, f.name)) for f in ident.__dataclass_fields__.values()]
    return tuple(keys)


# The modules whose code the model depends on (the plant it is measured on,
# the identification): a change in any makes the files cached on disk stale.
CODE = ("robstiff_drake.diagrams.station", "robstiff_drake.diagrams.compliant_arm",
        "robstiff_drake.model.joint_dynamics", "robstiff_drake.systems.gear_transmission",
        "robstiff_drake.model.transmission", "robstiff_drake.model.servo", "robstiff_drake.systems.milling_force",
        "robstiff_drake.systems.wrist_sensor", "robstiff_drake.plant", "robstiff_drake.model.description",
        "robstiff_drake.identification.stiffness.joint_stiffness", "robstiff_drake.identification.stiffness.payload",
        "robstiff_drake.identification.stiffness.pose_planning", "robstiff_drake.model.preview",
        "robstiff_drake.diagrams.user_model", __name__)


def code_hash():
    """A digest of the source of the modules in CODE."""
    from robstiff_drake.plant import code_digest

    return code_digest(CODE)[:16]


def disk_path(key):
    """Where the user model of inputs ``key`` (``signature``) made by this code is kept."""
    from robstiff_drake.plant import cache_dir

    digest = hashlib.sha256(repr((key, code_hash())).encode()).hexdigest()[:24]
    return cache_dir() / f"user-model-{digest}.json"


def to_json(m):
    """A UserModel as JSON text (``from_json`` reads it back)."""
    return json.dumps({"k": m.joint_stiffness_Nm_per_rad.tolist(), "ok": m.stiffness_identifiable.tolist(),
                       "cal": [m.calibration.mass_kg, list(m.calibration.com_mm), list(m.calibration.force_bias_N),
                               list(m.calibration.torque_bias_Nm)],
                       "factors": m.coefficient_factors,
                       "servo": [m.servo.dead_time_s, m.servo.position_gain_per_s, m.servo.velocity_bandwidth_hz,
                                 m.servo.velocity_integral_hz],
                       "rms": m.servo_fit_rms, "notes": m.notes})


def from_json(text):
    """The UserModel of ``to_json``'s text."""
    d = json.loads(text)
    m, com, bf, bt = d["cal"]
    cal = PayloadCalibration(mass_kg=m, com_mm=com, force_bias_N=bf, torque_bias_Nm=bt,
                             sensor_mount_rpy_deg=[0.0, 0.0, 0.0])
    return UserModel(np.array(d["k"], dtype=float), np.array(d["ok"], dtype=bool), cal, dict(d["factors"]),
                     ServoModel(*d["servo"]), float(d["rms"]), dict(d["notes"]))
