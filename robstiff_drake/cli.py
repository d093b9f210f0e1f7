"""The ``robstiff`` entry point (pyproject's console script and ``python -m
robstiff_drake``): the command's module imported inside the Ctrl-C guard.

A Ctrl-C while the interpreter is still importing numpy and the rest (the
first 0.1 s or so) used to end in a traceback, exit status 1: numpy turns a
KeyboardInterrupt in its import into an ImportError.  Here it is the same
one line and exit status as a Ctrl-C later on (commands/main.py)."""

import sys

from robstiff_drake.errors import INTERRUPTED, interrupted


def main(argv=None):
    try:
        from robstiff_drake.commands.main import main as run
    except BaseException as e:  # (an interrupted import; anything else as it was)
        if not interrupted(e):
            raise
        print("robstiff: interrupted", file=sys.stderr)
        return INTERRUPTED
    return run(argv)
