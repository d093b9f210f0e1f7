"""The keys of a robot file (models/*.yaml and a user's own), each with its
kind, allowed range and unit, in ONE table: ``KEYS``; and the reader that
checks a file against it before anything is built from it.

To add a key, add one line to ``KEYS`` (dotted path; ``[]`` for the items of
a list, e.g. ``links[].mass_kg``) with its range, unit and the reason for
the range; ``read_robot_values`` then refuses the file when the key is
missing (unless ``required=False``), of the wrong type or length, or out of
range, and returns its value (a float, a numpy vector or a text) under the
same dotted path (list items: ``values["links"][i]["mass_kg"]``).
model/robot.py builds the RobotModel from those values.

Every error is one line, ``FILE:LINE: key 'KEY': what is wrong (allowed
range and unit)``.  The YAML is read by user_files.load_yaml: duplicated
keys (PyYAML keeps the last one silently), anchors and aliases, and deep
nesting are refused; a value quoted in an error is a short, escaped excerpt.

After the ranges, ``check_units`` looks for values written in another unit
than the key's, from the scales a 6-axis arm has: link lengths in metres,
angles in radians.  Plain Python and numpy; no Drake.
"""

import math
import re
from dataclasses import dataclass

import numpy as np

from robstiff_drake.errors import InputError, excerpt

N_JOINTS = 6
CONVENTIONS = ("standard_dh", "modified_dh")
# Joint stiffness of a robot joint (N*m/rad): a small cobot's wrist is about
# 1e3, the stiffest axis of the largest industrial robots about 1e7; the
# scenario's and compensate's stiffness checks use the same range.
STIFFNESS_RANGE_NM_PER_RAD = (1e3, 1e9)
# The largest industrial arms reach about 4 m; 5 m bounds any link length,
# centre of mass or tool offset (mm).
MAX_LENGTH_MM = 5000.0
# A cell: 10 m from the robot base covers the largest arm on a track (mm).
MAX_CELL_MM = 10000.0


@dataclass(frozen=True)
class Key:
    """One key of a robot file.  ``kind``: "number", "vector" (``length``
    numbers), "text", "choice" (one of ``options``), "section" (a mapping of
    keys) or "list" (``length`` items, 0: any number; each a mapping of the
    keys ``NAME[].KEY``).  Numbers lie in [lo, hi] (``lo_open``: lo itself
    excluded) in ``unit``; ``names`` names a vector's components in errors."""

    kind: str
    unit: str = ""
    lo: float = -math.inf
    hi: float = math.inf
    length: int = 0
    required: bool = True
    lo_open: bool = False
    integer: bool = False
    options: tuple = ()
    names: tuple = ()
    why: str = ""


JOINTS = tuple(f"joint {j}" for j in range(1, N_JOINTS + 1))
PERIODIC_WHY = "reducers and encoders give a few tenths to a few mrad; 20 mrad (1.1 deg) would be seen"
XYZ = ("x", "y", "z")
ANGLE = dict(unit="deg", lo=-360.0, hi=360.0, length=N_JOINTS, names=JOINTS)
LENGTH = dict(unit="mm", lo=-MAX_LENGTH_MM, hi=MAX_LENGTH_MM)

KEYS = {
    "name": Key("text"),
    "manufacturer": Key("text", required=False),
    "model": Key("text", required=False),
    "source": Key("text", required=False),
    "convention": Key("choice", options=CONVENTIONS, required=False),
    "dh": Key("section"),
    "dh.d_mm": Key("vector", length=N_JOINTS, names=JOINTS, **LENGTH),
    "dh.a_mm": Key("vector", length=N_JOINTS, names=JOINTS, **LENGTH),
    "dh.alpha_deg": Key("vector", **ANGLE),
    "dh.home_deg": Key("vector", **ANGLE),
    # Hayati's tilt between nearly parallel axes (a calibrated arm, written by
    # `diagnose --write-robot`): a small correction; larger angles belong in alpha_deg
    "dh.beta_deg": Key("vector", "deg", -5.0, 5.0, N_JOINTS, required=False, names=JOINTS,
                       why="a small tilt between nearly parallel axes; larger angles belong in alpha_deg"),
    "controller": Key("section", required=False),
    "controller.sign": Key("vector", "", -1.0, 1.0, N_JOINTS, required=False, names=JOINTS,
                           why="each sign must be +1 or -1"),
    "controller.offset_deg": Key("vector", required=False, **ANGLE),
    "controller.coupling": Key("list", required=False),
    "controller.coupling[].joint": Key("number", "", 1, N_JOINTS, integer=True),
    "controller.coupling[].from": Key("number", "", 1, N_JOINTS, integer=True),
    "controller.coupling[].factor": Key("number", "", -10.0, 10.0, why="FANUC's J2/J3 interaction is +-1"),
    # angle errors periodic in a joint's controller angle (reducer, encoder), found by a tracker campaign's
    # `diagnose --write-robot`: error_rad = 1e-3 (sin_mrad sin(2 pi q / period) + cos_mrad cos(2 pi q / period)),
    # q the controller's angle (deg), added to it before the model's joint map
    "joint_periodic_errors": Key("list", required=False),
    "joint_periodic_errors[].joint": Key("number", "", 1, N_JOINTS, integer=True),
    "joint_periodic_errors[].period_deg": Key("number", "deg", 1.0, 720.0, why="a reducer stage's or an encoder's "
                                              "period, a few degrees to a full turn"),
    "joint_periodic_errors[].sin_mrad": Key("number", "mrad", -20.0, 20.0, why=PERIODIC_WHY),
    "joint_periodic_errors[].cos_mrad": Key("number", "mrad", -20.0, 20.0, why=PERIODIC_WHY),
    "joint_limits": Key("section"),
    # two turns either way: the widest working range a robot controller offers
    "joint_limits.lower_deg": Key("vector", "deg", -720.0, 720.0, N_JOINTS, names=JOINTS),
    "joint_limits.upper_deg": Key("vector", "deg", -720.0, 720.0, N_JOINTS, names=JOINTS),
    # the controller's axis speeds and accelerations (controller convention), optional; `compensate` and
    # `sim-cell` need them.  The fastest wrist axes of small arms turn about 1,000 deg/s; 5,000 bounds a typo
    "joint_limits.speed_deg_per_s": Key("vector", "deg/s", 0.0, 5000.0, N_JOINTS, required=False, lo_open=True,
                                        names=JOINTS, why="data sheets give 50-1,000 deg/s"),
    "joint_limits.acceleration_deg_per_s2": Key("vector", "deg/s^2", 0.0, 1e5, N_JOINTS, required=False,
                                                lo_open=True, names=JOINTS,
                                                why="full speed in a few tens of milliseconds at most"),
    "joint_stiffness_Nm_per_rad": Key("vector", "N*m/rad", *STIFFNESS_RANGE_NM_PER_RAD, N_JOINTS, names=JOINTS,
                                      why="a small cobot's wrist ~1e3; the stiffest large-robot axis ~1e7; values in "
                                          "kN*m/rad are 1000 times too small"),
    # Reflected rotor inertias (n^2 J_rotor at the joint): above 1e4 a value is a unit slip (the largest
    # arms' main axes reflect a few hundred); 0 would leave the motor massless.  Absent: the station's rule
    # (diagrams/station.motor_inertia)
    "motor_inertia_kgm2": Key("vector", "kg*m^2", 1e-3, 1e4, N_JOINTS, required=False, names=JOINTS,
                              why="the largest arms' main axes reflect a few hundred kg*m^2"),
    "links": Key("list", length=N_JOINTS + 1, why="the base and six moving links"),
    "links[].name": Key("text"),
    "links[].mass_kg": Key("number", "kg", 0.01, 2e4, why="a desktop arm's wrist to the heaviest industrial robots, "
                                                         "about 11 t in all"),
    "links[].com_mm": Key("vector", length=3, names=XYZ, **LENGTH),
    # a link's housing: from a millimetre (no housing is thinner) to 5 m
    "links[].box_mm": Key("vector", "mm", 1.0, MAX_LENGTH_MM, 3, required=False, names=XYZ),
    "links[].cylinder_mm": Key("section", required=False),
    "links[].cylinder_mm.radius": Key("number", "mm", 1.0, MAX_LENGTH_MM / 2),
    "links[].cylinder_mm.length": Key("number", "mm", 1.0, MAX_LENGTH_MM),
    "links[].cylinder_mm.axis": Key("choice", options=XYZ),
    "links[].inertia_kgm2": Key("vector", "kg*m^2", -1e4, 1e4, 6, required=False,
                                names=("ixx", "iyy", "izz", "ixy", "ixz", "iyz")),
    # the maker's rated wrist payload (data sheet): a payload above it is a warning (robot.py), not an error
    "rated_payload_kg": Key("number", "kg", 0.0, 2500.0, required=False, lo_open=True,
                            why="data sheets give 0.5 kg (small cobots) to 2,300 kg (the largest arms)"),
    "payload": Key("section"),
    # the heaviest robot payloads are about 1.3 t (as the payload calibration's range)
    "payload.mass_kg": Key("number", "kg", 0.0, 2000.0, lo_open=True),
    "payload.com_mm": Key("vector", "mm", -2000.0, 2000.0, 3, names=XYZ),
    # as --tool: a tool 5 m from the flange is no robot tool
    "payload.tool_point_mm": Key("vector", length=3, required=False, names=XYZ, **LENGTH),
    # the point a laser tracker measured on the flange (its target), as `diagnose --write-robot` fits it; the
    # machining tool point (tool_point_mm) is another point: the diagnosis of a tracker campaign starts from this one
    "payload.measured_point_mm": Key("vector", length=3, required=False, names=XYZ, **LENGTH),
    "machining_workspace": Key("section"),
    "machining_workspace.x_mm": Key("vector", "mm", -MAX_CELL_MM, MAX_CELL_MM, 2, names=("min", "max")),
    "machining_workspace.y_mm": Key("vector", "mm", -MAX_CELL_MM, MAX_CELL_MM, 2, names=("min", "max")),
    "machining_workspace.z_mm": Key("vector", "mm", -MAX_CELL_MM, MAX_CELL_MM, 2, names=("min", "max")),
    "machining_workspace.reference_tool_point_mm": Key("vector", "mm", -MAX_CELL_MM, MAX_CELL_MM, 3, names=XYZ),
}


# A number as YAML 1.2 reads it: PyYAML's YAML 1.1 takes "1.5e6" (no sign in
# the exponent) for text.  ASCII digits only ("١٢" is not 12).
_NUMBER = re.compile(r"[+-]?(\d+(\.\d*)?|\.\d+)([eE][+-]?\d+)?", re.ASCII)


def _range_text(k):
    lo = "(" if k.lo_open else "["
    return f"{lo}{k.lo:g}, {k.hi:g}] {k.unit}".rstrip()


class _Walker:
    """Checks a parsed robot file against KEYS; errors name file, line, key."""

    def __init__(self, path, lines):
        self.path = str(path)
        self.lines = lines

    def fail(self, where, key, what):
        line = None
        p = tuple(where)
        while p and line is None:
            line, p = self.lines.get(p), p[:-1]
        at = f"{self.path}:{line}" if line else self.path
        raise InputError(f"{at}: key '{excerpt(key, 120)[1:-1]}': {what}")

    def number(self, where, key, v, k, name=""):
        label = f"{name}: " if name else ""
        if isinstance(v, str) and _NUMBER.fullmatch(v.strip()):
            v = float(v)
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            self.fail(where, key, f"{label}expected a number in {k.unit or 'no unit'}, got {excerpt(v)}")
        if not math.isfinite(v):
            self.fail(where, key, f"{label}expected a finite number, got {v}")
        if k.integer and v != int(v):
            self.fail(where, key, f"{label}expected a whole number, got {v:g}")
        why = f" ({k.why})" if k.why else ""
        if k.lo_open and v <= k.lo:
            self.fail(where, key, f"{label}must be > {k.lo:g}, got {v:g} (allowed range {_range_text(k)}){why}")
        if v < k.lo or v > k.hi:
            self.fail(where, key, f"{label}{v:g} is outside the allowed range {_range_text(k)}{why}")
        return float(v)

    def value(self, where, key, v, k):
        if k.kind == "number":
            return self.number(where, key, v, k)
        if k.kind == "vector":
            if not isinstance(v, list) or any(isinstance(x, (list, dict)) for x in v):
                self.fail(where, key, f"expected {k.length} numbers in {k.unit or 'no unit'}, got {excerpt(v)}")
            if len(v) != k.length:
                self.fail(where, key, f"expected {k.length} numbers, got {len(v)}")
            return np.array([self.number(where + (i,), key, x, k, k.names[i] if k.names else f"[{i}]")
                             for i, x in enumerate(v)])
        if k.kind == "text":
            if not isinstance(v, (str, int, float)) or isinstance(v, bool):
                self.fail(where, key, f"expected text, got {excerpt(v)}")
            return str(v)
        if k.kind == "choice":
            if v not in k.options:
                self.fail(where, key, f"unknown {key.rsplit('.', 1)[-1]} {excerpt(v)} (known: {', '.join(k.options)})")
            return v
        raise AssertionError(k.kind)  # sections and lists are walked by ``mapping``

    def mapping(self, where, prefix, doc, table_prefix):
        """The values of the keys under ``table_prefix`` in mapping ``doc``."""
        rest = {name[len(table_prefix):]: k for name, k in KEYS.items() if name.startswith(table_prefix)}
        children = {name: k for name, k in rest.items() if "." not in name and "[]" not in name}
        for key in doc:
            if key not in children:
                self.fail(where + (key,), prefix + str(key), f"unknown key (allowed: {', '.join(sorted(children))})")
        out = {}
        for name, k in children.items():
            key = prefix + name
            if name not in doc:
                if k.required:
                    self.fail(where, key, "missing")
                continue
            v = doc[name]
            w = where + (name,)
            if k.kind == "section":
                if not isinstance(v, dict):
                    self.fail(w, key, f"expected a mapping of keys, got {excerpt(v)}")
                for sub, value in self.mapping(w, key + ".", v, table_prefix + name + ".").items():
                    out[f"{name}.{sub}"] = value
            elif k.kind == "list":
                if not isinstance(v, list):
                    self.fail(w, key, f"expected a list, got {excerpt(v)}")
                if k.length and len(v) != k.length:
                    self.fail(w, key, f"expected a list of {k.length} items ({k.why or 'see the docs'}), got {len(v)}")
                items = []
                for i, item in enumerate(v):
                    if not isinstance(item, dict):
                        self.fail(w + (i,), f"{key}[{i}]", f"expected a mapping of keys, got {excerpt(item)}")
                    items.append(self.mapping(w + (i,), f"{key}[{i}].", item, table_prefix + name + "[]."))
                out[name] = items
            else:
                out[name] = self.value(w, key, v, k)
        return out


class RobotValues(dict):
    """{dotted key: checked value} of a robot file, and ``fail(key, what)``:
    an InputError naming the file, the key's line and the key."""

    def __init__(self, walker, values):
        super().__init__(values)
        self._walker = walker

    def fail(self, key, what):
        self._walker.fail(tuple(_split(key)), key, what)

    def at(self, key):
        """'FILE:LINE' of the key (its section's line when it has none of
        its own), for a warning about it."""
        w, line, p = self._walker, None, tuple(_split(key))
        while p and line is None:
            line, p = w.lines.get(p), p[:-1]
        return f"{w.path}:{line}" if line else str(w.path)


def read_robot_values(path, doc, lines):
    """The checked values of a parsed robot file (RobotValues; see the
    module docstring); InputError naming file, line and key."""
    w = _Walker(path, lines)
    if not isinstance(doc, dict):
        raise InputError(f"{path}: expected a mapping of keys at the top level, got {excerpt(doc)}")
    return RobotValues(w, w.mapping((), "", doc, ""))


def _split(key):
    """'links[2].mass_kg' -> ['links', 2, 'mass_kg']"""
    out = []
    for part in key.split("."):
        name, _, index = part.partition("[")
        out.append(name)
        if index:
            out.append(int(index.rstrip("]")))
    return out


# ---------------------------------------------------------------- units

# Where a robot file's numbers are in the wrong unit, the error says which
# unit they look like.  The scales of a 6-axis arm (any maker, any size):
# its longest link is hundreds of mm (a desktop arm's ~100 mm); its joints'
# working ranges span tens to hundreds of degrees; its link housings are
# tens to hundreds of mm.
MIN_LONGEST_LINK_MM = 50.0
MAX_RADIAN_LIMIT = 2 * math.pi + 0.01
MIN_LARGEST_SHAPE_MM = 20.0
# A tool point or payload centre of mass closer to the flange than this (but
# not at it) is a length in metres more likely than a real tool (mm).
MIN_TOOL_MM = 5.0


def _looks_like_radians(v):
    """Whether some value is a multiple of 90 deg written in radians."""
    a = np.abs(np.asarray(v, dtype=float))
    return bool(np.any(np.isclose(a[:, None], np.pi / 2 * np.arange(1, 5)[None, :], atol=2e-3, rtol=0)))


def check_units(values):
    """Refuse values in another unit than their key's (see above); return
    warnings (one line each) for the doubtful ones."""
    fail = values.fail
    lengths = np.abs(np.r_[values["dh.a_mm"], values["dh.d_mm"]])
    if 0.0 < lengths.max() < MIN_LONGEST_LINK_MM:
        fail("dh.a_mm", f"the longest link length (a_mm, d_mm) is {lengths.max():g} mm: a 6-axis arm's links are "
                        "hundreds of mm long; are these metres? (write mm)")
    for key in ("dh.alpha_deg", "dh.home_deg", "controller.offset_deg"):
        if key in values and _looks_like_radians(values[key]):
            v = values[key]
            i = int(np.argmax(np.isclose(np.abs(v)[:, None], np.pi / 2 * np.arange(1, 5), atol=2e-3).any(axis=1)))
            fail(key, f"{JOINTS[i]}: {v[i]:g} looks like radians ({np.rad2deg(v[i]):.0f} deg); write degrees")
    limits = np.abs(np.r_[values["joint_limits.lower_deg"], values["joint_limits.upper_deg"]])
    if limits.max() <= MAX_RADIAN_LIMIT:
        fail("joint_limits.lower_deg", f"every joint limit is within +-{limits.max():g}: a 6-axis arm's working "
                                       "ranges span tens to hundreds of degrees; are these radians? (write degrees)")
    if "joint_limits.speed_deg_per_s" in values:
        speeds = np.abs(values["joint_limits.speed_deg_per_s"])
        if speeds.max() <= MAX_RADIAN_LIMIT:
            fail("joint_limits.speed_deg_per_s", f"every axis speed is at most {speeds.max():g} deg/s: data sheets "
                                                 "give 50-1,000 deg/s; are these rad/s? (write deg/s)")
    sizes = []
    for link in values["links"]:
        if "box_mm" in link:
            sizes.append(np.max(link["box_mm"]))
        if "cylinder_mm.radius" in link:
            sizes.append(max(2 * link["cylinder_mm.radius"], link["cylinder_mm.length"]))
    if sizes and max(sizes) < MIN_LARGEST_SHAPE_MM:
        fail("links", f"the largest link shape is {max(sizes):g} mm: a 6-axis arm's links are hundreds of mm; "
                      "are box_mm and cylinder_mm in metres? (write mm)")
    ws = np.abs(np.r_[values["machining_workspace.x_mm"], values["machining_workspace.y_mm"],
                      values["machining_workspace.z_mm"]])
    if ws.max() < MIN_LONGEST_LINK_MM:
        fail("machining_workspace.x_mm", f"the workspace box lies within +-{ws.max():g} mm of the base: are its "
                                         "values metres? (write mm)")
    warnings = []
    for key, what in (("payload.tool_point_mm", "tool point"), ("payload.com_mm", "payload's centre of mass")):
        if key in values:
            d = float(np.linalg.norm(values[key]))
            if 0.0 < d < MIN_TOOL_MM:
                warnings.append(f"{values.at(key)}: {key} ({', '.join(f'{x:g}' for x in values[key])}): the {what} is "
                                f"{d:g} mm from the flange; is it in metres? (write mm)")
    return warnings
