"""`robstiff identify` and the gears' play: its fit is the six-spring law
(Eq. 8), so it does not identify play and its --json (compensate's
--model) carries no lost_motion_* keys; it says so in one line, rather
than leaving a user who expects the play to reach compensate's play note
(cell/play_note.py) to find out from the note's absence."""

import json

from robstiff_drake.cell.play_note import read_play
from robstiff_drake.commands.identify import PLAY_NOT_IDENTIFIED
from robstiff_drake.commands.main import main


def test_identify_says_it_does_not_identify_play_and_writes_no_play_keys(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    # a campaign with play in joints 1-3 (the named effect diagnose finds)
    assert main(["synth", "stiffness", "campaign.csv", "--n", "60", "--effect", "lost_motion=0.05"]) == 0
    capsys.readouterr()
    assert main(["identify", "campaign.csv", "--json", "model.json"]) == 0
    out = capsys.readouterr().out
    assert PLAY_NOT_IDENTIFIED in out.splitlines()
    doc = json.loads((tmp_path / "model.json").read_text())
    assert not [k for k in doc if k.startswith("lost_motion")]
    assert read_play(doc, "model.json") is None  # compensate --model: no play, so no play note
