"""The running command: what it reads and what it will write, so that one
rule holds for every file a command reads, whether named on the command
line or inside another file (a scenario's program, robot, identification
JSON and payload YAML; a compensator.yaml's robot; a run folder's files):
no output may be, contain, or replace an input.

``command_scope()`` is entered by ``robstiff``'s main around each command.
Every reader of a user file calls ``note_input(path, named_by)``; io's
``check_outputs`` declares the outputs.  Whichever comes second refuses the
conflict (OutputError, one line naming the option, the output and the file
that named the input); io's writes check once more before they rename.
``input_warning(message)``: a warning about an input file, found by its
reader, printed at once and carried into the command's Warnings and JSON;
``input_note(message)``: what a reader did that the user should know
(e.g. decimal commas read), printed once on stderr unless --quiet.
Outside a scope (library use) nothing is recorded and nothing printed.
"""

import os
import sys
from contextlib import contextmanager

from robstiff_drake.errors import OutputError, one_line

STDOUT = "-"


class Command:
    """What one command reads and writes."""

    def __init__(self):
        self.inputs = {}  # path as given -> what named it ("" for the command line)
        self.outputs = []  # (option, path, is_folder), declared by io.check_outputs
        self.input_warnings = []
        self.input_notes = []
        self.staged = None  # [(temporary file, target, path)] inside io.staged_outputs()


_CURRENT = None


@contextmanager
def command_scope():
    """One command's inputs, outputs and input warnings."""
    global _CURRENT
    previous, _CURRENT = _CURRENT, Command()
    try:
        yield _CURRENT
    finally:
        _CURRENT = previous


def current():
    """The running command (Command), or None outside a command_scope."""
    return _CURRENT


def same_file(a, b):
    try:
        return os.path.samefile(a, b)
    except OSError:
        return os.path.realpath(a) == os.path.realpath(b)


def inside(path, folder):
    """Whether ``path`` resolves (through every symbolic link) to ``folder``
    or somewhere inside it."""
    p, f = os.path.realpath(path), os.path.realpath(folder)
    return p == f or p.startswith(f.rstrip(os.sep) + os.sep)


def label(path, named_by):
    return f"{path}, {named_by}" if named_by else str(path)


def conflict(input_path, output, is_folder):
    """Whether writing ``output`` (a file, or a folder replaced as a whole)
    would overwrite, replace or remove ``input_path``."""
    if not os.path.lexists(input_path):
        return False
    if is_folder:
        return inside(input_path, output)
    return same_file(input_path, output) if os.path.exists(output) else \
        os.path.realpath(input_path) == os.path.realpath(output)


def note_input(path, named_by=None):
    """Record ``path`` as an input of the running command (``named_by``: the
    file and key that name it, e.g. "toolpath.program of s.yaml"), and
    refuse it (OutputError) when an output already declared would be it,
    replace it or contain it."""
    if _CURRENT is None or path is None or str(path) in ("", STDOUT):
        return
    text = os.fspath(path)
    _CURRENT.inputs.setdefault(text, named_by or "")
    for key, out, is_folder in _CURRENT.outputs:
        if conflict(text, out, is_folder):
            what = "holds" if is_folder else "is"
            raise OutputError(f"{key} {out}: {what} an input of the command ({label(text, named_by)}); choose "
                              "another output, inputs are never overwritten")


def command_inputs():
    """The inputs noted so far: [(path, what named it)]."""
    return [] if _CURRENT is None else list(_CURRENT.inputs.items())


def check_not_an_input(path, is_folder=False):
    """The last check before a write renames anything into place."""
    for src, named_by in command_inputs():
        if conflict(src, os.fspath(path), is_folder):
            raise OutputError(f"cannot write {path}: {'it holds' if is_folder else 'it is'} an input of the command "
                              f"({label(src, named_by)}); inputs are never overwritten")


def input_warning(message):
    """A warning about an input file, found while reading it: printed once,
    at once, and carried into the command's Warnings and JSON.  Returns the
    one-line message (outside a command: only that)."""
    message = one_line(" ".join(str(message).split()))
    if _CURRENT is not None and message not in _CURRENT.input_warnings:
        _CURRENT.input_warnings.append(message)
        print(f"robstiff: warning: {message}", file=sys.stderr)
    return message


def input_note(message):
    """A note on how an input file was read (not a warning: the result is
    as the user meant it): printed once, at once, on stderr unless quiet.
    Returns the one-line message (outside a command: only that)."""
    message = one_line(" ".join(str(message).split()))
    if _CURRENT is not None and message not in _CURRENT.input_notes:
        _CURRENT.input_notes.append(message)
        from robstiff_drake.progress import info

        info(f"robstiff: note: {message}", file=sys.stderr)
    return message
