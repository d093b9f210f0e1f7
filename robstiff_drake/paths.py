"""Where the project's data files live (the repository's top-level folders)."""

from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parents[1]
MODELS_DIR = REPO_ROOT / "models"
DIAGRAMS_DIR = REPO_ROOT / "diagrams"
DEFAULT_ROBOT_YAML = MODELS_DIR / "irb6400.yaml"
IRB6400_PACKAGE_XML = MODELS_DIR / "irb6400" / "package.xml"
IRB6400_URDF = MODELS_DIR / "irb6400" / "urdf" / "irb6400.urdf"
