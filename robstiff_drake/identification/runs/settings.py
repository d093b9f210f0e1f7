"""The compensator's settings of a run folder, compensator.yaml
(docs/run_files.md): what the compensator believes and how its loop
runs, nothing of the plant; its reader (an InputError of one line naming
the file, line and column) and its writer (text).  Plain numpy and
PyYAML; no Drake.
"""

import math
from dataclasses import dataclass, field, fields

import numpy as np
import yaml

from robstiff_drake.errors import InputError, excerpt
from robstiff_drake.identification.runs.tables import fail, header_meta, meta_lines, number_text, read_text
from robstiff_drake.user_files import UserYamlLoader


def _zeros6():
    return [0.0] * 6


@dataclass
class CompensatorSettings:
    """What the compensator is set to (compensator.yaml).  The plant is not
    here: a cell knows its compensator, not its robot's true joints."""

    joint_stiffness_Nm_per_rad: list  # the model's six joint stiffnesses
    payload: dict  # mass_kg, com_mm, force_bias_N, torque_bias_Nm, sensor_mount_rpy_deg
    tool_point_mm: list  # the tool point (centre of the cutter's face) in the flange frame
    cutter_diameter_mm: float
    mode: str = "plain"  # "plain", "predictive" or "preview"
    period_ms: float = 4.0
    delay_steps: int = 1
    filter_kind: str = "lowpass"  # "lowpass", "revolution_average" or "none"
    filter_cutoff_hz: float = 2.0  # as `compensate --cutoff-hz` (10 Hz is unstable at realistic damping: docs/cli.md)
    filter_order: int = 2
    sensor_rate_hz: float = 1000.0
    max_jump_N: float = 1000.0
    spindle_rpm: float = 3600.0
    saturation_deg: float = 0.5
    rate_limit_deg_per_s: float = 5.0
    lost_motion_rad: list = field(default_factory=_zeros6)
    # the compensator's law of that lost motion (model/compensator.PLAY_LAWS) and its identified take-up torques
    # (the smooth law's) and friction in the play (the hysteretic law's), N*m per joint; None: the fallbacks
    # (model/transmission.fallback_take_up_Nm, gap_friction_Nm of the model's stiffness).  ASSUMPTION: a file
    # without lost_motion_law (written before it was logged) ran the compensator's default, hysteretic
    # (diagrams/model_schema.ModelConfig)
    lost_motion_law: str = "hysteretic"
    lost_motion_take_up_Nm: list = None
    lost_motion_friction_Nm: list = None
    coupling_c23_rad_per_Nm: float = 0.0
    force_model_scale: float = 1.0
    # the robot the model belongs to: a library name (`robstiff robots`) or a
    # robot file (relative to this settings file); empty: the IRB6400
    robot: str = ""
    # the robot controller's servo (its `servo:` section, SERVO_KEYS): the
    # interpolator's dead time (ms), the position loop's gain (1/s), the
    # velocity loop's bandwidth (Hz) and the path's velocity feed-forward
    # (0-1).  None: not stated (a file written by an earlier version); what a
    # correction takes to reach the motor is then unknown.
    servo: dict = None
    path: str = ""

    def values(self):
        """The settings as a flat dict of numbers and strings (no path)."""
        return {f.name: getattr(self, f.name) for f in fields(self) if f.name != "path"}

    def same_as(self, other, rtol=1e-9):
        """Whether two settings are the same (numbers to ``rtol``)."""
        a, b = self.values(), other.values()
        for k, va in a.items():
            vb = b[k]
            if va is None or vb is None:
                if (va is None) != (vb is None):
                    return False
            elif isinstance(va, dict):
                if va.keys() != vb.keys() or not all(np.allclose(va[n], vb[n], rtol=rtol, atol=0) for n in va):
                    return False
            elif isinstance(va, str):
                if va != vb:
                    return False
            elif not np.allclose(va, vb, rtol=rtol, atol=0):
                return False
        return True


# ---------------------------------------------------------------- settings (YAML)

# key -> (attribute, kind); kind: "positive", "nonneg", "int>=0", "int>=1",
# ("choice", options), ("vector", n, "positive" | "nonneg" | "any"), "number"
_SETTINGS_LAYOUT = {
    "robot": ("robot", "text"),
    "mode": ("mode", ("choice", ("plain", "predictive", "preview"))),
    "period_ms": ("period_ms", "positive"),
    "delay_steps": ("delay_steps", "int>=0"),
    "saturation_deg": ("saturation_deg", "positive"),
    "rate_limit_deg_per_s": ("rate_limit_deg_per_s", "positive"),
    "sensor": {"rate_hz": ("sensor_rate_hz", "positive"), "max_jump_N": ("max_jump_N", "positive")},
    "filter": {"kind": ("filter_kind", ("choice", ("lowpass", "revolution_average", "none"))),
               "cutoff_hz": ("filter_cutoff_hz", "positive"), "order": ("filter_order", "int>=1")},
    "model": {"joint_stiffness_Nm_per_rad": ("joint_stiffness_Nm_per_rad", ("vector", 6, "positive")),
              "lost_motion_rad": ("lost_motion_rad", ("vector", 6, "nonneg")),
              "lost_motion_law": ("lost_motion_law", ("choice", ("hysteretic", "smooth"))),
              "lost_motion_take_up_Nm": ("lost_motion_take_up_Nm", ("vector", 6, "positive")),
              "lost_motion_friction_Nm": ("lost_motion_friction_Nm", ("vector", 6, "nonneg")),
              "coupling_c23_rad_per_Nm": ("coupling_c23_rad_per_Nm", "number"),
              "force_model_scale": ("force_model_scale", "positive")},
    "payload_calibration": {"mass_kg": ("payload.mass_kg", "nonneg"),
                            "com_mm": ("payload.com_mm", ("vector", 3, "any")),
                            "force_bias_N": ("payload.force_bias_N", ("vector", 3, "any")),
                            "torque_bias_Nm": ("payload.torque_bias_Nm", ("vector", 3, "any")),
                            "sensor_mount_rpy_deg": ("payload.sensor_mount_rpy_deg", ("vector", 3, "any"))},
    "tool": {"point_mm": ("tool_point_mm", ("vector", 3, "any")),
             "cutter_diameter_mm": ("cutter_diameter_mm", "positive"),
             "spindle_rpm": ("spindle_rpm", "positive")},
    "servo": {"interpolator_delay_ms": ("servo.interpolator_delay_ms", "nonneg"),
              "position_gain_per_s": ("servo.position_gain_per_s", "positive"),
              "velocity_bandwidth_hz": ("servo.velocity_bandwidth_hz", "positive"),
              "velocity_feedforward": ("servo.velocity_feedforward", ("range", 0.0, 1.0)),
              "velocity_integral_hz": ("servo.velocity_integral_hz", ("range", 0.0, 100.0))},
}
SERVO_KEYS = tuple(_SETTINGS_LAYOUT["servo"])
# servo.velocity_integral_hz: files written before it was logged lack it (run_diagnosis.servo_of
# then takes model/servo.ServoParameters' default, an ASSUMPTION written there)
_OPTIONAL = {"lost_motion_rad", "lost_motion_law", "lost_motion_take_up_Nm", "lost_motion_friction_Nm",
             "coupling_c23_rad_per_Nm", "force_model_scale", "robot", "servo.velocity_integral_hz"}
_OPTIONAL_SECTIONS = {"servo"}  # a file without it is read (servo None); diagnose-run refuses it
_KEY_NOTES = {
    "robot": "the robot the model belongs to: a library name or a robot file (relative to this file)",
    "mode": "plain: the measured force, filtered and delayed; predictive: the force model ahead plus the "
            "filtered measured residual; preview: the planned path through the arm's dynamics too",
    "period_ms": "the controller's cycle",
    "delay_steps": "controller periods between the wrench sample and the correction",
    "saturation_deg": "largest correction per joint",
    "rate_limit_deg_per_s": "largest rate of change of the correction",
    "sensor": "how the compensator reads the sensor: sample rate; a sample that jumps more than max_jump_N is "
              "rejected",
    "filter": "the force filter at the sensor rate",
    "model": "what the compensator believes: joint stiffness, lost motion (rad, joints 1-6), joint 2-3 "
             "coupling, and the predictive mode's cutting-force model scale (1: as set up)",
    "payload_calibration": "gravity removal (what `robstiff calibrate-payload` writes)",
    "tool": "the tool point in the flange frame, the cutter's diameter and the spindle speed",
    "servo": "the robot controller's joint servo (not the compensator's, and not changed by a fix): the "
             "interpolator's dead time, the position loop's gain, the velocity loop's bandwidth and the path's "
             "velocity feed-forward (1: full; a correction gets no feed-forward), and the velocity loop's "
             "integral corner (optional)",
}


def _settings_source(s):
    """{attribute path: value} of the settings."""
    out = {}
    for f in fields(s):
        if f.name in ("payload", "servo"):
            for k, v in (getattr(s, f.name) or {}).items():
                out[f"{f.name}.{k}"] = v
        elif f.name != "path":
            out[f.name] = getattr(s, f.name)
    return out


def _value_text(v):
    if isinstance(v, str):
        return v
    if isinstance(v, (bool, np.bool_)):
        return "true" if v else "false"
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    if np.ndim(v):
        return "[" + ", ".join(number_text(x) for x in np.ravel(v)) + "]"
    return number_text(v)


def settings_text(settings, run_id, notes=()):
    """compensator.yaml of ``settings``."""
    src = _settings_source(settings)
    ints = {"delay_steps", "filter_order"}

    def value(attr):
        return _value_text(int(src[attr]) if attr in ints else src[attr])

    lines = [meta_lines(run_id, ["The compensator's settings: what it believes and how its loop runs. Nothing "
                                 "of the plant (the robot's true joints) is here.", *notes]), "compensator:\n"]
    for key, spec in _SETTINGS_LAYOUT.items():
        if key in _OPTIONAL_SECTIONS and getattr(settings, key) is None:
            continue
        if key in _KEY_NOTES:
            lines.append(f"  # {_KEY_NOTES[key]}\n")
        if isinstance(spec, dict):
            lines.append(f"  {key}:\n")
            lines.extend(f"    {sub}: {value(attr)}\n" for sub, (attr, _) in spec.items()
                         if (attr in src and src[attr] is not None) or attr not in _OPTIONAL)
        else:
            lines.append(f"  {key}: {value(spec[0])}\n")
    return "".join(lines)


def _where(path, node):
    return f"{path}, line {node.start_mark.line + 1}, column {node.start_mark.column + 1}"


def _scalar(loader, node):
    return loader.construct_object(node, deep=True)


def _as_number(v):
    if isinstance(v, bool):
        return None
    if isinstance(v, (int, float)):
        return float(v)
    if isinstance(v, str):  # YAML 1.1 reads 1e-5 (no dot) as a string
        try:
            return float(v)
        except ValueError:
            return None
    return None


def _check_value(path, loader, node, key, kind):
    where = _where(path, node)
    if isinstance(kind, tuple) and kind[0] == "choice":
        v = _scalar(loader, node)
        if v not in kind[1]:
            raise InputError(f"{where}: {key}: expected one of {', '.join(kind[1])}, got {excerpt(v)}")
        return v
    if isinstance(kind, tuple) and kind[0] == "range":
        x = _as_number(_scalar(loader, node))
        if x is None or not kind[1] <= x <= kind[2]:
            raise InputError(f"{where}: {key}: expected a number from {kind[1]:g} to {kind[2]:g}, "
                             f"got {excerpt(_scalar(loader, node))}")
        return x
    if isinstance(kind, tuple) and kind[0] == "vector":
        _, n, each = kind
        v = _scalar(loader, node)
        nums = [_as_number(x) for x in v] if isinstance(v, list) else None
        if nums is None or len(nums) != n or any(x is None or not math.isfinite(x) for x in nums):
            raise InputError(f"{where}: {key}: expected a list of {n} numbers, got {excerpt(v)}")
        if each == "positive" and min(nums) <= 0:
            raise InputError(f"{where}: {key}: every value must be > 0, got {v}")
        if each == "nonneg" and min(nums) < 0:
            raise InputError(f"{where}: {key}: every value must be >= 0, got {v}")
        return nums
    v = _scalar(loader, node)
    if kind == "text":
        v = "" if v is None else v
        if not isinstance(v, str) or len(v) > 4096:
            raise InputError(f"{where}: {key}: expected a name or a file path, got {excerpt(v)}")
        return v
    if kind.startswith("int"):
        low = int(kind[-1])
        if isinstance(v, bool) or not isinstance(v, int) or v < low:
            raise InputError(f"{where}: {key}: expected a whole number >= {low}, got {excerpt(v)}")
        return v
    x = _as_number(v)
    if x is None or not math.isfinite(x):
        raise InputError(f"{where}: {key}: expected a number, got {excerpt(v)}")
    if kind == "positive" and x <= 0:
        raise InputError(f"{where}: {key}: must be > 0, got {v}")
    if kind == "nonneg" and x < 0:
        raise InputError(f"{where}: {key}: must be >= 0, got {v}")
    return x


def _mapping(path, node, key):
    if not isinstance(node, yaml.MappingNode):
        raise InputError(f"{_where(path, node)}: {key}: expected a mapping of keys")
    out = {}
    for k, v in node.value:
        if k.value in out:
            raise InputError(f"{_where(path, k)}: {key}.{excerpt(k.value)[1:-1]}: given twice")
        out[k.value] = (k, v)
    return out


def read_settings(path):
    """The compensator's settings: ({key: (value, line)} of the header, CompensatorSettings)."""
    text = read_text(path)
    meta = header_meta(path, text.splitlines())
    loader = UserYamlLoader(text, path)  # no anchors or aliases, bounded nesting
    try:
        root = loader.get_single_node()
    except yaml.YAMLError as e:
        mark = getattr(e, "problem_mark", None)
        where = f"{path}, line {mark.line + 1}, column {mark.column + 1}" if mark else str(path)
        raise InputError(f"{where}: invalid YAML ({getattr(e, 'problem', None) or e})") from None
    finally:
        loader.dispose()
    if root is None:
        fail(path, what="empty; expected a 'compensator:' mapping")
    top = _mapping(path, root, "(top)")
    for k, (knode, _) in top.items():
        if k != "compensator":
            raise InputError(f"{_where(path, knode)}: unknown top-level key {excerpt(k)} (expected 'compensator'; "
                             "a settings file holds the compensator only)")
    if "compensator" not in top:
        fail(path, what="missing the 'compensator:' mapping")
    values = {}

    def walk(node, layout, prefix):
        items = _mapping(path, node, prefix)
        for k, (knode, _) in items.items():
            if k not in layout:
                raise InputError(f"{_where(path, knode)}: {prefix}: unknown key {excerpt(k)} "
                                 f"(allowed: {', '.join(layout)})")
        for k, spec in layout.items():
            key = f"{prefix}.{k}"
            if k not in items:
                if k in _OPTIONAL_SECTIONS and prefix == "compensator":
                    continue
                if isinstance(spec, dict) or spec[0] not in _OPTIONAL:
                    raise InputError(f"{_where(path, node)}: {prefix}: missing key {excerpt(k)}")
                continue
            knode, vnode = items[k]
            if isinstance(spec, dict):
                walk(vnode, spec, key)
            else:
                values[spec[0]] = _check_value(path, loader, vnode, key, spec[1])

    walk(top["compensator"][1], _SETTINGS_LAYOUT, "compensator")
    payload = {k.split(".", 1)[1]: v for k, v in values.items() if k.startswith("payload.")}
    servo = {k.split(".", 1)[1]: v for k, v in values.items() if k.startswith("servo.")} or None
    rest = {k: v for k, v in values.items() if not k.startswith(("payload.", "servo."))}
    settings = CompensatorSettings(payload=payload, servo=servo, path=str(path), **rest)
    if settings.filter_kind == "lowpass" and not settings.filter_cutoff_hz < 0.5 * settings.sensor_rate_hz:
        fail(path, what=f"compensator.filter.cutoff_hz: {settings.filter_cutoff_hz:g} Hz must be below half the "
                        f"sensor rate ({0.5 * settings.sensor_rate_hz:g} Hz)")
    return meta, settings

