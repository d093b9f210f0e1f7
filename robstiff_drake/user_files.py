"""The one reader of the YAML and JSON files a user gives (scenarios, robot
files, payload calibrations, compensator.yaml, identification JSON): every
such file is bounded before it is walked, and every error about it is one
short line.

* ``read_user_text(path, what)``: the text of a regular file of at most
  MAX_USER_FILE_BYTES, UTF-8 (a byte-order mark is dropped); a folder, a
  FIFO or a device is refused before it is opened (a FIFO would block),
  and the file is noted as an input of the running command
  (``io.note_input``: no output may overwrite it).
* ``load_yaml(text, source)``: YAML through ``UserYamlLoader``: anchors and
  aliases (``&a``, ``*a``, ``<<: *a``) are refused outright (no project file
  needs them; a few KB of nested aliases expand to gigabytes, and PyYAML
  builds the expanded tree before anything can check it), nesting deeper
  than MAX_DEPTH is refused before Python's recursion limit is reached, and
  a duplicated key is refused (PyYAML keeps the last one silently).
  Returns the document and the line of every key.
* ``load_json(text, source)``: JSON nested at most MAX_DEPTH levels (checked
  on the text before the parser recurses); a duplicated key in an object is
  refused, naming it and its line (json keeps the last one silently).

Values quoted in an error go through ``errors.excerpt`` (short, escaped).
"""

import copy
import json
import os
import re
import stat
import threading
from pathlib import Path

import numpy as np
import yaml

from robstiff_drake.errors import InputError, excerpt
from robstiff_drake.command import note_input

# The largest YAML or JSON file a user gives: a scenario with 100,000
# waypoints is about 4 MB; 32 MB leaves room and stays far below what a
# walk of the parsed tree could make of memory.
MAX_USER_FILE_BYTES = 32 * 1024 * 1024
# No project file nests deeper than 6 levels; 64 is far beyond any
# hand-written file and far below Python's recursion limit.
MAX_DEPTH = 64


class UserFileError(InputError):
    """A user file that cannot be read as what it should be (one line)."""


def check_regular_file(path, what="file"):
    """Refuse (UserFileError) a path that is missing, a folder, or not a
    regular file, before anything opens it."""
    path = Path(path)
    try:
        st = os.stat(path)
    except FileNotFoundError:
        raise UserFileError(f"{path}: no such {what}") from None
    except OSError as e:
        raise UserFileError(f"{path}: cannot read ({e.strerror})") from None
    if stat.S_ISDIR(st.st_mode):
        raise UserFileError(f"{path}: is a folder, not a {what}")
    if not stat.S_ISREG(st.st_mode):
        raise UserFileError(f"{path}: not a regular file (a device, FIFO or socket), not a {what}")
    return st


def read_user_text(path, what="file", *, named_by=None, max_bytes=MAX_USER_FILE_BYTES):
    """The text of a user file (see the module docstring).  ``named_by``:
    the file and key that name it, for the output check."""
    path = Path(path)
    note_input(path, named_by)
    st = check_regular_file(path, what)
    if max_bytes is not None and st.st_size > max_bytes:
        raise UserFileError(f"{path}: {st.st_size / 1e6:.1f} MB is more than a {what} can be "
                            f"({max_bytes / 1e6:.0f} MB)")
    try:
        raw = path.read_bytes()
    except OSError as e:
        raise UserFileError(f"{path}: cannot read ({e.strerror})") from None
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError as e:
        raise UserFileError(f"{path}: not UTF-8 text (byte {e.start}); save the {what} as UTF-8") from None


# ---------------------------------------------------------------- YAML


class UserYamlLoader(yaml.SafeLoader):
    """PyYAML's SafeLoader for user files: no anchors or aliases, nesting at
    most MAX_DEPTH, no duplicated key, and the line of every key kept in
    ``key_lines`` as (id of the mapping, key, line)."""

    def __init__(self, stream, source):
        super().__init__(stream)
        self.source = str(source)
        self.key_lines = []
        self._depth = 0

    def _fail(self, mark, what):
        where = f"{self.source}:{mark.line + 1}: column {mark.column + 1}" if mark else self.source
        raise UserFileError(f"{where}: {what}")

    def compose_node(self, parent, index):
        event = self.peek_event()
        if isinstance(event, yaml.AliasEvent) or getattr(event, "anchor", None) is not None:
            self._fail(event.start_mark, "YAML anchors and aliases (&name, *name, <<) are not read in robstiff "
                                         "files; write the values out")
        self._depth += 1
        try:
            if self._depth > MAX_DEPTH:
                self._fail(event.start_mark, f"nested more than {MAX_DEPTH} levels deep")
            return super().compose_node(parent, index)
        finally:
            self._depth -= 1


def _construct_mapping(loader, node, deep=False):
    out = {}
    seen = {}
    for key_node, value_node in node.value:
        key = loader.construct_object(key_node, deep=deep)
        line = key_node.start_mark.line + 1
        if not isinstance(key, str):
            raise UserFileError(f"{loader.source}:{line}: key {excerpt(key)} is not a name")
        if key in seen:
            raise UserFileError(f"{loader.source}:{line}: duplicated key '{excerpt(key)[1:-1]}' (first on line "
                                f"{seen[key]}); a second value would silently replace the first")
        seen[key] = line
        out[key] = loader.construct_object(value_node, deep=True)
        loader.key_lines.append((id(out), key, line))
    return out


UserYamlLoader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _construct_mapping)


_PARSED = {}  # text -> (document, lines) of the last texts read (PyYAML's pure-Python reader: ~10 ms a robot file)
_PARSED_MAX = 32
_PARSED_MAX_CHARS = 200_000  # (a larger text is parsed each time, not kept)
_PARSED_LOCK = threading.Lock()


def load_yaml(text, source):
    """(document, {key path tuple: line}) of a user's YAML text (see the
    module docstring); UserFileError naming ``source``, line and column.
    A text read before in this process is not parsed again: a copy of its
    document (a robot file is read several times by one command, and about
    2,500 times by the test suite, 10 ms each)."""
    with _PARSED_LOCK:  # (a sweep's Dask workers may be threads of one process)
        hit = _PARSED.get(text)
    if hit is None:
        hit = _parse_yaml(text, source)
        if len(text) > _PARSED_MAX_CHARS:
            return hit
        with _PARSED_LOCK:
            while len(_PARSED) >= _PARSED_MAX:
                _PARSED.pop(next(iter(_PARSED)))  # (the oldest)
            _PARSED[text] = hit
    return copy.deepcopy(hit[0]), dict(hit[1])


def _parse_yaml(text, source):
    try:
        loader = UserYamlLoader(text, source)  # PyYAML checks the characters here
    except yaml.reader.ReaderError as e:  # a raw control character (ESC, NUL, ...) anywhere in the file
        pos = e.position
        line, col = text.count("\n", 0, pos) + 1, pos - (text.rfind("\n", 0, pos) + 1) + 1
        raise UserFileError(f"{source}:{line}: column {col}: character U+{e.character:04X}, a control character "
                            "a YAML file cannot hold; remove it") from None
    try:
        doc = loader.get_single_data()
    except yaml.YAMLError as e:
        mark = getattr(e, "problem_mark", None)
        where = f":{mark.line + 1}: column {mark.column + 1}:" if mark else ":"
        problem = getattr(e, "problem", None) or str(e).splitlines()[0]
        raise UserFileError(f"{source}{where} invalid YAML ({excerpt(problem, 120)[1:-1]})") from None
    except RecursionError:  # not reached within MAX_DEPTH; a last guard
        raise UserFileError(f"{source}: nested too deep to read") from None
    finally:
        loader.dispose()
    lines = {}
    parents = {}
    stack = [(doc, ())]
    while stack:  # the key paths of every mapping, without recursion
        obj, prefix = stack.pop()
        if isinstance(obj, dict):
            parents[id(obj)] = prefix
            stack.extend((v, prefix + (k,)) for k, v in obj.items())
        elif isinstance(obj, list):
            stack.extend((v, prefix + (i,)) for i, v in enumerate(obj))
    for obj_id, key, line in loader.key_lines:
        if obj_id in parents:
            lines[parents[obj_id] + (key,)] = line
    return doc, lines


# ---------------------------------------------------------------- JSON

_JSON_STRING = re.compile(r'"(?:[^"\\]|\\.)*"', re.DOTALL)
_BRACKET_STEP = np.zeros(256, dtype=np.int8)
_BRACKET_STEP[[ord("["), ord("{")]] = 1
_BRACKET_STEP[[ord("]"), ord("}")]] = -1


def json_depth(text):
    """The deepest nesting of brackets in a JSON text (outside strings)."""
    bare = _JSON_STRING.sub('""', text).encode("utf-8", errors="replace")
    b = np.frombuffer(bare, dtype=np.uint8)
    step = _BRACKET_STEP[b]
    step = step[step != 0]
    return int(np.cumsum(step, dtype=np.int64).max()) if step.size else 0


class _DuplicatedKey(Exception):
    def __init__(self, key):
        self.key = key


def _no_duplicates(pairs):
    """json's object_pairs_hook: the object as a dict, _DuplicatedKey when a key comes twice (json.loads keeps the
    last one silently: a model file's joint_stiffness_Nm_per_rad given twice would be read as its second)."""
    d = dict(pairs)
    if len(d) != len(pairs):
        seen = set()
        for k, _ in pairs:
            if k in seen:
                raise _DuplicatedKey(k)
            seen.add(k)
    return d


_JSON_STRING_OR_BRACKET = re.compile(r'"(?:[^"\\]|\\.)*"(\s*:)?|[{}\[\]]')


def _duplicate_line(text, key):
    """The line of ``key``'s second occurrence in one object of the JSON ``text`` (None if not found)."""
    stack = []  # per open bracket: the keys of an object, None for an array
    for m in _JSON_STRING_OR_BRACKET.finditer(text):
        tok = m.group()
        if tok == "{" or tok == "[":
            stack.append(set() if tok == "{" else None)
        elif tok == "}" or tok == "]":
            if stack:
                stack.pop()
        elif m.group(1) and stack and stack[-1] is not None:  # (a string followed by ':': a key)
            try:
                k = json.loads(tok[:tok.rindex('"') + 1])
            except ValueError:
                continue
            if k == key and k in stack[-1]:
                return text.count("\n", 0, m.start()) + 1
            stack[-1].add(k)
    return None


def load_json(text, source):
    """A user's JSON document, nested at most MAX_DEPTH levels;
    UserFileError naming ``source``."""
    depth = json_depth(text)
    if depth > MAX_DEPTH:
        raise UserFileError(f"{source}: nested {depth} levels deep (at most {MAX_DEPTH})")
    try:
        return json.loads(text, object_pairs_hook=_no_duplicates)
    except _DuplicatedKey as e:
        line = _duplicate_line(text, e.key)
        raise UserFileError(f"{source}: duplicated key '{excerpt(e.key)[1:-1]}' in one object"
                            + (f" (line {line})" if line else "") + "; a second value would silently replace the first") from None
    except ValueError as e:
        raise UserFileError(f"{source}: not a JSON file (line {getattr(e, 'lineno', '?')}, column "
                            f"{getattr(e, 'colno', '?')}: {excerpt(getattr(e, 'msg', str(e)), 80)[1:-1]})") from None
    except RecursionError:
        raise UserFileError(f"{source}: nested too deep to read") from None
