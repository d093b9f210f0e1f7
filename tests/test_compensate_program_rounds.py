"""compensate-program's floor refinement (diagrams/offline_refinement.py)
is a fixed-point iteration that need not converge: on a newcomer's FANUC
job (its own identified stiffness, a 1.5 mm face cut) the rounds went
0.266, 0.035, 0.306 mm (largest predicted error on the compensator's
model) against 0.085 mm for the program as written, and the last, worst,
round was written without a word.  The best round is written, and a
corrected program predicted worse than the program as written is a
warning."""

import json
from dataclasses import dataclass

import numpy as np
import pytest


@dataclass
class _Prediction:
    delta_mm: np.ndarray
    s_m: np.ndarray
    path: object = None


def _scripted_refine(monkeypatch, maxima):
    """refine() with the twin's runs replaced by a script: round k's scan
    gives largest error maxima[k]."""
    from robstiff_drake.diagrams import offline_compensation as oc
    from robstiff_drake.diagrams import offline_refinement as ofr
    from robstiff_drake.model import floor_generation
    from robstiff_drake.model.gcode import writer

    runs = iter(range(len(maxima)))
    monkeypatch.setattr(oc, "move_corrections", lambda *a, **k: {})
    monkeypatch.setattr(writer, "rewrite_corrected", lambda text, moves, corr, *a: (text, 0))
    monkeypatch.setattr(ofr, "twin_run", lambda *a, **k: next(runs))
    monkeypatch.setattr(oc, "scanned_against_program",
                        lambda k, path: {"mean": maxima[k] / 2, "rms": maxima[k] / 2, "max_abs": maxima[k]})
    monkeypatch.setattr(ofr, "generating_errors", lambda res, path: (np.zeros(1), np.zeros(1)))
    monkeypatch.setattr(floor_generation, "floor_raise_mm", lambda s, s_gen, err: np.full(len(s), 0.01))

    class _Program:
        path = "job.nc"
        moves = []

    start = _Prediction(delta_mm=np.zeros((4, 3)), s_m=np.linspace(0.0, 0.1, 4))
    return ofr.refine(None, None, _Program(), "G1 X1.\n", start, rounds=len(maxima) - 1, chord_mm=0.005,
                      max_correction_mm=1.0)


def test_the_best_round_is_returned_when_the_rounds_do_not_converge(monkeypatch):
    from robstiff_drake.diagrams.offline_refinement import best_round

    prediction, history = _scripted_refine(monkeypatch, [0.266, 0.035, 0.306])
    assert [h["max_abs"] for h in history] == [0.266, 0.035, 0.306]
    assert best_round(history) == 1
    # round 1's prediction: the preview's delta raised once by the (scripted) 0.01 mm
    assert prediction.delta_mm[:, 2] == pytest.approx(0.01)


def test_the_last_round_is_returned_when_the_rounds_improve(monkeypatch):
    from robstiff_drake.diagrams.offline_refinement import best_round

    prediction, history = _scripted_refine(monkeypatch, [0.118, 0.033, 0.031])
    assert best_round(history) == 2
    assert prediction.delta_mm[:, 2] == pytest.approx(0.02)


def test_best_round_ties_go_to_the_smaller_mean_then_the_later_round():
    from robstiff_drake.diagrams.offline_refinement import best_round

    assert best_round([{"mean": 0.02, "max_abs": 0.05}, {"mean": -0.01, "max_abs": 0.05}]) == 1
    assert best_round([{"mean": 0.01, "max_abs": 0.05}, {"mean": -0.01, "max_abs": 0.05}]) == 1
    assert best_round([{"mean": 0.0, "max_abs": 0.04}, {"mean": 0.0, "max_abs": 0.05}]) == 0


def test_the_command_writes_the_best_round_and_warns_when_worse_than_as_written(tmp_path, monkeypatch, capsys):
    """The command end to end on the tests' short job, the refinement's
    history and the twin's run of the program as written scripted: the
    summary names the round written and both warnings are in its JSON."""
    from robstiff_drake.commands.main import main
    from robstiff_drake.diagrams import offline_refinement as ofr
    from test_compensate_program import short_job

    job = short_job(tmp_path / "job")
    history = [{"mean": 0.127, "rms": 0.13, "max_abs": 0.266}, {"mean": 0.010, "rms": 0.02, "max_abs": 0.035},
               {"mean": 0.132, "rms": 0.14, "max_abs": 0.306}]
    monkeypatch.setattr(ofr, "refine", lambda sc, robot, program, text, prediction, **k: (prediction, history))
    as_written = {"mean": 0.010, "rms": 0.012, "max_abs": 0.020}  # better than every round: the second warning
    monkeypatch.setattr(ofr, "predicted_errors", lambda *a, after=None, **k: (as_written, after))
    out = tmp_path / "corrected"
    assert main(["compensate-program", str(job), "--out", str(out), "--no-simulate", "--json",
                 str(tmp_path / "s.json")]) == 0
    summary = json.loads((tmp_path / "s.json").read_text())
    assert summary["refinement_round_written"] == 1
    assert summary["predicted_error_mm"]["after"] == {"mean": 0.010, "max_abs": 0.035}
    assert any(w.startswith("the floor's refinement did not converge") and "round 1" in w
               for w in summary["warnings"])
    assert any(w.startswith("the corrected program is predicted to cut worse than the program as written")
               for w in summary["warnings"])
    text = (out / "short_compensated.nc").read_text()
    assert "AFTER MEAN +0.010 MAX 0.035" in text
    err = capsys.readouterr()
    assert "(written)" in err.out and "robstiff: warning: the corrected program is predicted to cut worse" in err.err
