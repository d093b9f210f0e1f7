"""Shared by the learnt controller port's hostile tests (tests/
test_controller_port_attacks.py, tests/test_controller_port_attacks_sessions.py):
the cell's inputs and sensor, the check of every target anyone received,
summary.json's counts and the figures printed."""

import json
import os
import sys

import numpy as np
import pytest

sys.path.insert(0, os.path.dirname(__file__))
import cell_helpers as h  # noqa: E402

from robstiff_drake.cell.safety import clamp_deg  # noqa: E402
from robstiff_drake.model.robot import load_robot  # noqa: E402

T_MS = 4.0
T = T_MS / 1e3
FAR_DEG = np.array([30.0, 10.0, 10.0, 30.0, 20.0, 30.0])  # the stranger's pose: this far from the arm's
TAKE_UP_SILENCE_S = 0.6  # 6x port_switch_silence_s (0.1 s): a new session, whatever this machine's load
# the controller's address, and the start check's tolerance above the process force the cell fixture holds from the
# first message (707 N: the tool in the part at the start, as a user who must start in the cut sets it;
# cell/sensor_checks.py): these tests attack the controller's port, the correction nonzero as in a cut
CTRL = ["--controller", "127.0.0.1", "--start-tolerance-N", "1000"]


@pytest.fixture(scope="module")
def robot():
    return load_robot()


@pytest.fixture()
def cell(tmp_path, robot):
    """(model, payload, reference path, reference function deg, sensor, log folder)."""
    model, payload, ref, ref_fn = h.write_inputs(str(tmp_path), robot, duration_s=3.0)
    # the payload's weight and a process force (N, sensor frame) held from the start: a correction of a few
    # tenths of a degree once compensating, so that the targets differ from the reference as in a cut
    w = np.asarray(h.hold_wrench(robot, ref_fn(0.0))(0.0), dtype=float) + [500.0, -400.0, 300.0, 0.0, 0.0, 0.0]
    sensor = h.FakeSensor(lambda t: w)
    yield model, payload, ref, (lambda t: np.degrees(ref_fn(t))), sensor, str(tmp_path / "log")
    sensor.close()


def _summary(log):
    with open(os.path.join(log, "summary.json")) as f:
        return json.load(f)["cycles"]


class Checker:
    """Every target anyone received against the robot's working ranges and
    the reference at its cycle (the correction's clamp + the reference's
    motion over a period either side); ``worst_deg``: the largest deviation
    from the reference seen."""

    def __init__(self, robot, ref):
        self.lo, self.hi = np.degrees(robot.q_lower_rad), np.degrees(robot.q_upper_rad)
        self.clamp = clamp_deg(robot, 0.5)
        self.ref = ref
        self.worst_deg = 0.0
        self.n = 0

    def check(self, target, k, who):
        t = np.asarray(target, dtype=float)
        assert t.shape == (6,) and np.all(np.isfinite(t)), (who, k, target)
        assert np.all(t >= self.lo - 1e-6) and np.all(t <= self.hi + 1e-6), (who, k, target)
        r = self.ref(k * T)
        motion = np.abs(self.ref((k + 1) * T) - self.ref(max(k - 1, 0) * T))
        off = np.abs(t - r)
        assert np.all(off <= self.clamp + motion + 1e-5), (who, k, (off - self.clamp).max())
        self.worst_deg = max(self.worst_deg, float(off.max()))
        self.n += 1


def _report(name, **figures):
    """The attack's figures on stdout (pytest -s shows them; the report quotes them)."""
    print(f"\n[{name}] " + ", ".join(f"{k} = {v}" for k, v in figures.items()))


def exchange_while_answered(ctrl, ks, ref_deg):
    """[(k, answer)] of the controller's messages k in ``ks`` (sequence k + 1, clock k periods, the reference's
    angles at k periods), up to the first left unanswered (10 s: a hang guard, not a deadline)."""
    out = []
    for k in ks:
        got = ctrl.exchange(k + 1, k * T_MS, ref_deg(k * T), timeout_s=10.0)
        if got is None:
            break
        out.append((k, got))
    return out


def finish_with_stranger(proc, ctrl, stranger):
    """(exit status, stderr, what the stranger was ever answered, what the controller was answered after the
    script's last message): the run ended, both sockets closed."""
    try:
        code, err = h.finish(proc)
        return code, err, stranger.answers(), ctrl.answers()
    finally:
        ctrl.close()
        stranger.close()
