"""`robstiff identify` against the campaign's noise floor: a campaign with
play in joints 1-3 (lost motion, which the six springs lack) fits with a
residual 4x the instrument's noise and a J1 11 % low whose 95 % interval
misses the truth; identify warns (text and JSON) that the springs alone do
not explain it, with the ratio, and points at `robstiff diagnose`.  A
campaign the springs explain gets no warning (the ratio near 1)."""

import json

import pytest

from robstiff_drake.commands.main import main
from robstiff_drake.identification.stiffness.lack_of_fit import RATIO_LIMIT, read_noise_header


def _identify(tmp_path, capsys, *extra):
    assert main(["identify", "campaign.csv", "--json", "k.json", *extra]) == 0
    captured = capsys.readouterr()
    return captured.out, captured.err, json.loads((tmp_path / "k.json").read_text())


def test_lost_motion_fit_is_warned_with_its_ratio_in_text_and_json(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(["synth", "stiffness", "campaign.csv", "--effect", "lost_motion", "--seed", "3"]) == 0
    capsys.readouterr()
    assert read_noise_header("campaign.csv") == pytest.approx(0.01)  # synth states its noise
    out, err, doc = _identify(tmp_path, capsys)
    lack = doc["lack_of_fit"]
    assert lack["noise_floor_mm"] == pytest.approx(0.01)
    assert lack["residual_to_noise_ratio"] > 3.0 and lack["explained_by_springs"] is False
    said = [w for w in doc["warnings"] if "not explained by joint springs alone" in w]
    assert len(said) == 1 and "robstiff diagnose campaign.csv --noise-mm 0.01" in said[0]
    assert f"{lack['residual_to_noise_ratio']:.1f}x the noise floor" in said[0]
    assert "intervals assume the model is right" in said[0]
    assert said[0] in " ".join(err.split())  # printed as a warning
    assert "NOT explained by joint springs alone" in out


def test_no_warning_when_the_springs_explain_the_data(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(["synth", "stiffness", "campaign.csv", "--seed", "3"]) == 0
    capsys.readouterr()
    _, err, doc = _identify(tmp_path, capsys)
    lack = doc["lack_of_fit"]
    assert lack["explained_by_springs"] is True and lack["residual_to_noise_ratio"] < 1.3
    assert not [w for w in doc["warnings"] if "springs alone" in w] and "springs alone" not in err
    # a stated --noise-mm wins over the file's line: a tenth of it makes the same fit implausible
    _, _, doc = _identify(tmp_path, capsys, "--noise-mm", "0.001")
    assert doc["lack_of_fit"]["noise_floor_source"] == "stated (--noise-mm)"
    assert doc["lack_of_fit"]["residual_to_noise_ratio"] > RATIO_LIMIT
    assert doc["lack_of_fit"]["explained_by_springs"] is False


def test_without_a_floor_the_json_says_so(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(["synth", "stiffness", "campaign.csv", "--seed", "3"]) == 0
    text = (tmp_path / "campaign.csv").read_text()
    (tmp_path / "campaign.csv").write_text("".join(line for line in text.splitlines(keepends=True)
                                                   if not line.startswith("# noise_mm:")))
    capsys.readouterr()
    out, _, doc = _identify(tmp_path, capsys)
    assert doc["lack_of_fit"]["noise_floor_mm"] is None and doc["lack_of_fit"]["explained_by_springs"] is None
    assert "no noise floor known" in out


def test_a_malformed_noise_line_is_refused_before_the_fit(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(["synth", "stiffness", "campaign.csv", "--seed", "3"]) == 0
    text = (tmp_path / "campaign.csv").read_text().replace("# noise_mm: 0.01", "# noise_mm: -1")
    (tmp_path / "campaign.csv").write_text(text)
    capsys.readouterr()
    assert main(["identify", "campaign.csv", "--json", "k.json"]) == 2
    err = capsys.readouterr().err
    assert "campaign.csv:" in err and "noise_mm" in err and "(0, 10] mm" in err
    assert not (tmp_path / "k.json").exists()
