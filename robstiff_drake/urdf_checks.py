"""The numbers of a URDF checked before Drake's parser sees them
(``robstiff import-urdf``): each refusal is one line naming the file, the
line, the element and the link or joint, where Drake would raise a
ValueError, a LinAlgError or an assertion failure, or replace a bad inertia
by 1 kg with only a warning.

* no ``xacro:`` element (a macro file: expand it first);
* elements nested at most MAX_DEPTH deep;
* ``origin`` xyz finite and within MAX_ORIGIN_M, rpy finite;
* ``axis`` xyz three finite numbers, not all zero;
* ``limit`` lower and upper finite, lower <= upper;
* ``mass`` finite and not negative; ``inertia`` finite, its principal
  moments not negative and each at most the sum of the other two (the
  triangle inequality every rigid body meets), to INERTIA_TOL of the trace.

Standard library and numpy only (no Drake)."""

import math
import xml.parsers.expat

import numpy as np

from robstiff_drake.errors import InputError

MAX_DEPTH = 32  # a URDF nests robot > link > inertial > inertia: four levels; gazebo plugins a few more
# ASSUMPTION: no robot arm's joint or link frame lies 100 m from its parent's
# (the longest industrial arms reach under 5 m); beyond, a typo or a unit.
MAX_ORIGIN_M = 100.0
INERTIA_TOL = 1e-6  # relative to the inertia's trace: CAD exports round their moments
XACRO_NS = "xacro"


def element_lines(raw):
    """The line of every element's start tag, in document order (as
    ElementTree's ``iter()`` visits them); InputError for a xacro element
    or nesting deeper than MAX_DEPTH (``raw``: the file's bytes)."""
    lines, depth = [], [0]
    p = xml.parsers.expat.ParserCreate()

    def start(tag, attrs):
        depth[0] += 1
        lines.append(p.CurrentLineNumber)
        if depth[0] > MAX_DEPTH:
            raise _Refused(p.CurrentLineNumber, f"elements nested {depth[0]} deep (<{tag}>); a URDF nests a few "
                                                "levels (robot > link > inertial > inertia)")
        if tag.startswith(XACRO_NS + ":") or tag == XACRO_NS:
            raise _Refused(p.CurrentLineNumber, f"<{tag}>: a xacro macro; import-urdf reads a plain URDF: expand "
                                                "it first (xacro robot.urdf.xacro > robot.urdf)")

    def end(tag):
        depth[0] -= 1

    p.StartElementHandler = start
    p.EndElementHandler = end
    try:
        p.Parse(raw, True)
    except _Refused:
        raise
    except xml.parsers.expat.ExpatError:
        return None  # (not well-formed: ElementTree's parse says where)
    return lines


class _Refused(Exception):
    def __init__(self, line, what):
        super().__init__(what)
        self.line, self.what = line, what


def _numbers(text, n, where, what):
    cells = (text or "").split()
    try:
        v = [float(c) for c in cells]
    except ValueError:
        raise _Refused(where, f"{what} {text!r}: not {n} numbers") from None
    if len(v) != n:
        raise _Refused(where, f"{what} {text!r}: {len(v)} numbers, expected {n}")
    if not all(math.isfinite(x) for x in v):
        raise _Refused(where, f"{what} {text!r}: not finite")
    return v


def _owner(parents, el):
    """'joint NAME' or 'link NAME' of the element ``el`` is in."""
    p = el
    while p is not None:
        if p.tag in ("joint", "link"):
            return f"{p.tag} {p.get('name')!r}"
        p = parents.get(p)
    return "the robot"


def _check(el, line, parents):
    owner = _owner(parents, el)
    tag = el.tag
    if tag == "origin":
        xyz = _numbers(el.get("xyz", "0 0 0"), 3, line, f"{owner}: <origin xyz>")
        _numbers(el.get("rpy", "0 0 0"), 3, line, f"{owner}: <origin rpy>")
        if max(abs(v) for v in xyz) > MAX_ORIGIN_M:
            raise _Refused(line, f"{owner}: <origin xyz {el.get('xyz')!r}>: more than {MAX_ORIGIN_M:g} m from its "
                                 "parent's frame (a URDF's lengths are metres)")
    elif tag == "axis":
        a = _numbers(el.get("xyz", "1 0 0"), 3, line, f"{owner}: <axis xyz>")
        if not any(a):
            raise _Refused(line, f"{owner}: <axis xyz {el.get('xyz')!r}>: a zero axis")
    elif tag == "limit":
        lo, hi = (el.get(k) for k in ("lower", "upper"))
        lo_v = _numbers(lo, 1, line, f"{owner}: <limit lower>")[0] if lo is not None else None
        hi_v = _numbers(hi, 1, line, f"{owner}: <limit upper>")[0] if hi is not None else None
        if lo_v is not None and hi_v is not None and lo_v > hi_v:
            raise _Refused(line, f"{owner}: <limit lower={lo!r} upper={hi!r}>: the lower limit is above the upper")
    elif tag == "mass":
        m = _numbers(el.get("value"), 1, line, f"{owner}: <mass value>")[0]
        if m < 0:
            raise _Refused(line, f"{owner}: <mass value={el.get('value')!r}>: a negative mass")
    elif tag == "inertia":
        keys = ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")
        v = dict(zip(keys, (_numbers(el.get(k, "0"), 1, line, f"{owner}: <inertia {k}>")[0] for k in keys)))
        inertia = np.array([[v["ixx"], v["ixy"], v["ixz"]], [v["ixy"], v["iyy"], v["iyz"]],
                            [v["ixz"], v["iyz"], v["izz"]]])
        ev = np.linalg.eigvalsh(inertia)
        tol = INERTIA_TOL * max(abs(float(np.trace(inertia))), 1e-12)
        if ev[0] < -tol or ev[2] > ev[0] + ev[1] + tol:
            raise _Refused(line, f"{owner}: <inertia>: principal moments {', '.join(f'{x:.4g}' for x in ev)} kg*m^2 "
                                 "are no rigid body's (each must be >= 0 and at most the sum of the other two)")


def check_urdf(path, raw, root):
    """InputError (one line: file, line, what) for the first number of
    the URDF (``raw`` its bytes, ``root`` its ElementTree root, before
    anything is removed) that no arm has."""
    try:
        lines = element_lines(raw)
        if lines is None:
            return
        parents = {c: p for p in root.iter() for c in p}
        for el, line in zip(root.iter(), lines):
            _check(el, line, parents)
    except _Refused as e:
        raise InputError(f"{path}:{e.line}: {e.what}") from None
