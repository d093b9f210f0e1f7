"""The output layer shared by every command.

* ``check_outputs(...)`` (robstiff_drake/output_checks.py): refuse, before
  any computation, an output that is an input, a folder where a file is
  wanted (or the reverse), a special file (device, FIFO, socket), a
  read-only file, a path longer than the system takes, or a place that
  cannot be written (InputError: one line, exit status 2).
* One rule for every file a command reads (robstiff_drake/command.py: the
  command's inputs, noted by every reader, wherever the file was named): no
  output may be, contain, or replace an input.  ``check_outputs`` refuses
  such an output against the inputs noted so far and declares the outputs
  (``command.note_input`` then refuses an input read later that one of
  them would overwrite or contain), and every write checks once more
  before it renames anything into place.
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
  A new Warnings, and every JSON object the command writes, carries the
  command's input warnings (``command.input_warning``: a robot file whose
  first mode is implausible, say, found by its reader).
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

from robstiff_drake.command import STDOUT, check_not_an_input, current
from robstiff_drake.errors import OutputError, one_line
from robstiff_drake.output_checks import RUN_ID_FILE, check_outputs  # noqa: F401 (the commands import them from io)

# ---------------------------------------------------------------- warnings


class Warnings(list):
    """One-line warnings about a legal input whose result is implausible.

    ``add`` prints the line to stderr at once (so a long run shows it when
    it happens) and keeps it for the JSON's ``warnings`` key.  A new
    Warnings starts with the command's input warnings (already printed)."""

    def __init__(self, *, quiet=False):
        super().__init__()
        self.quiet = quiet
        if current() is not None:
            self.extend(current().input_warnings)

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
    check_not_an_input(path)
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
        if current() is not None and current().staged is not None:
            current().staged.append((tmp, target, path))
        else:
            os.replace(tmp, target)
    except OSError as e:
        Path(tmp).unlink(missing_ok=True)
        raise _write_error(path, e) from None
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


@contextmanager
def _signals_held():
    """SIGINT and SIGTERM held in the block: their handlers run when it ends
    (in the main thread; elsewhere, as they come)."""
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        yield
        return
    pending = []
    old = {s: signal.signal(s, lambda signum, _frame: pending.append(signum)) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for s, h in old.items():
            signal.signal(s, h)
        for s in pending:
            signal.raise_signal(s)


@contextmanager
def staged_outputs():
    """Inside this block (of a command: main's command_scope), files written
    with write_atomic / save_figure_atomic / emit_json go to temporary files
    that are renamed into place together when the block ends without an
    error; on an error (a full disk at the second file) every temporary file
    is removed and no output appears or changes."""
    command = current()
    if command is None or command.staged is not None:
        yield
        return
    command.staged = staged = []
    try:
        yield
        with _signals_held():  # a Ctrl-C between two renames would leave some of the outputs new, some old
            for tmp, target, path in staged:
                try:
                    os.replace(tmp, target)
                except OSError as e:
                    raise _write_error(path, e) from None
    finally:
        command.staged = None
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
    gets the command's input warnings (``input_warning``) in that list, and
    its input notes (``input_note``: decimal commas read, a scenario's
    assumed spindle rating), printed on stderr, in its ``notes`` list."""
    bad = []
    data = _to_jsonable(obj, "", bad)
    if isinstance(data, dict) and current() is not None and current().input_warnings:
        listed = data.setdefault("warnings", [])
        if isinstance(listed, list):
            listed[:0] = [w for w in current().input_warnings if w not in listed]
    if isinstance(data, dict) and current() is not None and current().input_notes:
        listed = data.setdefault("notes", [])
        if isinstance(listed, list):
            listed[:0] = [n for n in current().input_notes if n not in listed]
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


def _run_id_of(folder):
    """The run id in an earlier run folder's RUN_ID file, or "" when it has none."""
    try:
        return (Path(folder) / RUN_ID_FILE).read_text().strip()[:64]
    except (OSError, UnicodeDecodeError):
        return ""


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
        self.replaced_run_id = None  # the RUN_ID of the earlier run folder this one replaced ("" unknown)

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
            check_not_an_input(self.path, is_folder=True)
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
                self.replaced_run_id = _run_id_of(target)
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
            # said, so that a second run into the same --out does not lose the first unnoticed (cli.md: an
            # earlier run folder is replaced); on stderr, beside the progress lines (stdout may be --json -)
            from robstiff_drake.progress import info

            earlier = f"the earlier run {self.replaced_run_id}" if self.replaced_run_id else "the earlier run"
            info(f"robstiff: note: {target}/ replaced {earlier} there (another --out keeps both)", file=sys.stderr)
        return False
