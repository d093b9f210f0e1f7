"""A scenario that does not state cutter.spindle_rating_W got the paper's
3.73 kW spindle for every run's spindle-power check without a word; now a
note says so (stderr, and the 'notes' of the JSON the command writes), and
the packaged scenarios state the rating, with its source, so a copy of one
carries it visibly."""

import json
from pathlib import Path

import pytest

from robstiff_drake.command import command_scope
from robstiff_drake.diagrams.scenario import load_scenario
from robstiff_drake.io import json_text

ROOT = Path(__file__).resolve().parents[1]


def test_an_unstated_rating_is_a_note_in_text_and_json(capsys, tmp_path):
    text = (ROOT / "diagrams" / "short_block.yaml").read_text()
    path = tmp_path / "mine.yaml"  # a user's scenario without the key
    path.write_text("".join(ln for ln in text.splitlines(keepends=True) if "spindle_rating_W" not in ln))
    with command_scope():
        sc = load_scenario(str(path))
        doc = json.loads(json_text({"warnings": []}))
    assert sc.cutter.spindle_rating_W == 3730.0
    err = capsys.readouterr().err
    said = [ln for ln in err.splitlines() if "spindle_rating_W not stated" in ln]
    assert len(said) == 1 and said[0].startswith("robstiff: note: ") and "3.73 kW" in said[0]
    assert "the paper's spindle" in said[0] and str(path) in said[0]
    assert doc["notes"] == [said[0].removeprefix("robstiff: note: ")] and doc["warnings"] == []


@pytest.mark.parametrize("name", sorted(p.name for p in (ROOT / "diagrams").glob("*.yaml")))
def test_the_packaged_scenarios_state_it(name, capsys):
    with command_scope():
        sc = load_scenario(str(ROOT / "diagrams" / name))
    assert sc.cutter.spindle_rating_W == 3730.0
    assert "spindle_rating_W not stated" not in capsys.readouterr().err
