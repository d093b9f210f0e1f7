"""A schema for YAML files read into dataclasses: each field carries its
allowed range and unit (``num``, ``vec``, ``rows``, ``choice``, ``text``),
and ``validate`` checks a file against it before Drake's ``yaml_load_typed``
builds the objects, so that every error names the file, line, key and
allowed range in one line.

It catches what a typed loader alone lets through or reports without a
key: unknown and duplicated keys (PyYAML keeps the last of a duplicated
section silently), values of the wrong type ("four" for a period), NaN and
infinities, values outside their physical range, lists of the wrong length.
The file is parsed by user_files.load_yaml (no anchors or aliases, bounded
nesting); a value quoted in an error is a short, escaped excerpt.
"""

import math
import re
import typing
from dataclasses import field, fields, is_dataclass

from robstiff_drake.errors import InputError, excerpt
from robstiff_drake.user_files import load_yaml

# A number as YAML 1.2 (and Drake's loader) reads it: PyYAML's YAML 1.1
# takes "1e9" (no dot) for text, so plain ASCII numbers in text are numbers.
_NUMBER = re.compile(r"[+-]?(\d+(\.\d*)?|\.\d+)([eE][+-]?\d+)?", re.ASCII)
_INTEGER = re.compile(r"[+-]?\d+", re.ASCII)


class SchemaError(InputError):
    """A value in a YAML file that does not fit its schema."""


def _meta(kind, **kw):
    return {"schema": dict(kind=kind, **kw)}


def num(default, lo, hi, unit, *, integer=False, lo_open=False, hi_open=False, why=""):
    """A number in [lo, hi] (or open at either end), in ``unit``."""
    return field(default=default, metadata=_meta("num", lo=lo, hi=hi, unit=unit, integer=integer,
                                                 lo_open=lo_open, hi_open=hi_open, why=why))


def vec(default, lengths, lo, hi, unit, *, why=""):
    """A list of numbers in [lo, hi] whose length is one of ``lengths``
    (e.g. (0, 6): empty, or six)."""
    return field(default_factory=lambda: list(default),
                 metadata=_meta("vec", lengths=tuple(lengths), lo=lo, hi=hi, unit=unit, why=why))


def rows(width, lo, hi, unit, *, min_rows=0, max_rows=10000, names="", why=""):
    """A list of rows of ``width`` numbers each (boxes, waypoints)."""
    return field(default_factory=list, metadata=_meta("rows", width=width, lo=lo, hi=hi, unit=unit,
                                                      min_rows=min_rows, max_rows=max_rows, names=names, why=why))


def drake_config(factory, ranges=None, choices=None):
    """A field holding one of Drake's own config structs (MultibodyPlantConfig,
    SimulatorConfig): its keys are checked against the struct's fields, its
    values against their types, and ``ranges`` ({field: (lo, hi, unit)}, or
    (lo, hi, unit, marker): the marker value allowed too) and
    ``choices`` ({field: options}) where given."""
    return field(default_factory=factory, metadata=_meta("drake", ranges=ranges or {}, choices=choices or {}))


def choice(default, options):
    return field(default=default, metadata=_meta("choice", options=tuple(options)))


def text(default="", *, max_length=10000, one_line=False):
    """Text of at most ``max_length`` characters; without control characters
    other than tab and line ends (``one_line``: none at all, the text is
    printed in titles and report lines, where an escape sequence would act
    on the user's terminal)."""
    return field(default=default, metadata=_meta("text", max_length=max_length, one_line=one_line))


# ---------------------------------------------------------------- parsing


def load_yaml_with_lines(path, text_):
    """(document, {key path tuple: line}) of a YAML text: user_files.load_yaml
    (no anchors or aliases, bounded nesting, duplicated keys refused)."""
    return load_yaml(text_, path)


# ---------------------------------------------------------------- checking


def dotted(path):
    out = ""
    for p in path:
        out += f"[{p}]" if isinstance(p, int) else (f".{p}" if out else str(p))
    return out


class _Checker:
    def __init__(self, source, lines):
        self.source = source
        self.lines = lines

    def line_of(self, path):
        path = tuple(path)
        while path:
            if path in self.lines:
                return self.lines[path]
            path = path[:-1]
        return None

    def fail(self, path, what):
        line = self.line_of(path)
        where = f"{self.source}:{line}" if line else str(self.source)
        raise SchemaError(f"{where}: {excerpt(dotted(path), 120)[1:-1]}: {what}")

    @staticmethod
    def _range_text(m):
        lo = "(" if m["lo_open"] else "["
        hi = ")" if m["hi_open"] else "]"
        return f"{lo}{m['lo']:g}, {m['hi']:g}{hi} {m['unit']}".rstrip()

    def number(self, path, value, m, what="a number"):
        if isinstance(value, str) and _NUMBER.fullmatch(value.strip()):
            value = int(value) if _INTEGER.fullmatch(value.strip()) else float(value)
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            self.fail(path, f"expected {what} in {m['unit'] or 'no unit'}, got {excerpt(value)}")
        if isinstance(value, float) and not math.isfinite(value):
            self.fail(path, f"{value} is not a finite number (allowed: {self._range_text(m)})")
        if m.get("integer") and not isinstance(value, int):
            self.fail(path, f"expected a whole number, got {excerpt(value)}")
        lo, hi = m["lo"], m["hi"]
        below = value <= lo if m.get("lo_open") else value < lo
        above = value >= hi if m.get("hi_open") else value > hi
        if below or above:
            why = f" ({m['why']})" if m.get("why") else ""
            self.fail(path, f"{value:g} is outside the allowed range {self._range_text(m)}{why}")

    def check(self, schema_cls, doc, path=()):
        if doc is None:
            if path:  # "plant:" with nothing under it (Drake's loader takes no null section)
                self.fail(path, "an empty section: give its keys or remove the line")
            return
        if not isinstance(doc, dict):
            self.fail(path, f"expected a section of keys, got {type(doc).__name__} {excerpt(doc)}")
        hints = typing.get_type_hints(schema_cls)
        by_name = {f.name: f for f in fields(schema_cls) if not f.name.startswith("_")}
        for key, value in doc.items():
            p = path + (key,)
            if key not in by_name or by_name[key].metadata.get("internal"):
                allowed = ", ".join(k for k, f in by_name.items() if not f.metadata.get("internal"))
                self.fail(p, f"unknown key (allowed here: {allowed})")
            f = by_name[key]
            t = hints[key]
            m = f.metadata.get("schema")
            if m is not None and m["kind"] == "drake":
                self._drake(p, value, m, t)
                continue
            if is_dataclass(t):
                self.check(t, value, p)
                continue
            m = f.metadata.get("schema")
            if m is None:
                raise AssertionError(f"schema: field {dotted(p)} has no range")  # a programming error
            getattr(self, "_" + m["kind"])(p, value, m)

    def _drake(self, p, value, m, struct):
        if value is None:
            self.fail(p, "an empty section: give its keys or remove the line")
        if not isinstance(value, dict):
            self.fail(p, f"expected a section of {struct.__name__} keys, got {excerpt(value)}")
        types = {f.name: f.type for f in struct.__fields__}
        for key, v in value.items():
            q = p + (key,)
            if key not in types:
                self.fail(q, f"unknown key of Drake's {struct.__name__} (allowed: {', '.join(types)})")
            self._drake_value(q, key, v, types[key], m)

    def _drake_value(self, q, key, v, kind, m):
        if key in m["ranges"]:
            lo, hi, unit, *marker = m["ranges"][key]
            if marker and isinstance(v, (int, float)) and not isinstance(v, bool) and v == marker[0]:
                return
            self.number(q, v, dict(lo=lo, hi=hi, unit=unit, integer=False, lo_open=False, hi_open=False,
                                   why=f"or {marker[0]:g}: not given" if marker else ""))
        elif key in m["choices"]:
            self._choice(q, v, {"options": m["choices"][key]})
        elif kind is bool and not isinstance(v, bool):
            self.fail(q, f"expected true or false, got {excerpt(v)}")
        elif kind is float:
            self.number(q, v, dict(lo=-math.inf, hi=math.inf, unit="", integer=False, lo_open=False, hi_open=False))
        elif kind is str and not isinstance(v, str):
            self.fail(q, f"expected text, got {excerpt(v)}")

    def _num(self, p, value, m):
        self.number(p, value, m, "a whole number" if m["integer"] else "a number")

    def _vec(self, p, value, m):
        if not isinstance(value, list):
            self.fail(p, f"expected a list of numbers in {m['unit']}, got {excerpt(value)}")
        if len(value) not in m["lengths"]:
            n = " or ".join(str(n) for n in m["lengths"])
            self.fail(p, f"expected {n} numbers, got {len(value)}")
        for i, v in enumerate(value):
            self.number(p + (i,), v, dict(m, integer=False, lo_open=False, hi_open=False))

    def _rows(self, p, value, m):
        if not isinstance(value, list):
            self.fail(p, f"expected a list of rows [{m['names']}], got {excerpt(value)}")
        if not m["min_rows"] <= len(value) <= m["max_rows"]:
            self.fail(p, f"expected {m['min_rows']} to {m['max_rows']} rows, got {len(value)}")
        for i, row in enumerate(value):
            if not isinstance(row, list) or len(row) != m["width"]:
                self.fail(p + (i,), f"expected [{m['names']}] ({m['width']} numbers), got {excerpt(row)}")
            for j, v in enumerate(row):
                self.number(p + (i, j), v, dict(m, integer=False, lo_open=False, hi_open=False))

    def _choice(self, p, value, m):
        if value not in m["options"]:
            self.fail(p, f"expected one of {', '.join(repr(o) for o in m['options'])}, got {excerpt(value)}")

    def _text(self, p, value, m):
        if not isinstance(value, str):
            self.fail(p, f"expected text, got {excerpt(value)}")
        if len(value) > m["max_length"]:
            self.fail(p, f"text longer than {m['max_length']} characters")
        allowed = "" if m.get("one_line") else "\t\n\r"
        for i, ch in enumerate(value):
            if not ch.isprintable() and ch not in allowed:
                self.fail(p, f"character {i + 1} is U+{ord(ch):04X}, a control or invisible character "
                             f"({'one line of printable text expected' if m.get('one_line') else 'not text'})")


def validate(schema_cls, path, text_):
    """Check the YAML ``text_`` of file ``path`` against ``schema_cls``.
    Returns {key path tuple: line} for later messages.  Raises SchemaError."""
    doc, lines = load_yaml_with_lines(path, text_)
    _Checker(path, lines).check(schema_cls, doc)
    return lines


def check_object(schema_cls, obj, source, lines=None, path=()):
    """Check a constructed dataclass (e.g. after a command-line override)
    against the same ranges."""
    checker = _Checker(source, lines or {})
    for f in fields(schema_cls):
        if f.name.startswith("_") or f.metadata.get("internal"):
            continue
        value = getattr(obj, f.name)
        p = path + (f.name,)
        m = f.metadata.get("schema")
        if m is not None and m["kind"] == "drake":
            for key in list(m["ranges"]) + list(m["choices"]):
                checker._drake_value(p + (key,), key, getattr(value, key), None, m)
            continue
        if is_dataclass(value):
            check_object(type(value), value, source, lines, p)
            continue
        if m is not None:
            getattr(checker, "_" + m["kind"])(p, value, m)
