"""The package as a user gets it: a wheel built from a copy of the sources,
installed (not editable) into a fresh virtual environment, run from an
empty folder: the robot library and the scenarios must come from the
installed package, not from the working tree.

Slow (a wheel build and the demo's two closed-loop runs, about a minute):
marked ``slow``; it runs with the rest (deselect with ``-m "not slow"``).
For speed the wheel is built without build isolation and installed with
--no-deps; the new environment reaches the test environment's packages
(drake, numpy, ...) through a .pth line naming its site-packages (a venv
made from a venv with --system-site-packages would see the base
interpreter's packages instead), which does not run the editable install's
import hook, so ``robstiff_drake`` can only come from the wheel.
"""

import json
import os
import shutil
import site
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
SOURCES = ("pyproject.toml", "README.md", "robstiff_drake", "models", "diagrams", "data")


def run(cmd, cwd, env, timeout=300):
    proc = subprocess.run([str(c) for c in cmd], cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout)
    assert proc.returncode == 0, f"{cmd}\n{proc.stdout}\n{proc.stderr}"
    return proc.stdout


@pytest.mark.slow
def test_a_built_wheel_runs_the_demo_from_a_clean_folder(tmp_path):
    src = tmp_path / "src"
    src.mkdir()
    for name in SOURCES:
        p = REPO / name
        if p.is_dir():
            shutil.copytree(p, src / name, ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
        else:
            shutil.copy2(p, src / name)
    env = {k: v for k, v in os.environ.items() if not k.startswith(("PYTHON", "VIRTUAL_ENV"))}
    env["HOME"] = str(tmp_path / "home")
    env["ROBSTIFF_CACHE_DIR"] = str(tmp_path / "cache")
    dist = tmp_path / "dist"
    run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "--no-index", "-q", "-w", dist, src],
        tmp_path, env)
    (wheel,) = dist.glob("robstiff_drake-*.whl")

    venv = tmp_path / "venv"
    run([sys.executable, "-m", "venv", "--without-pip", venv], tmp_path, env)
    python = venv / "bin" / "python"
    new_site = Path(run([python, "-c", "import site; print(site.getsitepackages()[0])"], tmp_path, env).strip())
    (new_site / "test_env_packages.pth").write_text("\n".join(site.getsitepackages()) + "\n")
    run([sys.executable, "-m", "pip", "--python", python, "install", "--no-deps", "--no-index", "-q", wheel],
        tmp_path, env)

    clean = tmp_path / "clean"
    clean.mkdir()
    robstiff = venv / "bin" / "robstiff"
    where = run([python, "-c", "import robstiff_drake.paths as p; print(p.MODELS_DIR)"], clean, env).strip()
    assert Path(where).is_relative_to(venv) and (Path(where) / "kr240_r2900.yaml").is_file()
    assert run([robstiff, "--version"], clean, env).strip() == "robstiff-drake 0.1.0"
    assert "r2000ic_165f" in run([robstiff, "robots"], clean, env)
    out = run([robstiff, "demo", "--out", "demo"], clean, env)
    rep = json.loads((clean / "demo" / "demo.json").read_text())
    unc, comp = rep["surface_error_mm"]["uncompensated"], rep["surface_error_mm"]["compensated"]
    # the installed package found its scenario, robot and cutting data: the
    # block test's result (as test_cli's demo test bounds it)
    assert 0.15 <= unc["mean"] <= 0.5 and abs(comp["mean"]) <= 0.02, out
    assert f"{unc['mean']:+.3f}" in out and f"{comp['mean']:+.3f}" in out, out
    assert (clean / "demo" / "demo.json").is_file() and (clean / "demo" / "surface_error.png").is_file()
    assert sorted(p.name for p in clean.iterdir()) == ["demo"]  # nothing else written in the working folder
    assert list((tmp_path / "cache").glob("irb6400-*.urdf"))  # the URDF went to the cache
