"""Checks of the files a command line names, before any heavy import.

A mistyped file name should be refused as fast as ``--help`` answers: this
module imports nothing beyond the standard library and ``paths`` (no numpy,
no scipy, no Drake), and runs between argument parsing and the import of the
command's module.  It checks only that the named inputs exist, in the words of
their readers (their content is the readers' business, after the import) and resolves a
scenario given by name (``robstiff simulate block_milling``) to the
packaged file, so the command itself always gets a path.

``check_inputs(args)`` raises InputError (one line, exit status 2).
"""

import os
from pathlib import Path

from robstiff_drake.errors import InputError
from robstiff_drake.paths import find_scenario, library_robots, replay_name_problem, unknown_scenario

NO_FILE = os.strerror(2)  # "No such file or directory", as the readers word it

# command -> attribute names of its positional or option inputs, by kind
DATA_FILES = {"identify": ["data"], "diagnose": ["data"], "calibrate-payload": ["data"]}
SCENARIOS = {"simulate": "scenario", "sweep": "scenario", "sim-cell": "scenario"}
# command -> [(attribute, the one line for a missing file, worded as the file's reader words it)]
OPTION_FILES = {
    "simulate": [("compensator", "{path}: no such run file"), ("toolpath", "{path}: no such G-code program")],
    "compensate": [("model", "--model {path}: cannot read (" + NO_FILE + ")"),
                   ("payload", "{path}: no such payload calibration")],
    # not compensate's --reference: compensate waits (bounded) for a reference about to appear (sim-cell's)
}


def _missing(path):
    return not os.path.lexists(path) or not os.path.exists(path)


def check_robot(spec):
    """--robot: a library robot's name or an existing robot file."""
    if spec is None or str(spec) == "":
        return
    text = str(spec)
    path = Path(text)
    path_like = path.suffix.lower() in (".yaml", ".yml") or "/" in text or "\\" in text
    if path.exists():
        return
    if path_like:
        raise InputError(f"{text}: no such robot file (a library robot is named without a folder or suffix: "
                         f"{', '.join(library_robots())})")
    if text not in library_robots():
        raise InputError(f"--robot {text}: not a library robot ({', '.join(library_robots())}) and not a YAML file")


def check_replay_name(path):
    """--replay: the replay is an HTML file: refuse another suffix (InputError)."""
    problem = replay_name_problem(path)
    if problem:
        raise InputError(problem)


def check_inputs(args):
    """Refuse a command line whose input files do not exist, or a new
    replay's name that is not HTML; replace a scenario's name by its
    packaged file (see the module docstring)."""
    command = getattr(args, "command", None)
    replay = getattr(args, "replay", None) if command == "simulate" else None
    if replay is not None and not os.path.lexists(replay):  # (an existing file: simulate checks it is no input)
        check_replay_name(replay)
    for attr in DATA_FILES.get(command, ()):
        path = getattr(args, attr, None)
        if path is not None and _missing(path):
            raise InputError(f"{path}: cannot read ({NO_FILE})")
    attr = SCENARIOS.get(command)
    if attr is not None:
        text = getattr(args, attr)
        found = find_scenario(text)
        if found is None:
            raise InputError(unknown_scenario(text))
        setattr(args, attr, str(found))
    for attr, line in OPTION_FILES.get(command, ()):
        path = getattr(args, attr, None)
        if path is not None and _missing(path):
            raise InputError(line.format(path=path))
    if command == "diagnose-run":
        for folder in [args.run_dir, *(args.verify or [])]:
            if not os.path.isdir(folder):
                raise InputError(f"{folder}: no such run folder")
    check_robot(getattr(args, "robot", None))
