"""The checks of a command's outputs, before anything is computed: an
output that is, holds or replaces an input of the command (robstiff_drake/
command.py: wherever the input was named), a folder where a file is wanted
(or the reverse), a special file (device, FIFO, socket), a read-only file, a
path longer than the system takes, or a place that cannot be written.
Each is an OutputError: one line naming the option and the path, exit
status 2.  ``check_outputs`` is what the commands call (through io)."""

import os
import stat
from pathlib import Path

from robstiff_drake.command import STDOUT, command_inputs, conflict, current, label, note_input
from robstiff_drake.errors import OutputError, one_line

RUN_ID_FILE = "RUN_ID"  # what makes a folder a robstiff run folder (io.RunFolder writes it)


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


def _check_place(text, key, inputs, is_folder):
    """What a file and a folder output share: a length the system takes, no
    input it would be or hold, no dangling symbolic link."""
    _check_length(text, key)
    for src, named_by in inputs:
        if conflict(src, os.path.realpath(text) if is_folder else text, is_folder):
            what = ("the folder holds an input of the command", "and a run folder is replaced as a whole; choose "
                    "another output folder") if is_folder else ("this is an input of the command", "choose another "
                                                                "output file, inputs are never overwritten")
            raise OutputError(f"{key} {shown_path(text)}: {what[0]} ({shown_path(label(src, named_by))}), {what[1]}")
    if os.path.lexists(text) and not os.path.exists(text):
        raise OutputError(f"{key} {shown_path(text)}: a symbolic link to {shown_path(os.readlink(text))}, which does "
                          "not exist")


def _check_file_output(path, key, inputs):
    text = str(path)
    if text == STDOUT:
        return
    if text == "" or text.endswith(os.sep):
        raise OutputError(f"{key} {text!r}: expected a file name")
    _check_place(text, key, inputs, False)
    target = os.path.realpath(text)
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
    _check_place(text, key, inputs, True)
    real = os.path.realpath(text)
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
    if current() is not None:
        current().outputs.extend(declared)
