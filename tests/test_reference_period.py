"""The joint reference `robstiff sim-cell --reference-out` (and `simulate`,
`compensate-program`) writes is on the controller's cycle, so `robstiff
compensate --period-ms` at that cycle takes it: a FANUC Stream Motion cell at
8 ms (the R-2000iC/165F block-milling scenario with controller.period_ms 8).
Before, the reference was written at path.reference_period_ms (4 ms) whatever
the controller's cycle, and compensate --period-ms 8 refused its second row
("rows must be at least the controller period (0.008 s) apart"), naming
neither the file's 4 ms nor what to set.  No pair, no timing: the writer and
compensate's input check."""

import os

import numpy as np
import pytest

from cell_helpers import ROOT
from robstiff_drake.commands.compensate_inputs import read_reference
from robstiff_drake.diagrams.cell_station import CellStation
from robstiff_drake.diagrams.milling_cell import planned_path
from robstiff_drake.diagrams.scenario import load_scenario, scenario_robot
from robstiff_drake.errors import InputError

FANUC = os.path.join(ROOT, "diagrams", "block_milling_r2000ic_165f.yaml")


@pytest.fixture(scope="module")
def stream_motion_reference(tmp_path_factory):
    """(robot, planned times s, planned q rad, the file sim-cell writes): the
    scenario at 8 ms, the station's reference writer without its Drake build."""
    text = open(FANUC).read()
    assert "\ncontroller:\n  period_ms: 4.0\n" in text and "reference_period_ms: 4.0" in text
    folder = tmp_path_factory.mktemp("stream_motion")
    scenario = folder / "r2000ic_165f_8ms.yaml"
    scenario.write_text(text.replace("\ncontroller:\n  period_ms: 4.0\n", "\ncontroller:\n  period_ms: 8.0\n"))
    sc = load_scenario(str(scenario))
    robot = scenario_robot(sc)
    station = CellStation.__new__(CellStation)  # reference_csv needs only these (sim-cell's period: the scenario's)
    station.sc, station.robot, station.T = sc, robot, sc.controller.period_ms / 1e3
    _, station.t_ref, station.q_ref = planned_path(sc, robot, robot.tool_point(where="sim-cell"))
    out = folder / "joint_reference.csv"
    out.write_text(station.reference_csv())
    return robot, np.asarray(station.t_ref), np.asarray(station.q_ref), out


def test_sim_cells_reference_is_taken_by_compensate_at_the_controllers_8_ms(stream_motion_reference):
    robot, t_plan, q_plan, out = stream_motion_reference
    assert np.diff(t_plan).min() == pytest.approx(0.004)  # the path planned every 4 ms
    t, q = read_reference(out, robot, period_s=0.008)  # before: InputError on the file's second row
    assert np.diff(t) == pytest.approx(0.008)
    assert t[-1] >= t_plan[-1] - t_plan[0]  # the whole path, ending where it ends
    assert np.degrees(q[-1]) == pytest.approx(robot.controller_deg(q_plan[-1]), abs=1e-9)
    mid = len(t) // 2  # a row between the plan's: on the plan's line (linear, as compensate plays it)
    expected = [np.interp(t[mid] + t_plan[0], t_plan, robot.controller_deg(q_plan)[:, j]) for j in range(6)]
    assert np.degrees(q[mid]) == pytest.approx(expected, abs=1e-9)
    assert "resampled on the controller's cycle, 8 ms" in out.read_text()


def test_a_reference_finer_than_period_ms_is_refused_naming_both_periods_and_what_to_set(stream_motion_reference):
    robot, _, _, out = stream_motion_reference
    with pytest.raises(InputError) as refused:
        read_reference(out, robot, period_s=0.016)
    said = str(refused.value)
    assert "is 8 ms after the previous row, finer than --period-ms 16" in said, said
    assert "controller.period_ms: set it to 16" in said and "run with --period-ms 8" in said, said
    assert "\n" not in said


def test_a_reference_at_the_cycle_or_coarser_is_written_as_it_is():
    from robstiff_drake.identification.runs.logs import on_controller_period

    t = np.arange(0.0, 1.0, 0.008)
    q = np.column_stack([t] * 6)
    same_t, same_q = on_controller_period(t, q, 0.008)
    assert np.array_equal(same_t, t) and np.array_equal(same_q, q)
    t4, q4 = on_controller_period(t, q, 0.004)  # finer controller: untouched
    assert np.array_equal(t4, t)


def test_a_jobs_path_planned_finer_than_period_ms_names_the_jobs_key_to_set(tmp_path):
    """compensate --job: the job's planned path (path.reference_period_ms 4)
    at --period-ms 8 is refused naming the job's key (the message of a
    --reference file, "sim-cell and simulate write it...", does not apply)."""
    from robstiff_drake.cell.preview_job import job_reference

    sc = load_scenario(FANUC)
    robot = scenario_robot(sc)
    with pytest.raises(InputError) as refused:
        job_reference(sc, robot, None, job=FANUC, reference=None, read_reference=None, period_s=0.008,
                      filter_ba=None, rate_hz=None, delay_steps=None, servo=None)
    said = str(refused.value)
    assert said.startswith(f"--job {FANUC} (its planned path)"), said
    assert "finer than --period-ms 8" in said and "set the job's path.reference_period_ms to 8" in said, said
    assert "sim-cell" not in said and "run with --period-ms 4" in said, said
