"""A scenario that gives no plant step: the station takes the largest step
up to 2 ms that keeps every mode stable and resolves the scenario's play
and tooth-resolved force (diagrams/scenario_step.scenario_step_s), says which
and why in one line, and builds at it; a step given is used as it is."""

import pytest

from robstiff_drake.diagrams.milling_cell import check_plant_step
from robstiff_drake.diagrams import scenario_step
from robstiff_drake.diagrams.scenario import load_scenario
from robstiff_drake.diagrams.scenario_step import plant_step_s, step_choice
from robstiff_drake.errors import InputError
from robstiff_drake.paths import DIAGRAMS_DIR

PLAY6 = [0.0, 0.0, 0.0, 0.0, 0.0, 2.9e-4]  # 1 arc-minute on joint 6 (its contact mode: 126 Hz)


def _scenario(tmp_path, step_line="", extra=""):
    """diagrams/short_block.yaml with its plant step line replaced by ``step_line``."""
    text = (DIAGRAMS_DIR / "short_block.yaml").read_text().replace("  time_step: 0.002\n", step_line)
    path = tmp_path / "scenario.yaml"
    path.write_text(text + extra)
    return load_scenario(path)


@pytest.mark.parametrize("play, mode, step_s, says", [
    ([], "averaged", 2e-3, "no play and no tooth-resolved force"),
    (PLAY6, "averaged", 5e-4, "joint 6's play (its 126 Hz contact mode) needs 0.5 ms"),
    (PLAY6, "tooth", 2.5e-4, "the tooth-resolved force (360 Hz tooth pass) needs 0.25 ms"),
])
def test_a_scenario_without_a_step_gets_the_largest_that_resolves_it(tmp_path, robot, capsys, play, mode, step_s,
                                                                     says):
    scenario_step._SAID.clear()  # (said once per process: said here)
    sc = _scenario(tmp_path)
    assert sc.plant_config.time_step == 0.0  # (not given)
    sc.plant.lost_motion_rad, sc.cutting.mode = list(play), mode
    assert plant_step_s(sc, robot) == pytest.approx(step_s)
    why = step_choice(sc)
    assert "\n" not in why and f"plant step {step_s * 1e3:g} ms" in why and says in why, why
    assert why in capsys.readouterr().err
    check_plant_step(sc, robot)  # builds at it (the station chooses it again for its own poses: the same)
    assert plant_step_s(sc) == pytest.approx(step_s) and step_choice(sc) == why


def test_a_given_step_is_kept_and_refused_when_it_does_not_resolve(tmp_path, robot):
    sc = _scenario(tmp_path, "  time_step: 0.002\n")
    sc.plant.lost_motion_rad = PLAY6
    assert step_choice(sc) is None
    with pytest.raises(InputError, match="use at most 0.5 ms"):
        check_plant_step(sc, robot)
    sc = _scenario(tmp_path, "  time_step: 0\n")  # 0: not given
    assert plant_step_s(sc, robot) == pytest.approx(2e-3) and step_choice(sc) is not None


def test_a_step_out_of_range_is_refused_naming_zero_as_not_given(tmp_path):
    with pytest.raises(InputError, match=r"plant_config.time_step: 0.03 is outside .*or 0: not given"):
        _scenario(tmp_path, "  time_step: 0.03\n")
