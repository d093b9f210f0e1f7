"""`robstiff diagnose` reads the campaign's `# noise_mm:` line (the
instrument's noise, written by `robstiff synth stiffness`) as `robstiff
identify` does, through the same function (stiffness/lack_of_fit.
stated_noise), with the same precedence: --noise-mm, then the file's line,
then the replicate rows; and says in its text and JSON where the floor came
from.  Before, diagnose took --noise-mm or the replicates only: a synthetic
campaign with its noise stated in the file was diagnosed with "noise floor:
none stated or measured" (no lack-of-fit test)."""

import json

import numpy as np
import pytest

from robstiff_drake.commands.main import main


def _diagnose(tmp_path, capsys, data, *extra):
    assert main(["diagnose", data, "--json", "d.json", *extra]) == 0
    out = capsys.readouterr().out
    return out, json.loads((tmp_path / "d.json").read_text())


@pytest.fixture
def campaign(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert main(["synth", "stiffness", "campaign.csv", "--n", "12", "--seed", "3"]) == 0
    capsys.readouterr()
    return tmp_path / "campaign.csv"


def _with_replicates(path, sigma_mm):
    """The campaign with each row measured again (its displacement plus
    Gaussian noise of ``sigma_mm``, fixed seed): replicate rows."""
    lines = path.read_text().splitlines()
    head = next(i for i, ln in enumerate(lines) if not ln.startswith("#"))
    rng = np.random.default_rng(11)
    again = []
    for ln in lines[head + 1:]:
        v = ln.split(",")
        v[1] = str(int(v[1]) + 10000)
        v[-3:] = [repr(float(x) + rng.normal(0.0, sigma_mm)) for x in v[-3:]]
        again.append(",".join(v))
    path.write_text("\n".join(lines + again) + "\n")


def test_the_files_noise_line_is_the_floor_and_the_report_says_so(tmp_path, capsys, campaign):
    out, doc = _diagnose(tmp_path, capsys, "campaign.csv")
    assert doc["noise_floor_mm"] == pytest.approx(0.01)  # before: None ("none stated or measured")
    assert doc["noise_source"] == "stated" and doc["lack_of_fit"] is not None
    assert doc["noise_floor_source"] == "stated in campaign.csv's '# noise_mm:' line"
    assert "noise floor: 0.0100 mm, stated in campaign.csv's '# noise_mm:' line" in out
    # --noise-mm wins over the file's line
    out, doc = _diagnose(tmp_path, capsys, "campaign.csv", "--noise-mm", "0.02")
    assert doc["noise_floor_mm"] == pytest.approx(0.02) and doc["noise_floor_source"] == "stated (--noise-mm)"
    assert "noise floor: 0.0200 mm, stated (--noise-mm)" in out


def test_the_files_line_wins_over_the_replicates_and_without_it_they_are_the_floor(tmp_path, capsys, campaign):
    _with_replicates(campaign, 0.03)
    _, doc = _diagnose(tmp_path, capsys, "campaign.csv")
    assert doc["noise_floor_mm"] == pytest.approx(0.01) and doc["noise_source"] == "stated"
    rep = doc["noise_floor_replicates_mm"]
    assert 0.015 < rep < 0.03  # (the replicates' own scatter, reported beside the stated floor)
    campaign.write_text("".join(ln for ln in campaign.read_text().splitlines(keepends=True)
                                if not ln.startswith("# noise_mm:")))
    out, doc = _diagnose(tmp_path, capsys, "campaign.csv")
    assert doc["noise_source"] == "replicates" and doc["noise_floor_mm"] == pytest.approx(rep)
    assert doc["noise_floor_source"] == f"estimated from 12 sets of replicate rows ({doc['replicate_dof']} dof)"
    assert f"noise floor: {rep:.4f} mm, estimated from 12 sets of replicate rows" in out


def test_a_malformed_noise_line_is_refused_before_the_diagnosis(tmp_path, capsys, campaign):
    campaign.write_text(campaign.read_text().replace("# noise_mm: 0.01", "# noise_mm: 0"))
    assert main(["diagnose", "campaign.csv", "--json", "d.json"]) == 2
    err = capsys.readouterr().err
    assert "campaign.csv:" in err and "noise_mm" in err and "(0, 10] mm" in err and "Traceback" not in err
    assert not (tmp_path / "d.json").exists()
