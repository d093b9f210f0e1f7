"""The bound on what the correction moves the tool by (cell/correction_bound.py,
compensate's --max-correction-mm and --max-correction-deg): a sensor scaled
wrong (a wrong unit, a force growing past any cut) is a fault, the correction
ramps to zero at the rate limit and no target beyond the bound is sent; a
normal run is unchanged; bad values of the options are refused.

The loop runs over a real EgmLink with its messages and the sensor's records
handed over by script on a clock the test sets (test_cell_review_loop.py's
helpers): no timing."""

import io
import math
import os
import subprocess
import sys

import numpy as np
import pytest

sys.path.insert(0, os.path.dirname(__file__))
import cell_helpers as h  # noqa: E402
from test_cell_review_loop import (Q0, RATE_DEG_PER_S, T, _messages, _run_scripted, _ScriptedEgm,  # noqa: E402
                                   _ScriptedSensor, scripted_clock)

from robstiff_drake.cell.correction_bound import CorrectionBound, shrink, start_note  # noqa: E402
from robstiff_drake.model import kinematics as kin  # noqa: E402
from robstiff_drake.model.robot import load_robot  # noqa: E402

MAX_MM, MAX_DEG = 5.0, 0.5  # compensate's defaults


@pytest.fixture(scope="module")
def robot():
    return load_robot()


def _drive(robot, n, wrench_at, *, max_mm=MAX_MM, max_deg=MAX_DEG, initial=None, settings=None):
    """The loop over ``n`` messages holding Q0, the sensor reading ``wrench_at(seq)`` (N, N*m, 6) for each;
    returns (loop, the poses the controller was told, deg).  ``settings``: the loop's LoopSettings as given
    (default: the moment guard at 350 N*m and the bound ``max_mm``, ``max_deg``)."""
    from robstiff_drake.cell.compensate import CompensatorLoop, LoopSettings, Reference

    clock = scripted_clock()
    script = _messages(n, Q0)
    link = _ScriptedEgm(script[1:], clock)
    sensor = _ScriptedSensor(wrench_at(1), clock, lambda seq: [wrench_at(max(seq, 1))])
    ref = Reference(period_s=T)
    ref.hold(Q0)
    comp = h.hold_compensator(robot, wrench_at(1) if initial is None else initial)
    if settings is None:
        # (the push held from the first message: the start's check against the payload calibration off,
        # explicitly; its tests: tests/test_sensor_checks.py, tests/test_sensor_attacks.py; the sensor's rate is
        # the script's, one record a message)
        settings = LoopSettings(max_jump_Nm=350.0, max_correction_mm=max_mm, max_correction_deg=max_deg,
                                start_tolerance_N=math.inf, sensor_rate_hz=1.0 / T)
    loop = CompensatorLoop(comp, link.link, sensor, ref, robot, settings, out=io.StringIO())
    _run_scripted(loop, link, sensor, script, clock)
    return loop, np.array(link.commanded)


def _tool_motion(robot, poses_deg):
    """Per pose: the tool point's distance (mm) and the tool's rotation (deg) from the reference's (Q0), by
    forward kinematics (not the loop's Jacobian: an independent check)."""
    tool = robot.payload.tool_point_m
    to_model = lambda q: robot.joint_map.to_model(np.radians(q))  # noqa: E731
    T0 = kin.tool_pose(robot.dh, to_model(np.asarray(Q0)), tool)
    Ts = kin.tool_pose(robot.dh, to_model(poses_deg), tool)
    d_mm = np.linalg.norm(Ts[:, :3, 3] - T0[:3, 3], axis=1) * 1e3
    R = np.einsum("ji,njk->nik", T0[:3, :3], Ts[:, :3, :3])
    rot_deg = np.degrees(np.arccos(np.clip((np.trace(R, axis1=1, axis2=2) - 1.0) / 2.0, -1.0, 1.0)))
    return d_mm, rot_deg


def _hold(robot):
    return np.asarray(h.hold_wrench(robot, np.radians(Q0))(0.0))


def test_a_sensor_in_the_wrong_unit_is_the_bound_fault_and_nothing_beyond_it_is_sent(robot):
    """Every record 100 times what the sensor should read (N*mm read as N*m, say): the model asks the clamp on
    every joint (tens of mm at the tool); the bound's fault at once, one line, counted; no pose beyond it."""
    w = (_hold(robot) + [300.0, -200.0, 0.0, 0.0, 0.0, 0.0]) * 100.0
    loop, poses = _drive(robot, 80, lambda seq: w.tolist())
    said = loop.out.getvalue()
    assert said.count("correction bound:") == 1, said
    assert "the correction ramps to zero" in said
    assert "bound" in loop.faults  # (still: the model's wish stays beyond it)
    s = loop.stats()["correction_bound"]
    assert s["faults"] == 1 and s["cycles_beyond"] > 50, s
    assert s["largest_sent_mm"] <= MAX_MM
    d_mm, rot_deg = _tool_motion(robot, poses)
    assert len(poses) >= 79
    assert d_mm.max() <= MAX_MM and rot_deg.max() <= MAX_DEG, (d_mm.max(), rot_deg.max())


def test_a_force_growing_past_any_cut_ramps_the_correction_to_zero(robot):
    """A cut's push for 60 messages (the correction ramped in: about 3 mm at the tool), then a force that grows
    by 0.2 of it a message (a sensor's gain running away; each step inside the guard's 1000 N): the model's
    correction crosses the bound, the fault's line, and from there the correction only shrinks, at the rate
    limit, to zero; no pose beyond the bound; the model's own clamp would have allowed far more."""
    push = np.array([900.0, -600.0, 0.0, 0.0, 0.0, 0.0])
    n_good = 60

    def wrench(seq):
        return (_hold(robot) + push * (1.0 + 0.2 * max(0, seq - n_good))).tolist()

    loop, poses = _drive(robot, 200, wrench)
    d_mm, rot_deg = _tool_motion(robot, poses)
    assert d_mm[n_good - 1] > 1.0, "the correction had ramped in before the force grew"
    assert d_mm.max() <= MAX_MM + 1e-6 and rot_deg.max() <= MAX_DEG, (d_mm.max(), rot_deg.max())
    said = loop.out.getvalue()
    assert said.count("correction bound:") == 1, said
    corr = poses - np.asarray(Q0)
    size = np.abs(corr).max(axis=1)
    peak = int(np.argmax(size))
    assert peak > n_good
    assert np.all(np.diff(size[peak:]) <= 1e-12), size[peak:]  # from the fault on it only shrinks
    assert size[-1] == 0.0
    step = np.abs(np.diff(poses, axis=0)).max()
    assert step <= RATE_DEG_PER_S * 2.0 * T + 1e-9, step  # (MAX_STEP_PERIODS: never a jump)
    # the shrink is in proportion: the correction's direction kept while it ramps down
    ramp = corr[peak:][size[peak:] > 0.01]
    cos = (ramp @ ramp[0]) / (np.linalg.norm(ramp, axis=1) * np.linalg.norm(ramp[0]))
    assert cos.min() > 0.999, cos.min()
    # without the bound the same run commands far more than the bound (the test can fail)
    _, free = _drive(robot, 200, wrench, max_mm=math.inf, max_deg=math.inf)
    assert _tool_motion(robot, free)[0].max() > 2 * MAX_MM


def test_a_library_users_loop_settings_bound_the_correction_as_compensate_does(robot):
    """LoopSettings built with no bound given (a library user's, not the command's): the command's bound and
    moment guard, from the same constants as compensate's options (before: inf, none; the sensor in the wrong
    unit then moved the tool 30 mm); math.inf turns each off, explicitly; a bound not above zero is refused."""
    from robstiff_drake.cell.compensate import LoopSettings
    from robstiff_drake.commands.parser import build_parser

    args = build_parser().parse_args(["compensate", "--egm-port", "1", "--netft", "127.0.0.1:1", "--model", "m.json",
                                      "--payload", "p.yaml"])
    s = LoopSettings()
    assert (s.max_correction_mm, s.max_correction_deg) == (args.max_correction_mm, args.max_correction_deg)
    assert (s.max_correction_mm, s.max_correction_deg) == (MAX_MM, MAX_DEG)
    w = (_hold(robot) + [300.0, -200.0, 0.0, 0.0, 0.0, 0.0]) * 100.0  # (the wrong unit: N*mm read as N*m)
    # LoopSettings() checks the sensor's start against the payload calibration too: the wrong unit from the first
    # message is that fault, the correction zero throughout
    loop, poses = _drive(robot, 80, lambda seq: w.tolist(), settings=LoopSettings())
    assert "sensor start" in loop.faults and np.abs(poses - np.asarray(Q0)).max() == 0.0, loop.out.getvalue()
    # and with that check off, the bound
    loop, poses = _drive(robot, 80, lambda seq: w.tolist(), settings=LoopSettings(start_tolerance_N=math.inf))
    d_mm, rot_deg = _tool_motion(robot, poses)
    assert "bound" in loop.faults and d_mm.max() <= MAX_MM and rot_deg.max() <= MAX_DEG, (d_mm.max(), rot_deg.max())
    off = LoopSettings(max_correction_mm=math.inf, max_correction_deg=math.inf, start_tolerance_N=math.inf)
    loop_off, free = _drive(robot, 80, lambda seq: w.tolist(), settings=off)
    d_off = _tool_motion(robot, free)[0].max()
    print(f"the wrong unit's tool motion: {d_mm.max():.2f} mm with LoopSettings() (bounded), {d_off:.2f} mm with "
          "the bound off (the old default)")
    assert loop_off.bound is None and d_off > 4 * MAX_MM
    # the moment guard: compensate's default (--max-jump-N at the tool point's lever, at least 0.1 m), not none
    lever_m = max(float(np.linalg.norm(robot.payload.tool_point_m)), 0.1)
    assert loop.s.max_jump_Nm == pytest.approx(1000.0 * lever_m) and LoopSettings().max_jump_Nm is None
    for bad in (dict(max_correction_mm=0.0), dict(max_correction_deg=-1.0), dict(max_correction_mm=math.nan),
                dict(max_jump_Nm=0.0), dict(max_correction_mm="5")):
        with pytest.raises(ValueError, match=next(iter(bad))):
            LoopSettings(**bad)


def test_the_default_moment_guard_refuses_a_moment_spike(robot):
    """A record whose moment jumps 2000 N*m (a spike: the force unchanged) among good ones, LoopSettings() as a
    library user builds it: refused and counted (before: the moment guard's default was inf, so it reached the
    filter)."""
    from robstiff_drake.cell.compensate import LoopSettings

    good = _hold(robot) + [300.0, -200.0, 0.0, 0.0, 0.0, 0.0]
    spike = good + [0.0, 0.0, 0.0, 2000.0, 0.0, 0.0]
    loop, _ = _drive(robot, 40, lambda seq: (spike if seq == 20 else good).tolist(), settings=LoopSettings())
    assert loop.n.moment_spikes == 1, loop.out.getvalue()
    assert "a moment jumped more than" in loop.out.getvalue()


def test_the_fault_ends_once_the_model_is_inside_the_bound_again(robot):
    """The wrong force for 40 messages, then the right one: the correction at zero and the model's wish inside the
    bound for 25 messages: the fault's end is logged and the correction ramps in again."""
    good = _hold(robot) + [300.0, -200.0, 0.0, 0.0, 0.0, 0.0]
    bad_until = 40

    def wrench(seq):
        return (good * (1.0 + 0.2 * seq) if seq <= bad_until else good).tolist()  # (steps inside the guard)

    loop, poses = _drive(robot, 160, wrench, initial=good.tolist())
    said = loop.out.getvalue()
    assert "correction bound:" in said and "compensating again" in said, said
    assert "bound" not in loop.faults
    assert np.abs(poses[-1] - np.asarray(Q0)).max() > 0.01  # compensating at the end


def test_a_normal_run_is_unchanged_by_the_bound(robot):
    """A cut's push well inside the bound: the same poses to the last bit with the bound as without; no fault."""
    w = (_hold(robot) + [300.0, -200.0, 0.0, 0.0, 0.0, 0.0]).tolist()
    loop, poses = _drive(robot, 80, lambda seq: w)
    _, free = _drive(robot, 80, lambda seq: w, max_mm=math.inf, max_deg=math.inf)
    assert not loop.faults and "correction bound" not in loop.out.getvalue()
    assert np.abs(poses[-1] - np.asarray(Q0)).max() > 0.01  # (compensating: 0.017 deg on q3)
    assert np.array_equal(poses, free)
    s = loop.stats()["correction_bound"]
    assert s["faults"] == 0 and 0.1 < s["largest_sent_mm"] < MAX_MM, s


def test_the_jacobian_bound_agrees_with_forward_kinematics(robot):
    """J c against the forward kinematics of reference + c, at a correction near the bound (the linearisation's
    rest well inside the bound's margin)."""
    from robstiff_drake.model.realtime import DeflectionPredictor

    tool = robot.payload.tool_point_m
    pred = DeflectionPredictor(robot.dh, robot.joint_stiffness_Nm_per_rad, tool)
    q = robot.joint_map.to_model(np.radians(Q0))
    c = np.radians([0.05, -0.1, 0.15, 0.1, -0.2, 0.1])
    d_m, r_rad = CorrectionBound(pred, MAX_MM, MAX_DEG).displacement(q.tolist(), c.tolist())
    fk = np.linalg.norm(kin.tool_position(robot.dh, q + c, tool) - kin.tool_position(robot.dh, q, tool))
    assert 1.0e-3 < d_m < 10e-3
    assert abs(d_m - fk) < 0.01 * fk, (d_m, fk)
    assert 0.0 < r_rad


def test_shrink_keeps_the_direction_and_the_rate():
    c = [0.01, -0.005, 0.0, 0.002, 0.0, 0.0]
    s = shrink(c, 0.001)
    assert abs(s[0] - 0.009) < 1e-15 and abs(s[1] / s[0] - (-0.5)) < 1e-12
    assert shrink(c, 0.02) == [0.0] * 6


def test_the_start_note_warns_when_a_hard_cut_would_be_stopped(robot):
    from robstiff_drake.model.realtime import DeflectionPredictor

    pred = DeflectionPredictor(robot.dh, robot.joint_stiffness_Nm_per_rad, robot.payload.tool_point_m)
    to_model = lambda q: robot.joint_map.to_model(np.radians(q))  # noqa: E731
    rows = np.array([Q0, Q0])
    assert start_note(pred, rows, to_model, 1000.0, MAX_MM, MAX_DEG, "the reference") is None
    line = start_note(pred, rows, to_model, 1000.0, 1.0, MAX_DEG, "the reference")
    assert line and "--max-correction-mm 1" in line and "row 1" in line


@pytest.mark.parametrize("option,value", [("--max-correction-mm", "0"), ("--max-correction-mm", "-3"),
                                          ("--max-correction-mm", "nan"), ("--max-correction-mm", "500"),
                                          ("--max-correction-deg", "0"), ("--max-correction-deg", "inf"),
                                          ("--max-correction-deg", "x")])
def test_bad_values_of_the_options_are_refused_in_one_line(tmp_path, option, value):
    cmd = [sys.executable, "-m", "robstiff_drake", "compensate", "--egm-port", "1", "--netft", "127.0.0.1:1",
           "--model", str(tmp_path / "m.json"), "--payload", str(tmp_path / "p.yaml"), option, value]
    cp = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert cp.returncode == 2, cp.stderr
    lines = [x for x in cp.stderr.splitlines() if x.strip()]
    assert len(lines) == 1 and option in lines[0], cp.stderr
    assert "Traceback" not in cp.stderr
