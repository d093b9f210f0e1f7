"""fk and stiffness take the pendant's degrees; six angles typed in radians
(a pose copied from a campaign in rad: -1.047 -0.291 -0.505 0.066 -1.098
2.529) were taken as a pose a few degrees off home without a word.  Now a
warning (stderr and the JSON's warnings); whole degrees, zeros and poses
with fewer than three angles off zero are not warned about."""

import json

import pytest

from robstiff_drake.commands.main import main

RAD = ["-1.047", "-0.291", "-0.505", "0.066", "-1.098", "2.529"]


@pytest.mark.parametrize("command", ["fk", "stiffness"])
def test_radians_are_a_warning(command, capsys):
    assert main([command, *RAD, "--robot", "r2000ic_165f", "--json", "-"]) == 0
    out, err = capsys.readouterr()
    assert err.count("is within +-2 pi: radians?") == 1
    assert any("radians?" in w for w in json.loads(out)["warnings"])


@pytest.mark.parametrize("q", [["0", "0", "0", "0", "5", "0"], ["0", "1", "-2", "0", "3", "0"],
                               ["0", "-0.5", "0.25", "0", "0", "0"], ["10", "-60", "100", "20", "30", "40"]])
def test_degrees_are_not(q, capsys):
    assert main(["fk", *q, "--robot", "r2000ic_165f"]) == 0
    assert "radians" not in capsys.readouterr().err
