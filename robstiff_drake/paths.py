"""Where the project's data files are: found through the installed package
(importlib.resources), so they are there after ``pip install .`` or from a
wheel, from any working directory.

The repository keeps them in its top-level folders; pyproject.toml maps
those into the package:  models/ -> robstiff_drake.models (robot files),
diagrams/ -> robstiff_drake.scenarios (scenario files), data/ ->
robstiff_drake.data (published tables).
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


def library_robots():
    """Names of the robot files in the library (models/*.yaml), sorted."""
    return sorted(p.stem for p in MODELS_DIR.glob("*.yaml"))


def robot_file(name):
    """The library robot file ``name`` (no check that it exists)."""
    return MODELS_DIR / f"{name}.yaml"


def scenario_file(name):
    """The packaged scenario ``name`` (e.g. "block_milling")."""
    return DIAGRAMS_DIR / f"{name}.yaml"
