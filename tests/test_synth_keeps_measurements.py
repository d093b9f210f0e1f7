"""`robstiff synth stiffness OUT.csv` wrote over any file: a newcomer's
measured FANUC campaign (fanuc.csv, 43 loaded measurements) became a
synthetic one, exit 0.  Now an existing file that robstiff did not make (its
first line says so), or a plan with measured displacements added, is
refused (exit 2, one line, the file untouched); synth's own campaigns and
plan-poses' plans are written over as before (docs/your_robot.md's
rehearsal writes over plan.csv)."""

import pytest

from robstiff_drake.commands.main import main

MEASURED = "# tool_mm: 6.9, 245.3, 319.3\npose,q1,q2,q3,q4,q5,q6,fx,fy,fz,dx,dy,dz\n" \
           "P001,-59.991,-16.693,-28.93,3.788,-62.93,144.919,-120.2,-78.2,-14.7,-0.686,-0.396,-0.025\n"


@pytest.mark.parametrize("kind", ["stiffness", "payload", "tracker"])
def test_a_measured_campaign_is_not_written_over(kind, tmp_path, capsys):
    path = tmp_path / "fanuc.csv"
    path.write_text(MEASURED)
    assert main(["synth", kind, str(path), "--robot", "r2000ic_165f"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "exists and was not made by robstiff" in err
    assert path.read_text() == MEASURED


def test_a_plan_with_measurements_added_is_not_written_over(tmp_path, capsys):
    plan = tmp_path / "plan.csv"
    assert main(["plan-poses", "8", "--out", str(plan), "--quiet"]) == 0
    assert main(["synth", "stiffness", str(plan), "--quiet"]) == 0  # a plan: the docs' rehearsal writes over it
    assert main(["plan-poses", "8", "--out", str(plan), "--quiet"]) == 0
    lines = plan.read_text().splitlines()
    i = next(k for k, ln in enumerate(lines) if not ln.startswith("#"))
    measured = lines[:i] + [lines[i] + ",dx,dy,dz"] + [ln + ",0.1,0.2,0.3" for ln in lines[i + 1:]]
    plan.write_text("\n".join(measured) + "\n")
    before = plan.read_text()
    capsys.readouterr()
    assert main(["synth", "stiffness", str(plan)]) == 2
    assert "a measurement plan with measured displacements added" in capsys.readouterr().err
    assert plan.read_text() == before


def test_synths_own_campaign_is_written_over(tmp_path):
    out = tmp_path / "sim.csv"
    assert main(["synth", "stiffness", str(out), "--n", "12", "--quiet"]) == 0
    first = out.read_text()
    assert main(["synth", "stiffness", str(out), "--n", "12", "--seed", "3", "--quiet"]) == 0
    assert out.read_text() != first


def test_plan_poses_does_not_write_over_measurements(tmp_path, capsys):
    """plan-poses --out over the plan the user filled in (or a measured campaign) is refused the same way;
    over its own plan it writes as before."""
    plan = tmp_path / "plan.csv"
    assert main(["plan-poses", "8", "--out", str(plan), "--quiet"]) == 0
    assert main(["plan-poses", "8", "--out", str(plan), "--quiet"]) == 0
    measured = tmp_path / "fanuc.csv"
    measured.write_text(MEASURED)
    capsys.readouterr()
    assert main(["plan-poses", "8", "--out", str(measured)]) == 2
    assert "exists and was not made by robstiff" in capsys.readouterr().err and measured.read_text() == MEASURED
