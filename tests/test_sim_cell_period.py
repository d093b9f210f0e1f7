"""`robstiff sim-cell`'s controller cycle: the scenario's controller.period_ms
unless --period-ms says otherwise (then a warning).  A FANUC R-30iB Plus
streams Stream Motion every 8 ms; before, sim-cell ran such a scenario at
its own default 4 ms without a word."""

import os

import pytest

from cell_helpers import ROOT
from robstiff_drake.commands import sim_cell

SHORT = os.path.join(ROOT, "tests", "data", "short_block.yaml")


class _Built(Exception):
    pass


@pytest.fixture
def eight_ms(tmp_path, monkeypatch):
    text = open(SHORT).read()
    assert "\n  period_ms: 4.0\n" in text
    scenario = tmp_path / "short_block_8ms.yaml"
    scenario.write_text(text.replace("\n  period_ms: 4.0\n", "\n  period_ms: 8.0\n"))
    built = {}

    def station(sc, robot, period_s):  # stands in for the Drake station: only the period it is built for
        built["period_s"] = period_s
        raise _Built

    import robstiff_drake.diagrams.cell_station as cell_station
    monkeypatch.setattr(cell_station, "CellStation", station)
    return str(scenario), built


def test_sim_cell_runs_at_the_scenarios_period_by_default(eight_ms, capsys):
    scenario, built = eight_ms
    with pytest.raises(_Built):
        sim_cell.run(scenario=scenario, egm_to="127.0.0.1:1", netft_port=1, protocol="stream-motion")
    assert built["period_s"] == pytest.approx(0.008)  # before: 0.004 (the option's default), silently
    assert "--period-ms" not in capsys.readouterr().err


def test_sim_cell_warns_when_the_period_differs_from_the_scenarios(eight_ms, capsys):
    scenario, built = eight_ms
    with pytest.raises(_Built):
        sim_cell.run(scenario=scenario, egm_to="127.0.0.1:1", netft_port=1, period_ms=4.0, protocol="stream-motion")
    assert built["period_s"] == pytest.approx(0.004)
    err = capsys.readouterr().err
    assert "--period-ms 4 differs from" in err and "controller.period_ms 8" in err
