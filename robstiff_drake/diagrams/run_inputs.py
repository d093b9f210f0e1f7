"""The inputs a simulated run was made with, kept in its run folder.

A run folder must be read later, elsewhere, by someone who does not have
the files it was made from (``robstiff diagnose-run RUN``, a colleague, a
rerun of ``RUN/sim_scenario.yaml``).  So ``robstiff simulate`` copies into
``RUN/inputs/`` every file the run names: the robot file (a library
robot's too: the library may change), the identified model
(``model.identified_json``), the payload calibration
(``model.payload_yaml``) and the G-code program (``toolpath.program``).
The run's own files then name the copies, relative to themselves:
``compensator.yaml``'s ``robot:`` (a library robot keeps its name; a robot
file becomes ``inputs/NAME.yaml``) and ``sim_scenario.yaml``'s references.  ``robstiff compensate --log RUN``
keeps the same way the robot file, the model JSON, the payload
calibration and the joint reference it ran with.
"""

import copy
from dataclasses import dataclass
from pathlib import Path

INPUTS_DIR = "inputs"


@dataclass
class KeptInputs:
    """{key: path in the run folder} and {key: source file}; ``robot``: how
    the run's files name the robot (a library name, or the kept copy)."""

    names: dict
    sources: dict
    robot: str


def _library_name(robot):
    """The library name of a robot loaded from the library's folder, else None."""
    from robstiff_drake.paths import MODELS_DIR, library_robots

    source = Path(robot.source).resolve()
    if source.parent == MODELS_DIR.resolve() and source.stem in library_robots():
        return source.stem
    return None


def kept_inputs(sc, robot):
    """What a run of scenario ``sc`` on ``robot`` (the RobotModel that ran,
    --robot's or the scenario's) keeps, and under which names."""
    from robstiff_drake.diagrams.scenario import resolve

    wanted = {}
    for key in ("identified_json", "payload_yaml"):
        if getattr(sc.model, key):
            wanted[key] = resolve(sc, getattr(sc.model, key))
    if sc.toolpath.program:
        wanted["program"] = resolve(sc, sc.toolpath.program)
    return kept_files(robot, wanted)


def kept_files(robot, files):
    """What a run on ``robot`` keeps of its robot file and of ``files``
    ({key: path}; None values left out), and under which names (a run of
    ``robstiff compensate --log`` keeps its model, payload and reference)."""
    wanted = {"robot": Path(robot.source)}
    wanted.update({k: Path(p) for k, p in files.items() if p is not None})
    names, taken = {}, set()
    for key, path in wanted.items():
        name = path.name
        if name in taken:  # two inputs of one name (a robot.yaml and a payload robot.yaml)
            name = f"{key}_{name}"
        taken.add(name)
        names[key] = f"{INPUTS_DIR}/{name}"
    library = _library_name(robot)
    return KeptInputs(names, {k: Path(p) for k, p in wanted.items()}, library or names["robot"])


def write_kept(run, kept):
    """Copy the kept inputs into ``run`` (an io.RunFolder); returns the names written."""
    for key, rel in kept.names.items():
        run.write(rel, kept.sources[key].read_bytes())
    return list(kept.names.values())


def scenario_as_kept(sc, kept):
    """A copy of ``sc`` whose file references name the kept copies (for
    ``sim_scenario.yaml``, at the run folder's top)."""
    sc = copy.deepcopy(sc)
    sc.robot = kept.robot
    for key in ("identified_json", "payload_yaml"):
        if getattr(sc.model, key):
            setattr(sc.model, key, kept.names[key])
    if sc.toolpath.program:
        sc.toolpath.program = kept.names["program"]
    return sc
