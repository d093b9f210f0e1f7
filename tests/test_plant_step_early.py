"""An unstable plant step is refused before the long computation: simulate
before the feed planner runs the compensator's twin of the cell (which can
be stable where the plant is not: a KR 210 job at 1 ms, its plant needs
0.5 ms, stable to 0.79 ms; its twin runs at 1 ms; refused only after the
feed plan's runs before), compensate-program before the preview along the
program and its refinement rounds (a user's KR 210 without motor inertias:
a 169 Hz mode, the 2 ms step of the copied scenario unstable, refused only
after 23 s of computing, in its first refinement round)."""

import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _refused_before(tmp_path, capsys, monkeypatch, module, name, argv):
    """The face_and_contour job at a 4 ms plant step (unstable) through ``argv`` (its job file and output
    folder appended); ``module.name``, the long computation, must not be reached; the one error line."""
    from robstiff_drake.commands.main import main

    text = (ROOT / "diagrams" / "face_and_contour.yaml").read_text()
    assert "time_step: 0.002" in text
    job = tmp_path / "job.yaml"
    job.write_text(text.replace("time_step: 0.002", "time_step: 0.004").replace(
        "program: face_and_contour.nc", f"program: {ROOT / 'diagrams' / 'face_and_contour.nc'}"))

    def long_computation(*args, **kwargs):
        pytest.fail(f"{argv[0]} ran {name} before refusing the plant step")

    monkeypatch.setattr(module, name, long_computation)
    out = tmp_path / "out"
    assert main([argv[0], str(job), "--out", str(out), *argv[1:]]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    errors = [ln for ln in err if ln.startswith("robstiff: error:")]
    # the error's line, then only its indented why (diagrams/plant_step.StepRefusal)
    at = err.index(errors[0])
    assert len(errors) == 1 and err[at + 1].startswith("  why: ") and all(ln.startswith("       ")
                                                                          for ln in err[at + 2:]), err
    assert "plant_config.time_step" in errors[0] and "unstable" in errors[0] and "job.yaml" in errors[0]
    assert not out.exists()
    print("\n".join(err), file=sys.stderr)  # (for a caller that reads the lines again)


def test_an_unstable_plant_step_is_refused_before_the_feed_plan(tmp_path, capsys, monkeypatch):
    from robstiff_drake.diagrams import feed_plan

    assert "tolerance_mm: 0.05" in (ROOT / "diagrams" / "face_and_contour.yaml").read_text()
    _refused_before(tmp_path, capsys, monkeypatch, feed_plan, "plan_feeds", ["simulate", "--quiet"])


def test_an_unstable_plant_step_is_refused_before_the_preview(tmp_path, capsys, monkeypatch):
    from robstiff_drake.diagrams import offline_compensation as oc

    _refused_before(tmp_path, capsys, monkeypatch, oc, "predict", ["compensate-program", "--no-simulate", "--quiet"])


def test_compensate_program_says_the_refused_step_is_its_model_twins(tmp_path, capsys, monkeypatch):
    """--no-simulate checks only the compensator's twin of the cell, whose modes are not the plant's (a user's
    M-20iD/25 file: `simulate` advised 1.6 ms for the plant, then compensate-program refused 1.6 ms and advised
    0.5 ms with the same words, naming neither): the refusal says it is the twin's."""
    from robstiff_drake.diagrams import offline_compensation as oc

    _refused_before(tmp_path, capsys, monkeypatch, oc, "predict", ["compensate-program", "--no-simulate"])
    err = capsys.readouterr().err
    assert "plant_config.time_step: for the compensator's model of the cell (its twin" in err, err
