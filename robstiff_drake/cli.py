"""The ``robstiff`` entry point (pyproject's console script and ``python -m
robstiff_drake``): the command's module imported inside the Ctrl-C guard.

A Ctrl-C while the interpreter is still importing numpy and the rest (the
first 0.1 s or so) used to end in a traceback, exit status 1: numpy turns a
KeyboardInterrupt in its import into an ImportError.  Here it is the same
one line and exit status as a Ctrl-C later on (commands/main.py).

A Ctrl-C while Drake's native library starts (pydrake.common, 60-200 ms, at
whatever point the command first imports Drake) made Drake print its own
critical log and a stack of import frames before that line (a loaded
machine, tests/test_reliability.py): the signal is now held back during that
one import (``_DrakeStartQuietly``) and delivered as soon as it is done, to
the handler there was (a KeyboardInterrupt by default)."""

import importlib.abc
import importlib.util
import signal
import sys
import threading

from robstiff_drake.errors import INTERRUPTED, interrupted

_DRAKE_NATIVE = "pydrake.common"


class _DrakeStartQuietly(importlib.abc.MetaPathFinder):
    """A finder that loads pydrake.common (the module that starts Drake's
    native library) with SIGINT held back (on the main thread, the only one
    that may set a signal's handler); every other import as it was."""

    def find_spec(self, fullname, path, target=None):
        if fullname != _DRAKE_NATIVE or threading.current_thread() is not threading.main_thread():
            return None
        sys.meta_path.remove(self)  # (once: the real finders find it)
        spec = importlib.util.find_spec(fullname)
        if spec is None or spec.loader is None:
            return spec
        spec.loader = _Blocked(spec.loader)
        return spec


class _Blocked(importlib.abc.Loader):
    def __init__(self, loader):
        self.loader = loader

    def create_module(self, spec):
        with _sigint_held():
            return self.loader.create_module(spec)

    def exec_module(self, module):
        with _sigint_held():
            self.loader.exec_module(module)


class _sigint_held:
    """SIGINT noted, not acted on, inside the block (a handler that only
    notes it: the signal reaches whichever thread the kernel picks, so a
    mask on this one would not hold it), then raised again to the handler
    there was before."""

    def __enter__(self):
        self.came = False
        self.old = signal.signal(signal.SIGINT, self._note)

    def _note(self, signum, frame):
        self.came = True

    def __exit__(self, *exc):
        signal.signal(signal.SIGINT, self.old)
        if self.came:
            signal.raise_signal(signal.SIGINT)  # (a Ctrl-C held back is delivered here)
        return False


def _hold_ctrl_c_while_drake_starts():
    if hasattr(signal, "raise_signal") and _DRAKE_NATIVE not in sys.modules \
            and not any(isinstance(f, _DrakeStartQuietly) for f in sys.meta_path):
        sys.meta_path.insert(0, _DrakeStartQuietly())


def main(argv=None):
    _hold_ctrl_c_while_drake_starts()
    try:
        from robstiff_drake.commands.main import main as run
    except BaseException as e:  # (an interrupted import; anything else as it was)
        if not interrupted(e):
            raise
        print("robstiff: interrupted", file=sys.stderr)
        return INTERRUPTED
    return run(argv)
