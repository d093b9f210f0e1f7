"""`robstiff sim-cell` stopped by a service manager (SIGTERM) or Ctrl-C
(SIGINT) while its controller streams: one line and the signal's exit
status, no traceback from its network thread (before: "ValueError: file
descriptor cannot be a negative integer (-1)" when the sockets closed under
the running thread)."""

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
                             "--wait-s", "60", "--lockstep", "--answer-timeout-s", f"{HANG_GUARD_S:g}"], cwd=ROOT,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    log = tmp_path / "log"
    comp = subprocess.Popen([sys.executable, "-m", "robstiff_drake", "compensate", "--listen-port", str(egm),
                             "--netft", f"127.0.0.1:{netft}", "--netft-http-port", str(netft), "--model", model,
                             "--payload", payload, "--reference", str(ref), "--wait-s", "60", "--idle-exit-s",
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


def _rows(path):
    """The data rows of a log CSV written so far (0 before it exists)."""
    if not path.exists():
        return 0
    return sum(1 for line in path.read_text().splitlines() if line[:1].isdigit())
