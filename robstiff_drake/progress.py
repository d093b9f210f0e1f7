"""Progress bars and informational lines, and the global ``--quiet``.

``progress(total, enabled, desc)`` is a tqdm bar on stderr: shown when
stderr is a terminal (``enabled=None``), forced on with ``enabled=True``
(a command's ``--progress``) or off with ``enabled=False``; ``--quiet``
(``set_quiet(True)``) turns every bar off, forced or not.  When stderr is
not a terminal (a log file, a batch job) and ``enabled=None``, a long
task says how far it is on a log line at most every LOG_EVERY_S seconds
instead of a bar (nothing for a task shorter than that).  ``info(text)``
prints an informational line (what was written where) unless quiet.
Warnings (``robstiff: warning: ...``) and errors are never silenced, and
neither is a command's result.
"""

import sys
import time

_QUIET = False
LOG_EVERY_S = 5.0  # a log line's interval (s) when stderr is not a terminal


def set_quiet(quiet):
    """Set the global ``--quiet``; returns the previous setting."""
    global _QUIET
    previous, _QUIET = _QUIET, bool(quiet)
    return previous


def quiet():
    return _QUIET


def bar_enabled(enabled=None):
    """Whether a bar shows: never when quiet; else ``enabled`` when given,
    else only when stderr is a terminal."""
    if _QUIET:
        return False
    if enabled is not None:
        return bool(enabled)
    try:
        return sys.stderr.isatty()
    except (AttributeError, ValueError):  # replaced or closed stderr
        return False


def progress(total, enabled=None, desc="", unit="it", **kwargs):
    """A tqdm progress bar on stderr over ``total`` steps (see the module
    docstring for when it shows); a no-op bar when it does not.  Use as
    ``with progress(n, enabled, "runs") as bar: ... bar.update(1)``."""
    from tqdm import tqdm

    if enabled is None and not _QUIET and not bar_enabled(None):
        return LogLines(total, desc, unit)
    kwargs.setdefault("leave", True)
    return tqdm(total=total, desc=desc or None, unit=unit, disable=not bar_enabled(enabled), file=sys.stderr,
                dynamic_ncols=True, **kwargs)


class LogLines:
    """A progress bar's surface (``update``, ``close``, a context manager,
    ``disable``) that prints ``robstiff: DESC: N/TOTAL UNIT (P %) after
    S s`` on stderr at most every ``every_s`` seconds, at an update (a
    task shorter than that prints nothing).  ``clock``: seconds (injected
    by the tests)."""

    disable = False

    def __init__(self, total, desc="", unit="it", every_s=None, clock=time.monotonic, file=None):
        self.total, self.desc, self.unit, self.n = total, desc or "working", unit, 0
        self.every_s = LOG_EVERY_S if every_s is None else float(every_s)
        self.clock, self.file = clock, file
        self.t0 = self.last = clock()

    def update(self, n=1):
        self.n += n
        now = self.clock()
        if now - self.last >= self.every_s and not _QUIET:
            self.last = now
            of = f"/{self.total:g}" if self.total else ""
            pct = f" ({100.0 * self.n / self.total:.0f} %)" if self.total else ""
            print(f"robstiff: {self.desc}: {self.n:g}{of} {self.unit}{pct} after {now - self.t0:.0f} s",
                  file=self.file or sys.stderr, flush=True)

    def close(self):
        pass

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
        return False


def simulation_bar(t_end_s, enabled=None, desc="simulating"):
    """A ``progress`` bar over simulated time, 0 to ``t_end_s`` (s)."""
    return progress(round(float(t_end_s), 3), enabled, desc, unit="s",
                    bar_format="{desc}: {percentage:3.0f}%|{bar}| {n:.1f}/{total:.1f} s simulated "
                               "[{elapsed}<{remaining}]")


def time_monitor(bar, t_end_s, steps=200):
    """A Drake Simulator monitor that moves ``bar`` (a ``simulation_bar``)
    with the simulated time, in ``steps`` increments up to ``t_end_s`` (s);
    None when the bar is disabled (no Python call per simulator step then)."""
    if bar.disable or isinstance(bar, LogLines):  # (log lines: no Python call per simulator step either)
        return None
    from pydrake.systems.framework import EventStatus

    t_end_s = float(t_end_s)
    quantum = t_end_s / steps
    state = {"shown": 0.0}

    def monitor(context):
        t = min(context.get_time(), t_end_s)
        if t - state["shown"] >= quantum or (t >= t_end_s and t > state["shown"]):
            bar.update(round(t, 3) - round(state["shown"], 3))
            state["shown"] = t
        return EventStatus.Succeeded()

    return monitor


def info(text, file=None):
    """Print an informational line (stdout unless ``file``), unless quiet."""
    if not _QUIET:
        print(text, file=file or sys.stdout)


def shown_path(path):
    """A path as a line shows it: ``run/`` and ``run//x`` as ``run`` and ``run/x``."""
    from pathlib import Path

    return str(Path(path))


def wrote(path, detail="", *, folder=False, to_stderr=False):
    """The informational line for a file (or, ``folder``, a folder: ``run/``)
    a command wrote: ``wrote PATH`` or ``wrote PATH: detail``; nothing for
    standard output (``-``) or an output not asked for (None).  ``to_stderr``
    when the command's JSON goes to standard output."""
    if path is None or str(path) == "-":
        return
    shown = shown_path(path) + ("/" if folder else "")
    info(f"wrote {shown}" + (f": {detail}" if detail else ""), file=sys.stderr if to_stderr else None)
