"""--tool written in metres (0.0069,0.2453,0.3193: a newcomer's FANUC tool
point copied from a source that gives metres) was taken silently by fk,
stiffness and stiffness-map as a point 0.4 mm from the flange; identify
warned about the same input.  Every command that parses --tool now warns
(stderr and the JSON's warnings), once."""

import json

import pytest

from robstiff_drake.commands.main import main

METRES = "0.0069,0.2453,0.3193"
LINE = "--tool: the tool point (0.0069, 0.2453, 0.3193) mm is 0.402706 mm from the flange: a length in metres?"


@pytest.mark.parametrize("argv", [["fk", "0", "0", "0", "0", "30", "0"], ["stiffness", "0", "0", "0", "0", "30", "0"]])
def test_fk_and_stiffness_warn_and_carry_it_into_the_json(argv, capsys):
    assert main(argv + ["--robot", "r2000ic_165f", "--tool", METRES, "--json", "-"]) == 0
    out, err = capsys.readouterr()
    assert err.count(LINE) == 1
    assert any(w.startswith(LINE) for w in json.loads(out)["warnings"])
    assert main(argv + ["--robot", "r2000ic_165f", "--tool", "6.9,245.3,319.3", "--json", "-"]) == 0
    out, err = capsys.readouterr()
    assert "metres" not in err and json.loads(out)["warnings"] == []


def test_a_tool_at_the_flange_is_no_warning(capsys):
    assert main(["fk", "0", "0", "0", "0", "30", "0", "--tool", "0,0,0"]) == 0
    assert "warning" not in capsys.readouterr().err


def test_stiffness_map_warns(tmp_path, capsys):
    assert main(["stiffness-map", "--robot", "r2000ic_165f", "--tool", METRES, "--resolution", "5", "--out",
                 str(tmp_path / "map.png")]) == 0
    assert capsys.readouterr().err.count(LINE) == 1
