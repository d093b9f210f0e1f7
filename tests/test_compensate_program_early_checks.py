"""compensate-program refuses a job whose plant step is unstable for the
arm's modes before the long computation (the preview along the program, its
refinement rounds), as simulate and sweep do: found on a user's own robot
file (a KR 210 without motor inertias: a 169 Hz mode, the 2 ms step of the
copied scenario unstable), which compensate-program refused only after
23 s of computing, in its first refinement round."""

from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def test_an_unstable_plant_step_is_refused_before_the_preview(tmp_path, capsys, monkeypatch):
    from robstiff_drake.commands.main import main
    from robstiff_drake.diagrams import offline_compensation as oc

    text = (ROOT / "diagrams" / "face_and_contour.yaml").read_text()
    assert "time_step: 0.002" in text
    job = tmp_path / "job.yaml"
    job.write_text(text.replace("time_step: 0.002", "time_step: 0.004").replace(
        "program: face_and_contour.nc", f"program: {ROOT / 'diagrams' / 'face_and_contour.nc'}"))

    def predict(*args, **kwargs):  # the long computation: must not be reached
        pytest.fail("compensate-program ran the preview before refusing the plant step")

    monkeypatch.setattr(oc, "predict", predict)
    out = tmp_path / "corrected"
    assert main(["compensate-program", str(job), "--out", str(out), "--no-simulate", "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    errors = [ln for ln in err if ln.startswith("robstiff: error:")]
    assert len(errors) == 1 and err[-1] == errors[0], err
    assert "plant_config.time_step" in errors[0] and "unstable" in errors[0] and "job.yaml" in errors[0]
    assert not out.exists()
