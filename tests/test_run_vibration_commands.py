"""The run's own vibration check (diagrams/run_vibration.py, `robstiff
simulate`'s) in `sweep`, `demo` and `sim-cell`: a cut that chatters
(tests/data/short_regenerative.yaml: the paper's block at the paper's
forces with the regenerative chip, a short path) gets simulate's warning
in the text (standard error) and in the JSON's warnings, and `vibration`
in the JSON; a default scenario (tests/data/short_block.yaml) gets its
`vibration` and no warning (also asserted in tests/test_sweep.py's and
tests/test_cli.py's runs of the default scenarios)."""

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from cell_helpers import ROOT, free_udp_port
from robstiff_drake.commands.main import main
from robstiff_drake.diagrams.run_vibration import PREFIX

REGEN = Path(__file__).parent / "data" / "short_regenerative.yaml"
SHORT = Path(__file__).parent / "data" / "short_block.yaml"
PLANE = "in the plane normal to the spindle axis"


def vibrated(v):
    """The run's vibration exceeds its feed per tooth (the warning's rule), by far."""
    return v is not None and v["amplitude_um"] > 3.0 * v["feed_per_tooth_um"]


def test_sweep_warns_of_a_run_that_vibrated(capsys, tmp_path):
    out = tmp_path / "sweep.json"
    code = main(["sweep", str(REGEN), "--period-ms", "4", "--workers", "1", "--no-predict", "--json", str(out)])
    _, err = capsys.readouterr()
    assert code == 0, err
    res = json.loads(out.read_text())
    (row,) = res["runs"]
    v = row["vibration"]
    print("sweep, short_regenerative:", {k: v[k] for k in ("amplitude_um", "axial_um", "frequency_hz", "onset_mm")})
    assert vibrated(v) and v["onset_t_s"] is not None, v
    assert v["spindle_axis"] == pytest.approx([0.0, 0.0, -1.0], abs=0.01)
    (line,) = [w for w in res["warnings"] if PREFIX in w]
    assert line.startswith(f"compensated (period 4 ms, delay 1, cutoff 5 Hz, plain): {PREFIX}: "
                           f"{v['amplitude_um']:.0f} um at "), line
    assert PLANE in line and "the regenerative chip: chatter" in line, line
    assert f"robstiff: warning: {line}" in err


def test_demo_warns_of_each_run_that_vibrated(capsys, tmp_path, monkeypatch):
    """The demo's block test replaced by the chattering one: its three runs (uncompensated, compensated, the exact
    model's bound) each warn, in demo.json and on standard error."""
    from robstiff_drake.commands import demo

    monkeypatch.setattr(demo, "block_scenario", lambda robot_yaml=None: REGEN)
    assert main(["demo", "--out", str(tmp_path)]) == 0
    _, err = capsys.readouterr()
    rep = json.loads((tmp_path / "demo.json").read_text())
    assert set(rep["vibration"]) == {"uncompensated", "compensated", "exact model"}
    print("demo, short_regenerative:", {k: round(v["amplitude_um"], 1) for k, v in rep["vibration"].items()})
    for name, v in rep["vibration"].items():
        assert vibrated(v), (name, v)
        (line,) = [w for w in rep["warnings"] if w.startswith(f"{name}: {PREFIX}: ")]
        assert PLANE in line and f"robstiff: warning: {line}" in err


def _reference(path):
    lines = [line for line in path.read_text().splitlines() if not line.startswith("#")]
    return np.array([[float(v) for v in line.split(",")] for line in lines[1:]])


@pytest.mark.parametrize("scenario, warns", [(REGEN, True), (SHORT, False)], ids=["regenerative", "default"])
def test_sim_cell_checks_the_vibration_of_its_cut(tmp_path, scenario, warns):
    """sim-cell in lockstep against a stand-in compensator that answers each message with the path's reference
    (no correction): its cut, from the link angles its station logs once per cycle, warns when it chatters."""
    from test_cell_io import _AnsweringCompensator

    ref, out = tmp_path / "reference.csv", tmp_path / "cell.json"
    period_s, answered = 0.004, []

    def answer(k, feedback_deg):
        if not ref.exists():
            return None
        if not answered:
            answered.append(_reference(ref))
        table = answered[0]
        t = period_s * (len(answered))  # the station's clock after this answer's cycle
        answered.append(None)
        return [float(np.interp(t, table[:, 0], table[:, j])) for j in range(1, 7)]

    # (newest only: a stall of this thread before the cell engaged left messages queued, and answering each in
    # turn ran this clock ahead of the cell's by the stall: the controller refused the jump, no face was cut)
    comp = _AnsweringCompensator(answer, newest_only=True)
    try:
        cell = subprocess.run([sys.executable, "-m", "robstiff_drake", "sim-cell", str(scenario), "--egm-to",
                               f"127.0.0.1:{comp.port}", "--netft-port", str(free_udp_port()), "--reference-out",
                               str(ref), "--json", str(out), "--wait-s", "60", "--lockstep",
                               # (the stand-in compensator is a thread of this process: a second's stall of it on a
                               # loaded machine is no end of the run; sim-cell's default waits 1 s for an answer)
                               "--answer-timeout-s", "60"],
                              cwd=ROOT, capture_output=True, text=True, timeout=600,
                              env=dict(os.environ, PYTHONUNBUFFERED="1"))
    finally:
        comp.close()
    err = cell.stderr
    assert "Traceback" not in err, err
    res = json.loads(out.read_text())
    v = res["vibration"]
    # (no vibration: nothing was cut; seen once at load 9, issue 32: sim-cell's own words say why)
    assert v is not None, (f"sim-cell exited {cell.returncode}, no cut: {res.get('stopped')}; "
                           f"{res.get('warnings')}\n{err[-3000:]}")
    print(f"sim-cell, {scenario.name}:", {k: v[k] for k in ("amplitude_um", "axial_um", "frequency_hz", "onset_mm",
                                                             "feed_per_tooth_um")}, "exit", cell.returncode)
    lines = [w for w in res["warnings"] if PREFIX in w]
    if warns:
        assert vibrated(v) and v["frequency_hz"] == pytest.approx(42.0, abs=6.0), v
        (line,) = lines
        assert line.startswith(f"sim-cell: {PREFIX}: {v['amplitude_um']:.0f} um at ") and PLANE in line, line
        assert f"robstiff: warning: {line}" in err
    else:
        assert cell.returncode == 0, err
        assert v["cut_s"][1] > v["cut_s"][0] + 1.0 and 0.0 <= v["amplitude_um"] < 0.5 * v["feed_per_tooth_um"], v
        assert lines == [] and PREFIX not in err
