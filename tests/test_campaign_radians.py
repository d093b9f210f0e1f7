"""Joint angles written in radians under q1..q6 (no unit in the header) are
refused for every library robot, not only for the IRB 6400: the check reads
the file both ways through the robot file's controller map (KUKA's A3
offset, FANUC's signs and J2/J3 coupling), and it also looks at files whose
angles reach beyond pi (a wrist joint: the real FANUC R-2000iC campaign's J6
reaches 4.15 rad).  Before, a FANUC campaign in radians was identified as
degrees, joints 3 and 6 'non-physical', exit 0."""

import numpy as np
import pytest

from robstiff_drake.commands.main import main


def _to_radians(src, dst):
    lines = src.read_text().splitlines()
    i = next(k for k, ln in enumerate(lines) if not ln.startswith("#"))
    head = lines[i].split(",")
    cols = [head.index(f"q{j}") for j in range(1, 7)]
    out = lines[:i + 1]
    for ln in lines[i + 1:]:
        cells = ln.split(",")
        for c in cols:
            cells[c] = repr(float(np.deg2rad(float(cells[c]))))
        out.append(",".join(cells))
    dst.write_text("\n".join(out) + "\n")
    return dst


@pytest.mark.parametrize("robot", ["irb6400", "kr240_r2900", "r2000ic_165f"])
def test_a_synthetic_campaign_in_radians_is_refused_on_every_robot(robot, tmp_path, capsys):
    deg = tmp_path / "deg.csv"
    assert main(["synth", "stiffness", str(deg), "--robot", robot, "--n", "40", "--seed", "4", "--quiet"]) == 0
    assert main(["identify", str(deg), "--robot", robot, "--quiet"]) == 0  # degrees: read as they are
    capsys.readouterr()
    rad = _to_radians(deg, tmp_path / "rad.csv")
    assert main(["identify", str(rad), "--robot", robot]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and ("look like radians" in err or "Or angles in radians?" in err), err


def test_the_fanuc_campaign_in_radians_is_refused(tmp_path, capsys):
    from realdata import FANUC, FANUC_ROBOT, fanuc_campaign_csv, missing

    reason = missing(FANUC)
    if reason:
        print(f"skipped: {reason}")
        pytest.skip(reason)
    deg = fanuc_campaign_csv(tmp_path / "deg.csv")
    assert main(["identify", str(deg), "--robot", FANUC_ROBOT, "--quiet"]) == 0
    capsys.readouterr()
    rad = _to_radians(deg, tmp_path / "rad.csv")
    assert np.max(np.abs(np.loadtxt(rad, delimiter=",", comments="#", skiprows=3, usecols=range(1, 7)))) > np.pi
    for command in ("identify", "diagnose"):
        assert main([command, str(rad), "--robot", FANUC_ROBOT]) == 2
        err = capsys.readouterr().err.strip()
        assert err.count("\n") == 0 and "look like radians" in err and "as radians none" in err, err
