"""A controller whose cycle is not compensate's --period-ms (FANUC Stream
Motion's 8 ms against the default 4 ms): every message a clock fault, the
correction held at zero and the reference played at half the program's
speed for the whole run, and before this all the run said was one "clock
disagrees with its sequence" line at its start (a newcomer's M-20iD/25 pair:
health "about 0.0 % of the compensation lost", exit 0).  Now a line names
the controller's cycle and the --period-ms to set, once."""

import json
import os
import sys

import numpy as np
import pytest

pytest.importorskip("pynetft", reason="the cell tests need pynetft (pip install '.[test]')")
pytest.importorskip("abb_robot_client", reason="the cell tests need abb-robot-client (pip install '.[test]')")

sys.path.insert(0, os.path.dirname(__file__))
import cell_helpers as h  # noqa: E402

from robstiff_drake.model.robot import load_robot  # noqa: E402


def test_a_controller_at_another_cycle_is_named_with_the_period_to_set(tmp_path):
    robot = load_robot()
    model, payload, ref, ref_fn = h.write_inputs(str(tmp_path), robot, duration_s=3.0)
    sensor = h.FakeSensor(h.hold_wrench(robot, ref_fn(0.0)))
    port = h.free_udp_port()
    proc = h.start_compensate(model, payload, sensor, port, reference=ref, log=str(tmp_path / "log"))
    ctrl = h.ScriptedController(port)
    try:
        for k in range(0, 60):  # an 8 ms controller: its clock steps 8 ms a message; compensate runs at 4
            assert ctrl.exchange(k + 1, k * 8.0, np.degrees(ref_fn(k * 0.004))) is not None
        code, err = h.finish(proc, end=True)
    finally:
        ctrl.close()
        sensor.close()
    assert code == 0, err
    said = [ln for ln in err.splitlines() if "--period-ms is not the controller's cycle" in ln]
    assert len(said) == 1, err  # once a run
    assert "stepped 8 ms a message" in said[0] and "--period-ms 4 says 4" in said[0]
    assert "plays at 0.50 times" in said[0] and "with --period-ms 8 " in said[0]
    # and the run's health says it compensated nothing (before: "about 0.0 % ... lost")
    health = json.loads((tmp_path / "log" / "summary.json").read_text())["health"]
    assert health["verdict"] == "poor" and health["compensation_lost_fraction"] > 0.9, health


def test_a_run_that_computed_no_correction_under_a_fault_is_counted_lost():
    """The health's estimate when a fault held the correction at zero from the
    first message (the run above: no correction ever computed): the share of
    the cycles lost, not 0 % (before: 'about 0.0 % of the compensation lost')."""
    from robstiff_drake.cell.health import LostEstimate, verdict

    held = LostEstimate()
    for _ in range(100):
        held.add(0.0, True, held=True)
    assert held.fraction() == 1.0
    word, _, line = verdict(cycles=100, answered=100, late=0, unanswered=0, faults=1, lost_fraction=held.fraction())
    assert word == "poor" and "about 100.0 % of the compensation lost" in line
    quiet = LostEstimate()  # no fault, no force: nothing to lose, late answers or not
    for k in range(100):
        quiet.add(0.0, k % 10 == 0)
    assert quiet.fraction() == 0.0
    weighted = LostEstimate()  # a correction computed: weighted by its size, as before
    weighted.add(1.0, False)
    weighted.add(3.0, True)
    assert weighted.fraction() == 0.75
