"""`robstiff sim-cell` stopped by a service manager (SIGTERM) or Ctrl-C
(SIGINT) while its controller streams: one line and the signal's exit
status, no traceback from its network thread (before: "ValueError: file
descriptor cannot be a negative integer (-1)" when the sockets closed under
the running thread).  And a pair of sim-cell and compensate whose processes
the machine stalls (SIGSTOP, SIGCONT) runs to the pass's end."""

import os
import signal
import subprocess
import sys
import time

import pytest

pytest.importorskip("pynetft", reason="the cell tests need pynetft (pip install '.[test]')")
pytest.importorskip("abb_robot_client", reason="the cell tests need abb-robot-client (pip install '.[test]')")

sys.path.insert(0, os.path.dirname(__file__))
from cell_helpers import HANG_GUARD_S, ROOT, free_udp_port  # noqa: E402

SHORT = os.path.join(ROOT, "tests", "data", "short_block.yaml")


@pytest.mark.parametrize("sig, status, word", [(signal.SIGTERM, 143, "terminated"), (signal.SIGINT, 130, "interrupted")])
def test_sim_cell_stops_on_a_signal_without_a_traceback(tmp_path, sig, status, word):
    """... with a compensator engaged (the station stepping in the network
    thread; before: SIGINT aborted the process, exit -6, "terminate called
    without an active exception", Drake's simulator torn down mid-step)."""
    from cell_helpers import write_inputs
    from robstiff_drake.model.robot import load_robot

    model, payload, _, _ = write_inputs(str(tmp_path), load_robot(), duration_s=0.1)
    ref = tmp_path / "ref.csv"
    egm, netft = free_udp_port(), free_udp_port()
    # neither side ends on a short silence of the other (a process descheduled for a second on a loaded machine:
    # before, compensate's --idle-exit-s 1 ended it and the lockstep cell then stopped for want of an answer,
    # before the signal): the cell by the test's signal, compensate by the test once the cell has ended
    cell = subprocess.Popen([sys.executable, "-m", "robstiff_drake", "sim-cell", SHORT, "--egm-to",
                             f"127.0.0.1:{egm}", "--netft-port", str(netft), "--reference-out", str(ref),
                             "--wait-s", f"{HANG_GUARD_S * 5:g}", "--lockstep", "--answer-timeout-s",
                             f"{HANG_GUARD_S:g}"], cwd=ROOT,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    log = tmp_path / "log"
    comp = subprocess.Popen([sys.executable, "-m", "robstiff_drake", "compensate", "--listen-port", str(egm),
                             "--netft", f"127.0.0.1:{netft}", "--netft-http-port", str(netft), "--model", model,
                             "--payload", payload, "--reference", str(ref), "--wait-s", f"{HANG_GUARD_S * 5:g}",
                             "--idle-exit-s",
                             f"{HANG_GUARD_S:g}", "--delay-steps", "0", "--log", str(log)], cwd=ROOT,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        # the compensator engaged, the station stepping: its joint log holds a second of answers (250 rows; the
        # log hands its rows over every half second), whatever this machine's pace (before: a 3 s sleep)
        t0 = time.monotonic()
        while _rows(log / "joint_log.csv") < 250 and cell.poll() is None and comp.poll() is None \
                and time.monotonic() - t0 < HANG_GUARD_S * 3:
            time.sleep(0.1)
        assert ref.exists() and _rows(log / "joint_log.csv") >= 250, (cell.poll(), comp.poll())
        assert cell.poll() is None
        cell.send_signal(sig)
        out, err = cell.communicate(timeout=60)
    finally:
        if cell.poll() is None:
            cell.kill()
        comp.send_signal(signal.SIGTERM)  # (what it says is not this test's)
        comp.communicate(timeout=60)
    assert "Traceback" not in err and "terminate called" not in err, err
    assert cell.returncode == status, (cell.returncode, err)
    assert f"robstiff: {word}" in err, err


def test_a_stalled_cell_or_compensator_does_not_end_the_pair(tmp_path):
    """The machine stalls each process of the lockstep pair for 1.5 s mid-pass (SIGSTOP, then SIGCONT: a loaded
    machine deschedules a process that long): first sim-cell, the controller (compensate says it is silent, then
    that its messages came again), then compensate (sim-cell waits for its answer).  The pass runs to its end,
    every message answered, and the pair ends as the test says (before: compensate's --idle-exit-s 1 ended it in
    the first stall and sim-cell stopped for want of an answer, exit 3; sim-cell's 1 s answer timeout stopped it
    in the second).  (Lockstep and deliberate stalls: no real-time test, it runs with the rest.)"""
    import json

    from cell_helpers import write_inputs
    from robstiff_drake.model.robot import load_robot
    from test_sim_cell import _run_pair

    model, payload, _, _ = write_inputs(str(tmp_path), load_robot())
    log = tmp_path / "log"
    stalled = []

    def stall(cell, comp):
        for who, proc, after_rows in (("sim-cell", cell, 150), ("compensate", comp, 400)):
            t_end = time.monotonic() + HANG_GUARD_S * 5
            while _rows(log / "joint_log.csv") < after_rows and proc.poll() is None and time.monotonic() < t_end:
                time.sleep(0.05)  # (0.6 s and 1.6 s of the controller's clock: the log's rows, 4 ms apart)
            if proc.poll() is not None:
                return
            proc.send_signal(signal.SIGSTOP)
            time.sleep(1.5)
            proc.send_signal(signal.SIGCONT)
            stalled.append((who, _rows(log / "joint_log.csv")))

    cell, comp, out = _run_pair(tmp_path, model, payload, lockstep=True, during=stall)
    assert [w for w, _ in stalled] == ["sim-cell", "compensate"], (stalled, cell.stderr, comp.stderr)
    assert cell.returncode == 0, (cell.stderr, comp.stderr)
    assert comp.returncode == 0, comp.stderr
    res = json.loads(out.read_text())
    assert res["stopped"] is None and res["surface_error_mm"] is not None and res["unanswered"] == 0, res
    err = comp.stderr
    assert err.index("no message from the controller for") < err.index("EGM: messages again"), err  # the 1st stall
    summary = json.loads((log / "summary.json").read_text())
    assert summary["cycles"]["ended_by"] == "interrupt" and "terminated: the run ends" in err, summary["cycles"]
    print("stalled (process, the log's rows then):", stalled, "; cycles", res["cycles"], "answered", res["answered"])


def _rows(path):
    """The data rows of a log CSV written so far (0 before it exists)."""
    if not path.exists():
        return 0
    return sum(1 for line in path.read_text().splitlines() if line[:1].isdigit())
