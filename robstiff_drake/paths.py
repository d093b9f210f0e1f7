"""Where the project's data files are: found through the installed package
(importlib.resources), so they are there after ``pip install .`` or from a
wheel, from any working directory.

The repository keeps them in its top-level folders; pyproject.toml maps
those into the package:  models/ -> robstiff_drake.models (robot files),
diagrams/ -> robstiff_drake.scenarios (scenario files), data/ ->
robstiff_drake.data (published tables), examples/ ->
robstiff_drake.examples (example measurement campaigns), docs/ ->
robstiff_drake.docs (the documentation's pages).

Light on purpose (no numpy, no Drake): the command line resolves a
scenario's name here before any heavy import.
"""

import os
from importlib import resources
from pathlib import Path

DEFAULT_ROBOT_NAME = "irb6400"


def _package_dir(package):
    """A data package's folder on disk (installed as plain files, not zipped)."""
    return Path(os.fspath(resources.files(package)))


MODELS_DIR = _package_dir("robstiff_drake.models")
DIAGRAMS_DIR = _package_dir("robstiff_drake.scenarios")
DATA_DIR = _package_dir("robstiff_drake.data")
DEFAULT_ROBOT_YAML = MODELS_DIR / f"{DEFAULT_ROBOT_NAME}.yaml"
# The repository's top folder (studies/ write their figures to docs/ there);
# only meaningful in a source checkout.
REPO_ROOT = Path(__file__).resolve().parents[1]


def examples_dir():
    """The example campaigns' folder (examples/ in the repository).  A
    function, not a constant: an editable install made before the folder
    existed does not map it, and only `robstiff examples` needs it."""
    try:
        return _package_dir("robstiff_drake.examples")
    except ModuleNotFoundError:
        from robstiff_drake.errors import InputError

        raise InputError("the example campaigns are not installed with this package (an editable install older than "
                         "examples/): reinstall it, pip install -e . in the clone") from None


def docs_dir():
    """The documentation's folder (docs/ in the repository), as examples_dir."""
    try:
        return _package_dir("robstiff_drake.docs")
    except ModuleNotFoundError:
        from robstiff_drake.errors import InputError

        raise InputError("the documentation is not installed with this package (an editable install older than "
                         "its docs package): reinstall it, pip install -e . in the clone") from None


def library_robots():
    """Names of the robot files in the library (models/*.yaml), sorted."""
    return sorted(p.stem for p in MODELS_DIR.glob("*.yaml"))


def robot_file(name):
    """The library robot file ``name`` (no check that it exists)."""
    return MODELS_DIR / f"{name}.yaml"


def scenario_file(name):
    """The packaged scenario ``name`` (e.g. "block_milling")."""
    return DIAGRAMS_DIR / f"{name}.yaml"


def packaged_scenarios():
    """Names of the packaged scenarios (diagrams/*.yaml), sorted."""
    return sorted(p.stem for p in DIAGRAMS_DIR.glob("*.yaml"))


def find_scenario(text):
    """The scenario file a command line names: ``text`` itself when that
    file exists (a path always wins), else the packaged scenario of that name
    (``block_milling`` or ``block_milling.yaml``).  None when it is neither
    (``unknown_scenario`` says so)."""
    text = str(text)
    path = Path(text)
    if path.exists():
        return path
    if path.name == text:  # no folder in it: a packaged scenario's name?
        name = path.stem if path.suffix.lower() in (".yaml", ".yml") else text
        if name in packaged_scenarios():
            return scenario_file(name)
    return None


def unknown_scenario(text):
    """The one line for a scenario that is neither a file nor a packaged name."""
    return (f"{text}: no such scenario file, and no packaged scenario of that name (packaged: "
            f"{', '.join(packaged_scenarios())}; `robstiff examples --copy DIR` copies them to edit)")


def replay_name_problem(path):
    """What is wrong with ``path`` as the name of a 3D replay (an HTML
    file), or None."""
    if not str(path).lower().endswith((".html", ".htm")):
        return f"--replay {path}: the replay is an HTML file; give a name ending in .html"
    return None
