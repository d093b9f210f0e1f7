"""`robstiff sim-cell`'s health on a pass the arm did not travel: every
answer fresh, but targets that leave the path's reference (a compensator
holding the start pose; one playing the reference at half speed, as a
--period-ms that is not the controller's cycle makes it).  Before: "health
GOOD", exit 0 (1063 fresh answers, the arm never moved along the short
block's pass).  Now: poor, a line saying where the arm left the path, exit 3
(cell/pass_check.py)."""

import json
import os
import subprocess
import sys

import numpy as np
import pytest

pytest.importorskip("pynetft", reason="the cell tests need pynetft (pip install '.[test]')")
pytest.importorskip("abb_robot_client", reason="the cell tests need abb-robot-client (pip install '.[test]')")

sys.path.insert(0, os.path.dirname(__file__))
from cell_helpers import HANG_GUARD_S, ROOT, free_udp_port  # noqa: E402

from robstiff_drake.cell.pass_check import FOLLOW_TOL_DEG, left_path  # noqa: E402

SHORT = os.path.join(ROOT, "tests", "data", "short_block.yaml")


def _path():
    """A path of 4 s at 4 ms moving q2 by 12 deg and q3 by -14 deg (the short block's pass, in shape)."""
    t = np.arange(0, 4.0 + 1e-9, 0.004)
    q = np.zeros((len(t), 6))
    q[:, 1], q[:, 2] = 8.0 + 3.0 * t, 28.5 - 3.5 * t
    return t, q


def test_targets_that_follow_the_path_with_a_correction_and_a_lag_pass():
    t, q = _path()
    lagged = np.vstack([q[:1], q[:1], q[:-2]]) + 0.5 * np.sin(t)[:, None]  # (two periods late, 0.5 deg corrections)
    assert left_path(t, lagged, t, q) is None
    assert left_path(t + 0.1, q[-1:].repeat(len(t), axis=0), t, q) is not None  # (the end pose from the start)


def test_targets_held_at_the_start_or_at_half_speed_leave_the_path_and_say_where():
    t, q = _path()
    held = left_path(t, q[:1].repeat(len(t), axis=0), t, q)
    assert held is not None and held[2] == 2 and held[3] == 0.0, held  # q3 first, 2 deg after 0.57 s
    assert abs(held[0] - FOLLOW_TOL_DEG / 3.5) < 0.01 and held[1] > FOLLOW_TOL_DEG
    half = left_path(t, q[np.arange(len(t)) // 2], t, q)  # (the reference at half speed)
    assert half is not None and abs(half[0] - 2 * FOLLOW_TOL_DEG / 3.5) < 0.01 and abs(half[3] - 2.0) < 0.01, half


def test_sim_cell_is_not_good_when_the_arm_never_travels_the_pass(tmp_path):
    from test_cell_io import _AnsweringCompensator

    first = []
    comp = _AnsweringCompensator(lambda k, q: (first.append(q) or first[0]))  # every answer fresh: the start pose
    out = tmp_path / "cell.json"
    try:
        cell = subprocess.run([sys.executable, "-m", "robstiff_drake", "sim-cell", SHORT, "--egm-to",
                               f"127.0.0.1:{comp.port}", "--netft-port", str(free_udp_port()), "--json", str(out),
                               "--wait-s", f"{HANG_GUARD_S:g}", "--lockstep"],
                              cwd=ROOT, capture_output=True, text=True, timeout=HANG_GUARD_S * 10)
    finally:
        comp.close()
    err = cell.stderr
    assert cell.returncode == 3, err  # (before: 0)
    assert "Traceback" not in err, err
    res = json.loads(out.read_text())
    assert res["unanswered"] == 0 and res["late"] == 0 and res["stopped"] is None, res  # every answer fresh
    assert res["health"]["verdict"] == "poor", res["health"]  # (before: good)
    assert "the arm did not travel the pass" in res["health"]["line"] and "reference's of t = 0.00 s" in err, err
    assert res["pass_left_path"]["joint"] in (2, 3), res["pass_left_path"]
