"""An adversarial review of `robstiff compensate`'s real-time path: each
test drives one suspicion (a scripted controller message, a bad input file)
and checks that what the controller would command stays inside the robot's
limits, or that the input is refused in one line before any socket opens.
No timing: the links are driven message by message (the loop's faults:
tests/test_cell_review_loop.py)."""

import json
import os
import socket
import subprocess
import sys

import numpy as np
import pytest

sys.path.insert(0, os.path.dirname(__file__))
import cell_helpers as h  # noqa: E402
from rsi_session import Q0, T, drive  # noqa: E402

from robstiff_drake.cell import rsi  # noqa: E402
from robstiff_drake.cell.safety import Envelope, UnsafeTarget, clamp_deg, supervision_tolerances  # noqa: E402
from robstiff_drake.errors import InputError  # noqa: E402


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


# ---------------------------------------------------------------------------------------------- RSI: lost datagrams


def _rsi_session(robot, speed_deg_per_s, *, lost_at=300, lost=7, epoch_ms=0, n=400, restart=False):
    """An RSI controller that keeps its session (tests/rsi_session.py) along a path moving q1 at
    ``speed_deg_per_s``; at message ``lost_at`` ``lost`` datagrams were lost on the way (its IPOC skips them;
    ``epoch_ms`` more: a new IPOC epoch; ``restart``: the controller restarts RSI there instead, its start the pose
    it stands at).  Returns (the largest |commanded - reference| (deg), the link's refusals); the link (closed) in
    ``_rsi_last``."""
    link, worst, refused, _ = drive(robot, speed_deg_per_s=speed_deg_per_s, first_ipoc=1_000_004, event_at=lost_at,
                                    n=n, lost=lost, epoch_ms=epoch_ms, restart=restart)
    _rsi_last[:] = [link]
    return worst, refused


_rsi_last = []


@pytest.mark.parametrize("speed", [1.0, 2.0])
def test_rsi_lost_datagrams_are_not_taken_for_a_restart_that_moves_the_arm(robot, speed):
    """Seven datagrams lost in a row mid-path: the IPOC skips more than the
    session check's window, as at a restart, but the controller keeps its
    session and its start.  Before: the link learnt a new start (the pose
    the controller commands now) and its one answer, AK from that start,
    made the controller command 2.4 deg (2 deg/s path) from the reference,
    back towards the session's start, passing its own check (the docstring's
    "residual risk").  A skip no longer than the time this PC saw pass may
    be lost datagrams: the answer must be safe under the old start too
    (else refused: the controller stops), so nothing beyond the bounds is
    commanded."""
    clamp = float(clamp_deg(robot, 0.5).max())
    worst, refused = _rsi_session(robot, speed)
    assert worst <= clamp + speed * T + 1e-6, worst
    assert refused and "the old start" in refused[0], refused[:1]


def test_rsi_restart_with_a_new_ipoc_epoch_is_still_taken(robot):
    """A skip far beyond the time this PC saw pass (a new IPOC epoch, as the
    simulated KRC restarts) cannot be lost datagrams: a controller that
    restarted there (its start the pose it stands at) is answered on as
    before, within the bounds."""
    worst, refused = _rsi_session(robot, 2.0, epoch_ms=10_000_000, restart=True)
    assert not refused and worst <= float(clamp_deg(robot, 0.5).max()) + 2.0 * T + 1e-6, (worst, refused[:1])


def test_rsi_restart_that_looks_like_lost_datagrams_is_not_answered_far_from_the_old_start(robot):
    """The price: a restart whose IPOC goes on with the time (no new epoch)
    at a pose far from the session's start (2.4 deg along the path) cannot
    be told from lost datagrams; its answers are refused (the controller
    stops) rather than risk the jump above."""
    worst, refused = _rsi_session(robot, 2.0, restart=True)
    assert refused and "the old start" in refused[0], refused[:1]


def test_rsi_restart_near_the_old_start_is_answered_and_the_setpoint_tells_it_a_restart(robot):
    """A restart without a new epoch 0.45 deg along the path (0.375 deg/s)
    from the old start: answers safe from either start go out; once the path
    has moved on by more than the setpoint check's tolerance, the setpoint
    (the new start plus an AK sent, not the old start plus any) ends the
    doubt."""
    worst, refused = _rsi_session(robot, 0.45 / (300 * T), restart=True, n=800)
    assert not refused and worst <= float(clamp_deg(robot, 0.5).max()) + 1e-3, (worst, refused[:1])
    assert _rsi_last[0]._maybe_old is None and _rsi_last[0].session == 2


# ---------------------------------------------------------------------------------------------- malformed datagrams


def _bad_datagrams(protocol):
    """(link, a good datagram, [bad datagrams]) of a protocol: truncated, oversized, of another kind."""
    import random

    from robstiff_drake.cell import stream_motion
    from robstiff_drake.cell.egm import ControllerLink, EgmLink

    rng = random.Random(7)
    noise = bytes(rng.getrandbits(8) for _ in range(60000))
    if protocol == "egm":
        side = ControllerLink("127.0.0.1", 1)
        good = side.robot_message(Q0, tm_ms=4)
        seven = side.robot_message(Q0 + [1.0], tm_ms=8)
        command = side.robot_message(Q0, mtype=side.pb2.EgmHeader.MSGTYPE_COMMAND, tm_ms=12)
        side.close()
        return EgmLink(0, ("127.0.0.1", None)), good, [b"", good[:len(good) // 2], noise, seven, command]
    if protocol == "rsi":
        good = rsi.encode_rob(1000, Q0, Q0)
        laughs = (b'<?xml version="1.0"?><!DOCTYPE r [<!ENTITY a "aaaaaaaaaa"><!ENTITY b "&a;&a;&a;&a;">]>'
                  b"<Rob><IPOC>&b;</IPOC></Rob>")
        return (rsi.RsiLink(0, ("127.0.0.1", None), T), good,
                [good[:-20], good + b" " * 5000, laughs, good.replace(b"<AIPos", b"<AXPos"), noise[:3000]])
    good = stream_motion.encode_status(1, 4, Q0)
    return (None, good, [good[:-1], good + b"\0", stream_motion.encode_status(2, 8, Q0, status=0x04),
                         stream_motion.encode_command(3, Q0), noise[:len(good)]])


@pytest.mark.parametrize("protocol", ["egm", "rsi", "stream-motion"])
def test_truncated_oversized_and_foreign_datagrams_are_dropped_and_counted(protocol):
    """From the controller's own address: each bad datagram is counted as
    malformed and never decoded into a message; the good one after them is
    read."""
    from robstiff_drake.cell import stream_motion

    sender = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sender.bind(("127.0.0.1", 0))
    link, good, bad = _bad_datagrams(protocol)
    if link is None:
        link = stream_motion.StreamMotionLink(0, ("127.0.0.1", sender.getsockname()[1]))
    try:
        for data in bad + [good]:
            sender.sendto(data, ("127.0.0.1", link.port))
        got = []
        for _ in range(20):
            got += link.receive(1.0)
            if got:
                break
        assert len(got) == 1 and np.allclose(got[0][0].joints_deg, Q0), got
        assert link.malformed == len(bad), (link.malformed, link.malformed_example)
    finally:
        link.close()
        sender.close()
