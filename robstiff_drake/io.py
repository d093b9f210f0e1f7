"""The output layer shared by every command.

* ``check_outputs(...)``: refuse, before any computation, an output that is
  an input, a folder where a file is wanted (or the reverse), a special file
  (device, FIFO, socket), a read-only file, a path longer than the system
  takes, or a place that cannot be written (InputError: one line, exit
  status 2).
* One rule for every file a command reads: ``command_scope()`` (entered by
  ``robstiff``'s main for each command) collects the command's inputs, both
  those on its command line and those named inside other files (a
  scenario's program, robot, identification JSON and payload YAML; a
  compensator.yaml's robot; a run folder's files): every reader calls
  ``note_input(path, named_by)``.  No output may be, contain, or replace
  an input: ``check_outputs`` refuses such an output against the inputs
  noted so far, ``note_input`` refuses an input read later that an output
  declared earlier would overwrite or contain, and every write checks once
  more before it renames anything into place.
* ``staged_outputs()``: the files a command writes inside it appear
  together when it ends without an error (nothing half-written: a full
  disk while writing the second file leaves neither).
* ``write_atomic`` / ``save_figure_atomic`` / ``emit_json``: a temporary
  file in the target's folder and a rename, so a reader never sees a
  half-written file; through a symlink the link's target is replaced (the
  link stays); a new file gets the mode the umask gives, an existing file
  keeps its own.
* ``RunFolder``: a folder of outputs written as a whole (a temporary folder,
  renamed into place when every file is written), stamped with a run id.
* ``Warnings``: implausible results, one line each, printed to stderr as
  ``robstiff: warning: ...`` and listed under ``warnings`` in the JSON.
  ``input_warning(message)``: a warning about an input file (a robot file
  whose first mode is implausible, say) found by a reader: printed at once
  and added to every Warnings and every JSON object the command writes.
* JSON is always valid JSON: NaN and infinities become null, with a warning.
"""

import json
import math
import os
import secrets
import shutil
import stat
import sys
import tempfile
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from robstiff_drake.errors import InputError, one_line

STDOUT = "-"
RUN_ID_FILE = "RUN_ID"


class OutputError(InputError):
    """An output that cannot be written (one line, exit status 2)."""


# ---------------------------------------------------------------- the command


class _Command:
    """What one command reads and writes (see the module docstring)."""

    def __init__(self):
        self.inputs = {}  # path as given -> what named it ("" for the command line)
        self.outputs = []  # (option, path, is_folder)
        self.input_warnings = []
        self.staged = None  # [(temporary file, target)] inside staged_outputs()


_COMMAND = None


@contextmanager
def command_scope():
    """One command's inputs, outputs and input warnings (main enters it
    around each command; outside it, only the explicit checks apply)."""
    global _COMMAND
    previous, _COMMAND = _COMMAND, _Command()
    try:
        yield _COMMAND
    finally:
        _COMMAND = previous


def _label(path, named_by):
    return f"{path}, {named_by}" if named_by else str(path)


def _conflict(input_path, output, is_folder):
    """Whether writing ``output`` (a file, or a folder replaced as a whole)
    would overwrite, replace or remove ``input_path``."""
    if not os.path.lexists(input_path):
        return False
    if is_folder:
        return inside(input_path, output)
    return _same(input_path, output) if os.path.exists(output) else \
        os.path.realpath(input_path) == os.path.realpath(output)


def note_input(path, named_by=None):
    """Record ``path`` as an input of the running command (``named_by``: the
    file and key that name it, e.g. "toolpath.program of s.yaml"), and
    refuse it (OutputError) when an output already declared would be it,
    replace it or contain it."""
    if _COMMAND is None or path is None or str(path) in ("", STDOUT):
        return
    text = os.fspath(path)
    _COMMAND.inputs.setdefault(text, named_by or "")
    for key, out, is_folder in _COMMAND.outputs:
        if _conflict(text, out, is_folder):
            what = "holds" if is_folder else "is"
            raise OutputError(f"{key} {out}: {what} an input of the command ({_label(text, named_by)}); choose "
                              "another output, inputs are never overwritten")


def command_inputs():
    """The inputs noted so far: [(path, what named it)]."""
    return [] if _COMMAND is None else list(_COMMAND.inputs.items())


def _check_not_an_input(path, is_folder=False):
    """The last check before a write renames anything into place."""
    for src, named_by in command_inputs():
        if _conflict(src, os.fspath(path), is_folder):
            raise OutputError(f"cannot write {path}: {'it holds' if is_folder else 'it is'} an input of the command "
                              f"({_label(src, named_by)}); inputs are never overwritten")


# ---------------------------------------------------------------- warnings


def input_warning(message):
    """A warning about an input file, found while reading it: printed once,
    at once, and carried into the command's Warnings and JSON.  Outside a
    command (library use) it is only returned."""
    message = one_line(" ".join(str(message).split()))
    if _COMMAND is not None and message not in _COMMAND.input_warnings:
        _COMMAND.input_warnings.append(message)
        print(f"robstiff: warning: {message}", file=sys.stderr)
    return message


class Warnings(list):
    """One-line warnings about a legal input whose result is implausible.

    ``add`` prints the line to stderr at once (so a long run shows it when
    it happens) and keeps it for the JSON's ``warnings`` key.  A new
    Warnings starts with the command's input warnings (already printed)."""

    def __init__(self, *, quiet=False):
        super().__init__()
        self.quiet = quiet
        if _COMMAND is not None:
            self.extend(_COMMAND.input_warnings)

    def add(self, message):
        message = one_line(" ".join(str(message).split()))
        if message in self:
            return
        self.append(message)
        if not self.quiet:
            print(f"robstiff: warning: {message}", file=sys.stderr)

    def extend_from(self, messages):
        for m in messages or ():
            self.add(m)


# ---------------------------------------------------------------- checks


def _umask():
    mask = os.umask(0)
    os.umask(mask)
    return mask


def _same(a, b):
    try:
        return os.path.samefile(a, b)
    except OSError:
        return os.path.realpath(a) == os.path.realpath(b)


def inside(path, folder):
    """Whether ``path`` resolves (through every symbolic link) to ``folder``
    or somewhere inside it."""
    p, f = os.path.realpath(path), os.path.realpath(folder)
    return p == f or p.startswith(f.rstrip(os.sep) + os.sep)


def _existing_ancestor(path):
    """The nearest ancestor of ``path`` that exists (Path), and the part below it."""
    p = Path(os.path.abspath(path)).parent
    while not p.exists():
        if p.is_symlink():  # a dangling symlink on the way
            return p, True
        p = p.parent
    return p, False


def _check_parent(path, key):
    anc, dangling = _existing_ancestor(path)
    if dangling:
        raise OutputError(f"{key} {shown_path(path)}: {shown_path(anc)} is a broken symbolic link")
    if not anc.is_dir():
        raise OutputError(f"{key} {shown_path(path)}: {shown_path(anc)} is a file, not a folder")
    if not os.access(anc, os.W_OK | os.X_OK):
        raise OutputError(f"{key} {shown_path(path)}: cannot write in {shown_path(anc)} (permission denied)")


# The longest path and file name the system takes (Linux: 4096 and 255 bytes).
try:
    PATH_MAX = os.pathconf("/", "PC_PATH_MAX")
    NAME_MAX = os.pathconf("/", "PC_NAME_MAX")
except (AttributeError, OSError, ValueError):
    PATH_MAX, NAME_MAX = 4096, 255


def shown_path(text, limit=160):
    """A path as an error shows it: one line, and a very long one shortened
    in the middle."""
    text = one_line(text)
    return text if len(text) <= limit else f"{text[:limit // 2 - 2]}...{text[-(limit // 2 - 2):]}"


def _check_length(text, key):
    full = os.fsencode(os.path.abspath(text))
    if len(full) >= PATH_MAX:
        raise OutputError(f"{key} {shown_path(text)}: the path is {len(full)} bytes long, more than the system takes "
                          f"({PATH_MAX - 1})")
    for part in Path(text).parts:
        if len(os.fsencode(part)) > NAME_MAX:
            raise OutputError(f"{key} {shown_path(text)}: a name in it is {len(os.fsencode(part))} bytes long, more "
                              f"than a file system takes ({NAME_MAX})")


def _check_file_output(path, key, inputs):
    text = str(path)
    if text == STDOUT:
        return
    if text == "" or text.endswith(os.sep):
        raise OutputError(f"{key} {text!r}: expected a file name")
    _check_length(text, key)
    target = os.path.realpath(text)
    for src, named_by in inputs:
        if _conflict(src, text, False):
            raise OutputError(f"{key} {shown_path(text)}: this is an input of the command "
                              f"({shown_path(_label(src, named_by))}); choose another output file, inputs are never "
                              "overwritten")
    if os.path.lexists(text) and not os.path.exists(text):
        raise OutputError(f"{key} {shown_path(text)}: a symbolic link to {shown_path(os.readlink(text))}, which does "
                          "not exist")
    if os.path.exists(target):
        st = os.stat(target)
        if stat.S_ISDIR(st.st_mode):
            raise OutputError(f"{key} {shown_path(text)}: is a folder; give a file name")
        if not stat.S_ISREG(st.st_mode):
            kind = ("a device" if stat.S_ISCHR(st.st_mode) or stat.S_ISBLK(st.st_mode) else
                    "a FIFO" if stat.S_ISFIFO(st.st_mode) else "a socket" if stat.S_ISSOCK(st.st_mode)
                    else "not a regular file")
            raise OutputError(f"{key} {shown_path(text)}: is {kind}; outputs go to regular files "
                              f"(use '{STDOUT}' for standard output where the option takes it)")
        if not st.st_mode & (stat.S_IWUSR | stat.S_IWGRP | stat.S_IWOTH) or not os.access(target, os.W_OK):
            raise OutputError(f"{key} {shown_path(text)}: the file is read-only; it is not replaced")
    _check_parent(target, key)


def _is_run_folder(path):
    return (Path(path) / RUN_ID_FILE).is_file()


def _check_folder_output(path, key, inputs):
    text = str(path)
    if text in ("", STDOUT):
        raise OutputError(f"{key} {text!r}: expected a folder name")
    _check_length(text, key)
    if os.path.lexists(text) and not os.path.exists(text):
        raise OutputError(f"{key} {shown_path(text)}: a symbolic link to {shown_path(os.readlink(text))}, which does "
                          "not exist")
    real = os.path.realpath(text)
    for src, named_by in inputs:
        if _conflict(src, real, True):
            raise OutputError(f"{key} {shown_path(text)}: the folder holds an input of the command "
                              f"({shown_path(_label(src, named_by))}), and a run folder is replaced as a whole; "
                              "choose another output folder")
    if os.path.exists(real):
        if not os.path.isdir(real):
            raise OutputError(f"{key} {shown_path(text)}: is a file, not a folder")
        if any(Path(real).iterdir()) and not _is_run_folder(real):
            raise OutputError(f"{key} {shown_path(text)}: the folder exists and is not a robstiff run folder (no "
                              f"{RUN_ID_FILE} file); choose a new folder or empty it, it would be replaced as a whole")
        if os.path.ismount(real) or real == os.path.realpath(os.getcwd()):
            raise OutputError(f"{key} {shown_path(text)}: cannot replace this folder as a whole; choose a sub-folder")
    _check_parent(real, key)


def check_outputs(*, inputs=(), files=None, folders=None):
    """Refuse bad outputs before anything is computed.

    ``inputs``: paths the command reads (files or folders), besides those
    its readers note (``note_input``).  ``files`` and ``folders``: ``{option
    name: path or None}`` of the outputs (None: not asked for).  Raises
    OutputError (one line naming the option and path)."""
    for p in inputs:
        note_input(p)
    given = [(os.fspath(p), "") for p in inputs if p is not None and str(p) not in ("", STDOUT)]
    inputs = given + [i for i in command_inputs() if i[0] not in {g for g, _ in given}]
    seen = {}
    declared = []
    try:
        for key, path in (files or {}).items():
            if path is None:
                continue
            _check_file_output(os.fspath(path), key, inputs)
            if str(path) != STDOUT:
                real = os.path.realpath(path)
                if real in seen:
                    raise OutputError(f"{key} {shown_path(path)}: the same file as {seen[real]}")
                seen[real] = key
                declared.append((key, os.fspath(path), False))
        for key, path in (folders or {}).items():
            if path is None:
                continue
            _check_folder_output(os.fspath(path), key, inputs)
            declared.append((key, os.fspath(path), True))
    except OSError as e:  # a path the system refuses to look at (too long, a loop of symlinks, ...)
        raise OutputError(f"{key} {shown_path(path)}: {e.strerror or e}") from None
    if _COMMAND is not None:
        _COMMAND.outputs.extend(declared)


# ---------------------------------------------------------------- writing


def _target(path):
    """Where the bytes go: through a symlink, its target."""
    return Path(os.path.realpath(path))


def _final_mode(target):
    if target.exists():
        return stat.S_IMODE(target.stat().st_mode)
    return 0o666 & ~_umask()


def _write_error(path, e):
    return OutputError(f"cannot write {path}: {e.strerror or e}")


def _replace_atomic(path, write):
    """Write through ``write(tmp_path)`` into a temporary file next to the
    target, then rename it over the target (inside ``staged_outputs``: when
    the block ends)."""
    _check_not_an_input(path)
    target = _target(path)
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
        mode = _final_mode(target)
        fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".tmp", dir=target.parent)
    except OSError as e:
        raise _write_error(path, e) from None
    try:
        os.close(fd)
        write(tmp)
        os.chmod(tmp, mode)
        if _COMMAND is not None and _COMMAND.staged is not None:
            _COMMAND.staged.append((tmp, target, path))
        else:
            os.replace(tmp, target)
    except OSError as e:
        Path(tmp).unlink(missing_ok=True)
        raise _write_error(path, e) from None
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


@contextmanager
def staged_outputs():
    """Inside this block (of a command: main's command_scope), files written
    with write_atomic / save_figure_atomic / emit_json go to temporary files
    that are renamed into place together when the block ends without an
    error; on an error (a full disk at the second file) every temporary file
    is removed and no output appears or changes."""
    if _COMMAND is None or _COMMAND.staged is not None:
        yield
        return
    _COMMAND.staged = staged = []
    try:
        yield
        for tmp, target, path in staged:
            try:
                os.replace(tmp, target)
            except OSError as e:
                raise _write_error(path, e) from None
    finally:
        _COMMAND.staged = None
        for tmp, _, _ in staged:
            Path(tmp).unlink(missing_ok=True)


def write_atomic(path, data):
    """Write ``data`` (str or bytes) to ``path`` atomically (see module docstring)."""
    raw = data if isinstance(data, bytes) else data.encode("utf-8")

    def write(tmp):
        with open(tmp, "wb") as f:
            f.write(raw)
            f.flush()
            os.fsync(f.fileno())

    _replace_atomic(path, write)


def save_figure_atomic(fig, path, **kwargs):
    """Save a matplotlib figure as PNG atomically, and close it."""
    import matplotlib.pyplot as plt

    try:
        _replace_atomic(path, lambda tmp: fig.savefig(tmp, format="png", **kwargs))
    finally:
        plt.close(fig)


# ---------------------------------------------------------------- JSON


def _to_jsonable(obj, where, bad):
    if isinstance(obj, dict):
        return {str(k): _to_jsonable(v, f"{where}.{k}" if where else str(k), bad) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_to_jsonable(v, f"{where}[{i}]", bad) for i, v in enumerate(obj)]
    if isinstance(obj, np.ndarray):
        return _to_jsonable(obj.tolist(), where, bad)
    if isinstance(obj, (np.bool_, bool)):
        return bool(obj)
    if isinstance(obj, np.generic):
        obj = obj.item()
    if isinstance(obj, float) and not math.isfinite(obj):
        bad.append(where)
        return None
    if isinstance(obj, Path):
        return str(obj)
    return obj


def json_text(obj):
    """``obj`` as JSON text; NaN and infinities become null, and when ``obj``
    is a dict a warning in its ``warnings`` list names them.  A dict also
    gets the command's input warnings (``input_warning``) in that list."""
    bad = []
    data = _to_jsonable(obj, "", bad)
    if isinstance(data, dict) and _COMMAND is not None and _COMMAND.input_warnings:
        listed = data.setdefault("warnings", [])
        if isinstance(listed, list):
            listed[:0] = [w for w in _COMMAND.input_warnings if w not in listed]
    if bad and isinstance(data, dict):
        shown = ", ".join(bad[:5]) + (f" and {len(bad) - 5} more" if len(bad) > 5 else "")
        data.setdefault("warnings", [])
        note = f"not finite, written as null: {shown}"
        if note not in data["warnings"]:
            data["warnings"].append(note)
    return json.dumps(data, indent=2, allow_nan=False) + "\n"


def emit_json(obj, destination):
    """Write ``obj`` as JSON to ``destination``: a path, or ``-`` for stdout."""
    text = json_text(obj)
    if str(destination) == STDOUT:
        sys.stdout.write(text)
        sys.stdout.flush()
    else:
        write_atomic(destination, text)


# ---------------------------------------------------------------- run folders


def new_run_id():
    return secrets.token_hex(6)


class RunFolder:
    """A folder of outputs written as a whole::

        with RunFolder("robstiff-out") as run:
            run.write("summary.json", text)
            run.save_figure("plot.png", fig)

    Files go to a temporary folder beside the target; on success a
    ``RUN_ID`` file is added and the folder is renamed into place, replacing
    an earlier run folder (never any other folder: ``check_outputs``
    refuses those).  On an error or an interrupt the temporary folder is
    removed and the earlier run is left as it was.  ``run.run_id`` is the
    id to stamp into every file."""

    def __init__(self, path, run_id=None):
        self.path = Path(path)
        self.run_id = run_id or new_run_id()
        self.written = []
        self._tmp = None

    def __enter__(self):
        target = _target(self.path)
        try:
            target.parent.mkdir(parents=True, exist_ok=True)
            self._tmp = Path(tempfile.mkdtemp(prefix=f".{target.name}.", suffix=".tmp", dir=target.parent))
        except OSError as e:
            raise _write_error(self.path, e) from None
        return self

    def file(self, name):
        """The path of ``name`` inside the folder being written."""
        return self._tmp / name

    def write(self, name, data):
        raw = data if isinstance(data, bytes) else data.encode("utf-8")
        p = self.file(name)
        try:
            p.parent.mkdir(parents=True, exist_ok=True)
            p.write_bytes(raw)
        except OSError as e:
            raise _write_error(self.path / name, e) from None
        self.written.append(name)

    def save_figure(self, name, fig, **kwargs):
        import matplotlib.pyplot as plt

        try:
            fig.savefig(self.file(name), format="png", **kwargs)
        except OSError as e:
            raise _write_error(self.path / name, e) from None
        finally:
            plt.close(fig)
        self.written.append(name)

    def __exit__(self, exc_type, exc, tb):
        if exc_type is not None:
            shutil.rmtree(self._tmp, ignore_errors=True)
            return False
        target = _target(self.path)
        old = None
        try:
            _check_not_an_input(self.path, is_folder=True)
        except BaseException:
            shutil.rmtree(self._tmp, ignore_errors=True)
            raise
        try:
            (self._tmp / RUN_ID_FILE).write_text(self.run_id + "\n")
            dir_mode = 0o777 & ~_umask()
            file_mode = 0o666 & ~_umask()
            for p in self._tmp.rglob("*"):
                os.chmod(p, dir_mode if p.is_dir() else file_mode)
            os.chmod(self._tmp, dir_mode)
            if target.exists():
                old = Path(tempfile.mkdtemp(prefix=f".{target.name}.", suffix=".old", dir=target.parent))
                os.rmdir(old)
                os.replace(target, old)
            os.replace(self._tmp, target)
        except OSError as e:
            if old is not None and old.exists() and not target.exists():
                os.replace(old, target)
            shutil.rmtree(self._tmp, ignore_errors=True)
            raise _write_error(self.path, e) from None
        except BaseException:
            if old is not None and old.exists() and not target.exists():
                os.replace(old, target)
            shutil.rmtree(self._tmp, ignore_errors=True)
            raise
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)
        return False
