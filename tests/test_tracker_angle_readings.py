"""A tracker campaign with one joint column misread (in radians, or two
columns interchanged) registers to no arm: the refusal now names the reading
that registers (identification/tracker/angle_readings.py) instead of only
"the robot file does not describe this arm, or q1..q6 are not its
controller's angles".  On a Drake-made campaign (tests/tracker_world.py,
always) and on the real UR10 series B (skipped, with the reason, without
../shared/realdata); another arm's robot file is not blamed on a column."""

from pathlib import Path

import numpy as np
import pytest
import realdata
import tracker_world as tw

from robstiff_drake.commands.main import main
from robstiff_drake.model.robot import load_robot

UR10 = Path(__file__).resolve().parent / "data" / "ur10_user.yaml"


def _misread(text, how):
    lines = text.splitlines()
    h = next(i for i, l in enumerate(lines) if not l.startswith("#"))
    col = {n: i for i, n in enumerate(lines[h].split(","))}
    out = lines[:h + 1]
    for line in lines[h + 1:]:
        c = line.split(",")
        if how.startswith("radians_"):
            k = col[how.split("_")[1]]
            c[k] = f"{np.deg2rad(float(c[k])):.10g}"
        else:
            a, b = col[how.split("_")[1]], col[how.split("_")[2]]
            c[a], c[b] = c[b], c[a]
        out.append(",".join(c))
    return "\n".join(out) + "\n"


CASES = [("radians_q5", "read with q5 in radians"), ("swap_q5_q6", "read with q5 and q6 interchanged"),
         ("swap_q2_q3", "read with q2 and q3 interchanged")]


def _refusal(capsys, path, *argv):
    code = main(["diagnose", str(path), *map(str, argv)])
    err = capsys.readouterr().err
    assert code == 2 and len(err.strip().splitlines()) == 1 and "Traceback" not in err, err
    return err


# q3 turns +-160 deg: q2's values in its column stop at the joint limit first; joints 4-6 turn +-360 deg
SYNTH = CASES[:2] + [("swap_q4_q6", "read with q4 and q6 interchanged")]


@pytest.mark.parametrize("how, said", SYNTH, ids=[c[0] for c in SYNTH])
def test_a_misread_joint_column_is_named_in_the_refusal(capsys, tmp_path, how, said):
    # the UR10's joints turn +-360 deg: a misread column stays within its limits (an IRB 6400's +-70 deg joint 2
    # refuses most such files at the joint limit first, naming the cell)
    world = tw.make_tracker_campaign(load_robot(str(UR10)), 61, n=200)
    path = tmp_path / "c.csv"
    path.write_text(_misread(world.csv_text, how))
    err = _refusal(capsys, path, "--robot", UR10)
    assert said in err and "check" in err, err


def test_another_arms_file_is_not_blamed_on_a_column(capsys, tmp_path):
    world = tw.make_tracker_campaign(load_robot("irb6400"), 54, n=60)
    path = tmp_path / "c.csv"
    path.write_text(world.csv_text)
    err = _refusal(capsys, path, "--robot", UR10)
    assert "does not describe this arm" in err and "read with" not in err, err


@pytest.fixture(scope="module")
def ur10_b(tmp_path_factory):
    realdata.require(realdata.IPA_UR10)
    return realdata.ipa_ur10_campaign_csv("B", tmp_path_factory.mktemp("ur10") / "ur10_B.csv")


@pytest.mark.parametrize("how, said", CASES, ids=[c[0] for c in CASES])
def test_the_real_ur10_misread_is_named(capsys, tmp_path, ur10_b, how, said):
    # before: "registered ... 31.5 mm RMS off: the robot file does not describe this arm, or q1..q6 are not its
    # controller's angles" (q5 in radians, q5/q6 interchanged) or "no length unit makes them match" (q2/q3)
    path = tmp_path / "b.csv"
    path.write_text(_misread(ur10_b.read_text(), how))
    err = _refusal(capsys, path, "--robot", UR10)
    assert said in err, err
