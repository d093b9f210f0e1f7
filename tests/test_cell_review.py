"""An adversarial review of `robstiff compensate`'s real-time path: each
test drives one suspicion (a scripted controller message, a bad input file)
and checks that what the controller would command stays inside the robot's
limits, or that the input is refused in one line before any socket opens.
No timing: the links are driven message by message."""

import json
import os
import socket
import subprocess
import sys

import numpy as np
import pytest

sys.path.insert(0, os.path.dirname(__file__))
import cell_helpers as h  # noqa: E402

from robstiff_drake.cell import rsi  # noqa: E402
from robstiff_drake.cell.safety import Envelope, UnsafeTarget, clamp_deg, supervision_tolerances  # noqa: E402
from robstiff_drake.errors import InputError  # noqa: E402
from robstiff_drake.model.robot import load_robot  # noqa: E402

T = 0.004
Q0 = [0.0, 7.008, 29.517, 0.0, 53.476, 0.0]


@pytest.fixture(scope="module")
def robot():
    return load_robot()


def _envelope(robot, ref, measured=None):
    """The loop's envelope at a standing reference ``ref`` (deg): the clamp around it and around the feedback."""
    c = tuple(clamp_deg(robot, 0.5).tolist())
    return Envelope(tuple(np.degrees(robot.q_lower_rad)), tuple(np.degrees(robot.q_upper_rad)), tuple(ref), c,
                    tuple(ref if measured is None else measured), c, *supervision_tolerances(robot, T))


@pytest.fixture()
def rsi_link():
    sink = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sink.bind(("127.0.0.1", 0))
    link = rsi.RsiLink(0, ("127.0.0.1", None), T)
    link.reply_to = sink.getsockname()
    yield link
    link.close()
    sink.close()


# ---------------------------------------------------------------------------------------------- RSI's start


@pytest.mark.parametrize("setpoint_off", [[20.0, 0, 0, 0, 0, 0], [0, 0, 0, 0, 0, 400.0], [0, 0, 0, 1e6, 0, 0]],
                         ids=["20 deg from the arm", "outside the working range", "absurd"])
def test_rsi_start_setpoint_that_is_not_where_the_arm_stands_is_not_answered(robot, rsi_link, setpoint_off):
    """RSI's corrections count from the session's start, the setpoint
    (ASPos) of its first message.  A setpoint far from the axes' actual
    angles (AIPos) of a controller at rest, or outside the working ranges,
    is no start the controller can have (a wrong RSI configuration, a
    corrupted value).  Held (no change needed): the link takes the start as
    the pose the controller commands now, so a target at the arm is more
    than one period's axis speed from it and is refused."""
    setpoint = (np.asarray(Q0) + setpoint_off).tolist()
    msg = rsi_link.decode(rsi.encode_rob(1_000_000, Q0, setpoint))
    with pytest.raises(UnsafeTarget, match="from the pose the controller commands now"):
        rsi_link.send_targets(msg, Q0, _envelope(robot, Q0))
    assert rsi_link.sent == 0


def test_rsi_start_setpoint_at_the_arm_is_answered(robot, rsi_link):
    """The normal start (ASPos = AIPos up to the wire's rounding) is answered, AK = 0."""
    actual = (np.asarray(Q0) + 2e-6).tolist()
    msg = rsi_link.decode(rsi.encode_rob(1_000_000, actual, Q0))
    assert rsi_link.send_targets(msg, Q0, _envelope(robot, Q0, actual))


# ---------------------------------------------------------------------------------------------- input files


def _model_with_a_duplicated_key(folder, robot):
    k = robot.joint_stiffness_Nm_per_rad.tolist()
    path = os.path.join(folder, "model.json")
    with open(path, "w") as f:
        f.write('{"robot": "%s",\n "joint_stiffness_Nm_per_rad": %s,\n "joint_stiffness_Nm_per_rad": %s}\n'
                % (robot.name, json.dumps(k), json.dumps([1e9] * 6)))
    return path


def test_a_model_json_with_a_duplicated_key_is_refused(tmp_path, robot):
    """json.loads keeps the last of a duplicated key silently: a --model
    whose joint_stiffness_Nm_per_rad came twice (a merge gone wrong) was read
    as its second value (1e9 N*m/rad: no compensation at all).  Now one line
    naming the file, the key and its line (as the YAML files' reader does)."""
    from robstiff_drake.commands.compensate_inputs import read_model

    path = _model_with_a_duplicated_key(str(tmp_path), robot)
    with pytest.raises(InputError, match=r"model\.json: duplicated key 'joint_stiffness_Nm_per_rad' in one object "
                                         r"\(line 3\)"):
        read_model(path, robot)


def test_compensate_refuses_it_in_one_line_before_any_socket_opens(tmp_path, robot):
    """The command: exit status 2, one line, no traceback, and before the
    controller's port is bound (the port is held here: binding it would
    fail with another message)."""
    model, payload, ref, _ = h.write_inputs(str(tmp_path), robot, duration_s=0.1)
    model = _model_with_a_duplicated_key(str(tmp_path), robot)
    held = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    held.bind(("127.0.0.1", 0))
    try:
        cp = subprocess.run([sys.executable, "-m", "robstiff_drake", "compensate", "--egm-port",
                             str(held.getsockname()[1]), "--netft", "127.0.0.1:1", "--model", model, "--payload",
                             payload, "--reference", ref], cwd=h.ROOT, capture_output=True, text=True, timeout=120)
    finally:
        held.close()
    lines = cp.stderr.strip().splitlines()
    assert cp.returncode == 2 and len(lines) == 1, cp.stderr
    assert "duplicated key 'joint_stiffness_Nm_per_rad'" in lines[0] and "Traceback" not in cp.stderr
