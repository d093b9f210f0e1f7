"""simulate refuses a plant step unstable for the plant's modes before the
feed planner runs the compensator's twin of the cell (which can be stable
where the plant is not): a KR 210 job at 1 ms (its plant needs 0.5 ms, stable to 0.79 ms; its
twin runs at 1 ms) was refused only after the feed plan's runs."""

from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def test_an_unstable_plant_step_is_refused_before_the_feed_plan(tmp_path, capsys, monkeypatch):
    from robstiff_drake.commands.main import main
    from robstiff_drake.diagrams import feed_plan

    text = (ROOT / "diagrams" / "face_and_contour.yaml").read_text()
    assert "time_step: 0.002" in text and "tolerance_mm: 0.05" in text
    job = tmp_path / "job.yaml"
    job.write_text(text.replace("time_step: 0.002", "time_step: 0.004").replace(
        "program: face_and_contour.nc", f"program: {ROOT / 'diagrams' / 'face_and_contour.nc'}"))

    def plan_feeds(*args, **kwargs):  # the long computation: must not be reached
        pytest.fail("simulate ran the feed planner before refusing the plant step")

    monkeypatch.setattr(feed_plan, "plan_feeds", plan_feeds)
    out = tmp_path / "run"
    assert main(["simulate", str(job), "--out", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    errors = [ln for ln in err if ln.startswith("robstiff: error:")]
    assert len(errors) == 1 and err[-1] == errors[0], err
    assert "plant_config.time_step" in errors[0] and "unstable" in errors[0]
    assert not out.exists()
