"""`robstiff compensate` and the gears' play a user identified: the
real-time chain is linear (C J^T W) and does not apply the play's law (the
simulation's compensator does: model/compensator.DeflectionModel), so
compensate says so in one line at the start, with the twist it ignores,
and in summary.json's ``play``; before, a --model carrying
``lost_motion_rad`` was read for its stiffness only and the play dropped
without a word.  Bad play keys: one line, exit status 2."""

import json
import os

import numpy as np
import pytest

import cell_helpers as h
from robstiff_drake.cell.play_note import play_note, read_play
from robstiff_drake.commands.main import main
from robstiff_drake.errors import InputError
from robstiff_drake.model.robot import load_robot

Q0 = [0.0, 7.008, 29.517, 0.0, 53.476, 0.0]
PLAY = [0.0, 1e-4, 0.0, 2e-4, 0.0, 3e-4]


def test_the_note_names_each_joint_with_play_and_its_ignored_twist():
    robot = load_robot()
    play = read_play({"joint_stiffness_Nm_per_rad": [1e6] * 6, "lost_motion_rad": PLAY}, "--model m.json")
    assert play["law"] == "hysteretic" and play["lost_motion_rad"] == PLAY
    line, doc = play_note(robot, play, Q0, "the reference's first row")
    assert "NOT compensated" in line and "q2: up to 200 urad" in line and "q4: up to 400 urad" in line
    assert "q6: up to 600 urad" in line and "q1:" not in line
    assert doc["compensated"] is False and doc["ignored_twist_bound_rad"] == [2 * b for b in PLAY]
    # joint 2 holds the arm against gravity at the block test's start (hundreds of N*m: only a process torque
    # over it, against it, takes the gear across); the wrist's joint 4 holds almost none there
    assert doc["holding_torque_Nm"][1] > 100.0 and doc["holding_torque_Nm"][3] < 1.0, doc["holding_torque_Nm"]
    assert doc["tool_move_bound_mm"][1] > 0.1, doc  # 200 urad on joint 2 over a 1.6 m reach
    line, doc = play_note(robot, play)  # no reference: the start pose not known yet, the bound alone
    assert "q4: up to 400 urad" in line and doc["holding_torque_Nm"] is None
    assert read_play({"lost_motion_rad": [0.0] * 6}, "m") is None and read_play({}, "m") is None
    assert play_note(robot, None) == (None, None)


@pytest.mark.parametrize("key, value, words", [
    ("lost_motion_rad", [0.0, 0.0, 0.0, 0.0, 0.0, 0.05], "lost_motion_rad: expected six numbers in [0, 0.01]"),
    ("lost_motion_rad", [1e-4] * 5, "lost_motion_rad: expected six numbers"),
    ("lost_motion_law", "sticky", "lost_motion_law: 'sticky', expected one of hysteretic, smooth"),
])
def test_bad_play_keys_are_one_line(key, value, words):
    doc = {"lost_motion_rad": PLAY, key: value}
    with pytest.raises(InputError, match="--model m.json: " + words.replace("[", r"\[").replace("]", r"\]")):
        read_play(doc, "--model m.json")


def test_compensate_says_at_its_start_that_the_play_is_not_compensated(tmp_path, capsys):
    robot = load_robot()
    model, payload, reference, _ = h.write_inputs(str(tmp_path), robot, duration_s=0.4)
    doc = json.loads(open(model).read())
    doc["lost_motion_rad"] = PLAY
    with open(model, "w") as f:
        json.dump(doc, f)
    # no sensor on the port: the run stops at the sensor (exit 2), after the start's lines
    code = main(["compensate", "--egm-port", str(h.free_udp_port()), "--netft", f"127.0.0.1:{h.free_udp_port()}",
                 "--netft-counts", "1000000,1000", "--netft-units", "N,N-mm", "--netft-open-s", "0.2",
                 "--model", model, "--payload", payload, "--reference", reference])
    err = capsys.readouterr().err
    assert code == 2, err
    lines = [x for x in err.splitlines() if "play" in x]
    assert len(lines) == 1 and lines[0].startswith("robstiff: warning: compensate: the gears' play (--model "), err
    assert "NOT compensated" in lines[0] and "at the reference's first row" in lines[0], lines[0]
    # a bad value: refused in one line before anything else
    doc["lost_motion_rad"] = [0.5] * 6
    with open(model, "w") as f:
        json.dump(doc, f)
    code = main(["compensate", "--egm-port", str(h.free_udp_port()), "--netft", "127.0.0.1", "--model", model,
                 "--payload", payload, "--reference", reference])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "lost_motion_rad: expected six numbers" in err, err
    assert os.path.exists(model) and np.allclose(json.loads(open(model).read())["lost_motion_rad"], [0.5] * 6)
