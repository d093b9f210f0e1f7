"""The files of one machining run as a cell records them (docs/run_files.md):

  wrench_log.csv    the wrist sensor's raw readings, sensor frame, with times
  joint_log.csv     the controller's joint angles (motor side) and the
                    compensator's correction in them, once per controller period
  compensator.yaml  the compensator's settings (nothing of the plant)
  scan.csv          the laser or CMM scan of the machined face: positions,
                    nominal and measured heights, the instrument's noise
  RUN_ID            the run's id; every file above carries it in a
                    ``# run_id: ...`` line

A reader for each (an InputError of one line naming the file, line and
column of anything wrong) and a writer (text) for each, which
``robstiff simulate --out`` uses so that a simulated run folder holds the
same files.  Files whose names start with ``sim_`` are the simulation's
truth (the plant, the actual tool path); nothing here reads them.

Plain numpy and PyYAML; no Drake.  Units are in the column and key names;
angles at the interface are the controller's degrees.
"""

import math
import os
from dataclasses import dataclass, field, fields
from pathlib import Path

import numpy as np
import yaml

from robstiff_drake.errors import InputError, excerpt
from robstiff_drake.command import inside
from robstiff_drake.io import RUN_ID_FILE
from robstiff_drake.user_files import UserYamlLoader, read_user_text

WRENCH_LOG = "wrench_log.csv"
JOINT_LOG = "joint_log.csv"
SETTINGS = "compensator.yaml"
SCAN = "scan.csv"
CELL_FILES = (WRENCH_LOG, JOINT_LOG, SETTINGS, SCAN)
SIM_PREFIX = "sim_"  # the simulation's truth: never read by the diagnosis

WRENCH_COLUMNS = ("t_s", "fx_N", "fy_N", "fz_N", "mx_Nm", "my_Nm", "mz_Nm")
JOINT_COLUMNS = ("t_s",) + tuple(f"q{j}_deg" for j in range(1, 7)) + tuple(f"corr{j}_deg" for j in range(1, 7))
SCAN_COLUMNS = ("x_mm", "y_mm", "nominal_mm", "height_mm")
REFERENCE_COLUMNS = ("t_s",) + tuple(f"q{j}_deg" for j in range(1, 7))
MIN_ROWS = {WRENCH_LOG: 10, JOINT_LOG: 10, SCAN: 20}


# ---------------------------------------------------------------- data


@dataclass
class WrenchLog:
    """The sensor's raw readings: (force N, moment N*m about the sensor
    origin) that the payload exerts on the sensor, in the sensor frame;
    NaN rows are samples the sensor did not deliver (dropouts)."""

    t_s: np.ndarray
    wrench: np.ndarray  # (N, 6)
    path: str = ""


@dataclass
class JointLog:
    """The controller's joint angles (deg, motor side: what the servos are
    sent and the encoders report) and the compensator's correction that
    they include (deg), once per controller period."""

    t_s: np.ndarray
    q_deg: np.ndarray  # (N, 6)
    correction_deg: np.ndarray  # (N, 6)
    path: str = ""


@dataclass
class Scan:
    """The measured face: positions (mm, robot base frame), the nominal
    height the program should leave and the measured height (mm).
    ``noise_mm``: the instrument's 1-sigma height noise as its file states
    it (None: not stated)."""

    x_mm: np.ndarray
    y_mm: np.ndarray
    nominal_mm: np.ndarray
    height_mm: np.ndarray
    noise_mm: float = None
    path: str = ""

    @property
    def error_mm(self):
        """Surface error (mm): nominal - measured, positive where more was cut."""
        return self.nominal_mm - self.height_mm


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
    mode: str = "plain"  # "plain" or "predictive"
    period_ms: float = 4.0
    delay_steps: int = 1
    filter_kind: str = "lowpass"  # "lowpass", "revolution_average" or "none"
    filter_cutoff_hz: float = 10.0
    filter_order: int = 2
    sensor_rate_hz: float = 1000.0
    max_jump_N: float = 1000.0
    spindle_rpm: float = 3600.0
    saturation_deg: float = 0.5
    rate_limit_deg_per_s: float = 5.0
    lost_motion_rad: list = field(default_factory=_zeros6)
    coupling_c23_rad_per_Nm: float = 0.0
    force_model_scale: float = 1.0
    # the robot the model belongs to: a library name (`robstiff robots`) or a
    # robot file (relative to this settings file); empty: the IRB6400
    robot: str = ""
    # the robot controller's servo (its `servo:` section, SERVO_KEYS): the
    # interpolator's dead time (ms), the position loop's gain (1/s), the
    # velocity loop's bandwidth (Hz) and the path's velocity feed-forward
    # (0-1).  None: not stated (a file written before issue 13); what a
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


@dataclass
class RunFiles:
    """A run folder's cell files (the ones a real cell has)."""

    folder: Path
    run_id: str
    settings: CompensatorSettings
    scan: Scan
    wrench: WrenchLog = None
    joints: JointLog = None


# ---------------------------------------------------------------- text tables


def _fail(path, line=None, column=None, what=""):
    where = str(path)
    if line is not None:
        where += f", line {line}"
    if column is not None:
        where += f", column {column}"
    raise InputError(f"{where}: {what}")


def _read_text(path):
    """A run file's text (user_files.read_user_text: a regular file, UTF-8,
    noted as an input of the command; no size bound, a long run's logs are large)."""
    return read_user_text(path, "run file", max_bytes=None)


def run_file(folder, name):
    """``folder/name``, refused (InputError) when it resolves outside the
    folder (a symbolic link out of it): a run folder's files are its own."""
    p = Path(folder) / name
    if os.path.lexists(p) and not inside(p, folder):
        _fail(p, what=f"a symbolic link to a file outside the run folder {folder}; every file of a run folder must "
                      "be inside it (copy the file in)")
    return p


def _header_meta(path, lines):
    """``# key: value`` lines before the first other line -> {key: (value, line)}."""
    meta = {}
    for n, line in enumerate(lines, 1):
        s = line.strip()
        if not s:
            continue
        if not s.startswith("#"):
            break
        key, sep, value = s[1:].partition(":")
        key = key.strip()
        if sep and key and " " not in key:
            if key in meta:
                _fail(path, n, what=f"'{key}' is given twice (first on line {meta[key][1]})")
            meta[key] = (value.strip(), n)
    return meta


def read_table(path, columns, *, empty_ok=()):
    """A CSV table with a header line: ({key: (value, line)} of its leading
    ``# key: value`` lines, {column: array}, line numbers of the rows).
    Every column of ``columns`` is required and no other is allowed; an
    empty field is NaN in ``empty_ok`` columns and an error elsewhere."""
    lines = _read_text(path).splitlines()
    meta = _header_meta(path, lines)
    header, header_line, rows, row_lines = None, 0, [], []
    for n, line in enumerate(lines, 1):
        s = line.strip()
        if not s or s.startswith("#"):
            continue
        cells = [c.strip() for c in s.split(",")]
        if header is None:
            header, header_line = cells, n
            for j, h in enumerate(header, 1):
                if h not in columns:
                    _fail(path, n, j, f"unknown column {excerpt(h)} (expected {', '.join(columns)})")
                if header.index(h) != j - 1:
                    _fail(path, n, j, f"column {excerpt(h)} is given twice")
            missing = [c for c in columns if c not in header]
            if missing:
                _fail(path, n, what=f"missing column {missing[0]} (expected {', '.join(columns)})")
            continue
        if len(cells) != len(header):
            _fail(path, n, what=f"{len(cells)} fields, but the header (line {header_line}) has {len(header)}")
        vals = []
        for j, (h, c) in enumerate(zip(header, cells), 1):
            if c == "":
                if h in empty_ok:
                    vals.append(math.nan)
                    continue
                _fail(path, n, j, f"{h} is empty")
            try:
                v = float(c)
            except ValueError:
                _fail(path, n, j, f"{h}: {excerpt(c)} is not a number")
            if not math.isfinite(v):
                _fail(path, n, j, f"{h}: {excerpt(c)} is not a finite number")
            vals.append(v)
        rows.append(vals)
        row_lines.append(n)
    if header is None:
        _fail(path, what=f"no header line (expected the columns {', '.join(columns)})")
    need = MIN_ROWS.get(Path(path).name, 1)
    if len(rows) < need:
        _fail(path, what=f"{len(rows)} data rows; at least {need} are needed")
    data = np.array(rows, dtype=float).reshape(len(rows), len(header))
    return meta, {h: data[:, header.index(h)] for h in columns}, np.array(row_lines)


def _check_times(path, t, row_lines):
    bad = np.flatnonzero(np.diff(t) <= 0)
    if bad.size:
        i = bad[0] + 1
        _fail(path, row_lines[i], 1, f"t_s {t[i]:g} is not after the previous row's {t[i - 1]:g} "
                                     "(times must increase)")


def _number_text(v):
    """A float as text that reads back exactly (and as a float in YAML 1.1)."""
    s = repr(float(v))
    if "e" in s and "." not in s:
        s = s.replace("e", ".0e")
    return s


def _meta_lines(run_id, notes):
    out = [] if run_id is None else [f"# run_id: {run_id}"]
    for note in notes:
        out.extend(f"# {ln}" if ln else "#" for ln in note.splitlines())
    return "\n".join(out) + "\n"


def _table_text(run_id, notes, columns, data, fmt):
    lines = [_meta_lines(run_id, notes), ",".join(columns) + "\n"]
    for row in np.asarray(data, dtype=float):
        lines.append(",".join("" if not math.isfinite(v) else format(v, fmt) for v in row) + "\n")
    return "".join(lines)


# ---------------------------------------------------------------- wrench log


def read_wrench_log(path):
    """The wrist sensor's log: ({key: (value, line)}, WrenchLog).  An empty
    row of all six wrench fields is a dropout (NaN); a partly empty row is an error."""
    meta, cols, row_lines = read_table(path, WRENCH_COLUMNS, empty_ok=WRENCH_COLUMNS[1:])
    w = np.column_stack([cols[c] for c in WRENCH_COLUMNS[1:]])
    partial = np.flatnonzero(np.isnan(w).any(axis=1) & ~np.isnan(w).all(axis=1))
    if partial.size:
        i = partial[0]
        j = int(np.flatnonzero(np.isnan(w[i]))[0])
        _fail(path, row_lines[i], j + 2, f"{WRENCH_COLUMNS[j + 1]} is empty while other components are not "
                                         "(a dropout leaves all six empty)")
    _check_times(path, cols["t_s"], row_lines)
    return meta, WrenchLog(cols["t_s"], w, str(path))


def wrench_log_text(log, run_id, notes=()):
    """wrench_log.csv: time (s) and the six raw components, sensor frame."""
    notes = ["wrench_log: the wrist sensor's raw readings, as it delivered them (bias and payload weight "
             "included): force (N) and moment (N*m, about the sensor origin) that the payload exerts on the "
             "sensor, in the sensor frame; t_s: seconds on the controller's clock; an empty row is a dropout.",
             *notes]
    return _table_text(run_id, notes, WRENCH_COLUMNS, np.column_stack([log.t_s, log.wrench]), ".7g")


# ---------------------------------------------------------------- joint log


def read_joint_log(path):
    """The controller's joint log: ({key: (value, line)}, JointLog)."""
    meta, cols, row_lines = read_table(path, JOINT_COLUMNS)
    _check_times(path, cols["t_s"], row_lines)
    q = np.column_stack([cols[f"q{j}_deg"] for j in range(1, 7)])
    c = np.column_stack([cols[f"corr{j}_deg"] for j in range(1, 7)])
    return meta, JointLog(cols["t_s"], q, c, str(path))


def joint_log_text(log, run_id, notes=()):
    """joint_log.csv: time (s), the six joint angles and the six corrections (deg)."""
    notes = ["joint_log: once per controller period, q*_deg: the joint angles the controller sends to the "
             "servos (motor side, controller degrees: the program's path plus the compensator's correction); "
             "corr*_deg: the compensator's correction included in them.",
             *notes]
    return _table_text(run_id, notes, JOINT_COLUMNS, np.column_stack([log.t_s, log.q_deg, log.correction_deg]),
                       ".10g")


# ---------------------------------------------------------------- joint reference


def joint_reference_text(robot, t_s, q_rad, run_id=None, notes=()):
    """joint_reference.csv, what `robstiff compensate --reference` streams:
    time (s) and the path's joint references in the controller's degrees
    (``q_rad``: the model's joint angles, (N, 6) rad, mapped through the
    robot file's joint map).  ``run_id`` None: a file outside a run folder."""
    q_deg = robot.controller_deg(np.asarray(q_rad, dtype=float))
    return _table_text(run_id, notes, REFERENCE_COLUMNS, np.column_stack([t_s, q_deg]), ".12g")


# ---------------------------------------------------------------- scan


def _meta_number(path, meta, key, *, low=0.0):
    if key not in meta:
        return None
    text, line = meta[key]
    try:
        v = float(text)
    except ValueError:
        _fail(path, line, what=f"{key}: {excerpt(text)} is not a number")
    if not (math.isfinite(v) and v >= low):
        _fail(path, line, what=f"{key}: must be a number >= {low:g}, got {text}")
    return v


def read_scan(path):
    """The measured face: ({key: (value, line)}, Scan).  Rows with an empty
    height (no reading) are left out; the header may state the
    instrument's noise as ``# noise_mm: SIGMA`` (1 sigma, mm)."""
    meta, cols, row_lines = read_table(path, SCAN_COLUMNS, empty_ok=("height_mm",))
    ok = np.isfinite(cols["height_mm"])
    if ok.sum() < MIN_ROWS[SCAN]:
        _fail(path, what=f"{int(ok.sum())} measured points; at least {MIN_ROWS[SCAN]} are needed")
    noise = _meta_number(path, meta, "noise_mm")
    return meta, Scan(cols["x_mm"][ok], cols["y_mm"][ok], cols["nominal_mm"][ok], cols["height_mm"][ok],
                      noise, str(path))


def scan_text(scan, run_id, notes=()):
    """scan.csv: positions, nominal and measured heights (mm); the stated noise in the header."""
    head = []
    if scan.noise_mm is not None:
        head.append(f"noise_mm: {_number_text(scan.noise_mm)}")
    notes = head + ["scan: the machined face as the scanner measures it; x_mm, y_mm: position in the robot "
                    "base frame; nominal_mm: the height the program should leave there; height_mm: the measured "
                    "height (empty: no reading). noise_mm: the instrument's 1-sigma height noise.", *notes]
    data = np.column_stack([scan.x_mm, scan.y_mm, scan.nominal_mm, scan.height_mm])
    return _table_text(run_id, notes, SCAN_COLUMNS, data, ".6f")


# ---------------------------------------------------------------- settings (YAML)

# key -> (attribute, kind); kind: "positive", "nonneg", "int>=0", "int>=1",
# ("choice", options), ("vector", n, "positive" | "nonneg" | "any"), "number"
_SETTINGS_LAYOUT = {
    "robot": ("robot", "text"),
    "mode": ("mode", ("choice", ("plain", "predictive"))),
    "period_ms": ("period_ms", "positive"),
    "delay_steps": ("delay_steps", "int>=0"),
    "saturation_deg": ("saturation_deg", "positive"),
    "rate_limit_deg_per_s": ("rate_limit_deg_per_s", "positive"),
    "sensor": {"rate_hz": ("sensor_rate_hz", "positive"), "max_jump_N": ("max_jump_N", "positive")},
    "filter": {"kind": ("filter_kind", ("choice", ("lowpass", "revolution_average", "none"))),
               "cutoff_hz": ("filter_cutoff_hz", "positive"), "order": ("filter_order", "int>=1")},
    "model": {"joint_stiffness_Nm_per_rad": ("joint_stiffness_Nm_per_rad", ("vector", 6, "positive")),
              "lost_motion_rad": ("lost_motion_rad", ("vector", 6, "nonneg")),
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
_OPTIONAL = {"lost_motion_rad", "coupling_c23_rad_per_Nm", "force_model_scale", "robot", "servo.velocity_integral_hz"}
_OPTIONAL_SECTIONS = {"servo"}  # a file without it is read (servo None); diagnose-run refuses it
_KEY_NOTES = {
    "robot": "the robot the model belongs to: a library name or a robot file (relative to this file)",
    "mode": "plain: the measured force, filtered and delayed; predictive: the force model ahead plus the "
            "filtered measured residual",
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
        return "[" + ", ".join(_number_text(x) for x in np.ravel(v)) + "]"
    return _number_text(v)


def settings_text(settings, run_id, notes=()):
    """compensator.yaml of ``settings``."""
    src = _settings_source(settings)
    ints = {"delay_steps", "filter_order"}

    def value(attr):
        return _value_text(int(src[attr]) if attr in ints else src[attr])

    lines = [_meta_lines(run_id, ["The compensator's settings: what it believes and how its loop runs. Nothing "
                                  "of the plant (the robot's true joints) is here.", *notes]), "compensator:\n"]
    for key, spec in _SETTINGS_LAYOUT.items():
        if key in _OPTIONAL_SECTIONS and getattr(settings, key) is None:
            continue
        if key in _KEY_NOTES:
            lines.append(f"  # {_KEY_NOTES[key]}\n")
        if isinstance(spec, dict):
            lines.append(f"  {key}:\n")
            lines.extend(f"    {sub}: {value(attr)}\n" for sub, (attr, _) in spec.items()
                         if attr in src or attr not in _OPTIONAL)
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
    text = _read_text(path)
    meta = _header_meta(path, text.splitlines())
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
        _fail(path, what="empty; expected a 'compensator:' mapping")
    top = _mapping(path, root, "(top)")
    for k, (knode, _) in top.items():
        if k != "compensator":
            raise InputError(f"{_where(path, knode)}: unknown top-level key {excerpt(k)} (expected 'compensator'; "
                             "a settings file holds the compensator only)")
    if "compensator" not in top:
        _fail(path, what="missing the 'compensator:' mapping")
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
        _fail(path, what=f"compensator.filter.cutoff_hz: {settings.filter_cutoff_hz:g} Hz must be below half the "
                         f"sensor rate ({0.5 * settings.sensor_rate_hz:g} Hz)")
    return meta, settings


# ---------------------------------------------------------------- run folders


def read_run_id(folder):
    """The run id in ``folder``/RUN_ID (InputError if there is none)."""
    p = run_file(folder, RUN_ID_FILE)
    if not p.is_file():
        raise InputError(f"{folder}: no {RUN_ID_FILE} file (a run folder names its run there; every file of the "
                         "run carries the same id in a '# run_id: ...' line)")
    rid = _read_text(p).strip()
    if not rid or len(rid.split()) != 1:
        _fail(p, 1, what=f"expected one run id, got {excerpt(rid)}")
    return rid


def check_run_id(path, meta, run_id):
    """Refuse a file that does not carry the folder's run id."""
    if "run_id" not in meta:
        _fail(path, what=f"no '# run_id: ...' line; every file of a run folder carries its run id ({run_id})")
    value, line = meta["run_id"]
    if value != run_id:
        _fail(path, line, what=f"run_id {value} is not this folder's run ({run_id} in {RUN_ID_FILE}): the folder "
                               "mixes files of different runs")


READERS = {WRENCH_LOG: read_wrench_log, JOINT_LOG: read_joint_log, SETTINGS: read_settings, SCAN: read_scan}


def load_run_files(folder, names=CELL_FILES, scan=None):
    """Read the cell files ``names`` of a run folder (each must carry the
    folder's run id); RunFiles.  Never opens a ``sim_`` file.  ``scan``: a
    scan file made outside the run (a CMM's or a laser line's, no run id)
    read instead of the folder's scan.csv."""
    folder = Path(folder)
    if not folder.is_dir():
        raise InputError(f"{folder}: no such run folder")
    if scan is not None:
        names = tuple(n for n in names if n != SCAN)
    for name in names:
        if not run_file(folder, name).is_file():
            raise InputError(f"{folder}: missing {name} (a run folder holds {', '.join(CELL_FILES)} and "
                             f"{RUN_ID_FILE}, see docs/run_files.md; `robstiff simulate` writes them for its "
                             "compensated cut)")
    run_id = read_run_id(folder)
    got = {}
    for name in names:
        meta, data = READERS[name](folder / name)
        check_run_id(folder / name, meta, run_id)
        got[name] = data
    if scan is not None:
        got[SCAN] = read_scan(scan)[1]
    return RunFiles(folder, run_id, got[SETTINGS], got[SCAN], got.get(WRENCH_LOG), got.get(JOINT_LOG))
