"""The unstable-plant-step refusal (diagrams/plant_step.unstable_step_refusal)
names the mode and its cause, states a criterion its own numbers satisfy,
and advises a step that itself passes the check, the same step from
whichever refused step it is asked (a newcomer followed 2 ms -> 1.1 ms ->
0.5 ms).  Its line says what is wrong and the fix, in at most 250
characters (before: one line of 624 to 957); the detail (the mode's
damping and motor share, the motor inertia, assumed or given, the bound
with its numbers) is its ``why``, printed after the error's line,
indented.  A robot file without motor_inertia_kgm2 (the shipped KR 240
file with that key removed: the wrist's rotor then assumed as light as
its link, model/joint_dynamics.motor_inertia) and the shipped IRB 6400."""

import re

import numpy as np
import pytest

from robstiff_drake.diagrams import compliant_arm
from robstiff_drake.diagrams.milling_cell import check_plant_step
from robstiff_drake.diagrams.path_references import planned_path
from robstiff_drake.diagrams.plant_step import chosen_step, unstable_step_message, unstable_step_refusal
from robstiff_drake.diagrams.scenario import load_scenario
from robstiff_drake.diagrams.scenario_models import plant_damping_ratios, plant_stiffness, servo_parameters
from robstiff_drake.errors import InputError
from robstiff_drake.model import joint_dynamics
from robstiff_drake.model.robot import load_robot
from robstiff_drake.paths import DIAGRAMS_DIR, MODELS_DIR


def _scenario(tmp_path, step_s):
    text = (DIAGRAMS_DIR / "short_block.yaml").read_text().replace("  time_step: 0.002\n",
                                                                    f"  time_step: {step_s:g}\n")
    path = tmp_path / f"scenario_{step_s:g}.yaml"
    path.write_text(text)
    return load_scenario(path)


def _without_motor_inertia(tmp_path):
    text = (MODELS_DIR / "kr240_r2900.yaml").read_text()
    kept = [line for line in text.splitlines() if not line.startswith("motor_inertia_kgm2:")]
    assert len(kept) == len(text.splitlines()) - 1
    path = tmp_path / "kr240_no_motors.yaml"
    path.write_text("\n".join(kept) + "\n")
    robot = load_robot(str(path))
    assert robot.motor_inertia_kgm2 is None
    return robot


def _joints(sc, robot):
    q = compliant_arm.path_poses(planned_path(sc, robot, robot.tool_point(where="the test"))[2])
    K = joint_dynamics.stiffness_matrix(np.asarray(plant_stiffness(sc, robot), dtype=float), 0.0)
    return compliant_arm.arm_joints(compliant_arm.controller_model(robot), robot, q, K, plant_damping_ratios(sc),
                                    servo_parameters(sc), sc.plant.damping_on)


LINE_CHARS = 250  # the refusal's line: what is wrong and the fix


def _refusal(jm, h, assumed=False):
    """(line, why) of the refusal of step ``h``: the line one line of at most LINE_CHARS."""
    r = unstable_step_refusal(jm, h, assumed_motor_inertia=assumed)
    assert r is not None and "\n" not in r.line and "\n" not in r.why and len(r.line) <= LINE_CHARS, r
    assert unstable_step_message(jm, h, assumed_motor_inertia=assumed) == r.line
    return r.line, r.why


def _numbers(line, why):
    """(advised step s, omega h bound, its step s, omega h at the refused step) of a refusal."""
    advised = float(re.search(r"plant_config\.time_step: ([0-9.e-]+)\)", line).group(1))
    bound, limit_ms = re.search(r"holds only while omega h <= ([0-9.]+) \(up to ([0-9.]+) ms\)", why).groups()
    at = float(re.search(r"omega h = ([0-9.]+) and it grows", why).group(1))
    return advised, float(bound), float(limit_ms) / 1e3, at


@pytest.mark.parametrize("which, steps_s", [("no_motor_inertia", (0.002, 0.0011, 0.001)),
                                            ("irb6400", (0.004, 0.003))])
def test_the_advised_step_passes_and_does_not_move(tmp_path, robot, which, steps_s):
    r = _without_motor_inertia(tmp_path) if which == "no_motor_inertia" else robot
    jm = _joints(_scenario(tmp_path, steps_s[0]), r)
    advice = set()
    for h in steps_s:
        line, why = _refusal(jm, h, r.motor_inertia_kgm2 is None)
        advised, bound, limit_s, at = _numbers(line, why)
        assert unstable_step_message(jm, advised) is None, line  # the advised step passes the check
        assert advised <= limit_s and jm.is_stable_step(limit_s) and not jm.is_stable_step(limit_s + 1e-5)
        assert at > bound, why  # the stated criterion is what refused it
        f_hz = float(re.search(r"the arm's ([0-9]+) Hz mode", line).group(1))
        assert f"the {f_hz:.0f} Hz mode" in why, why
        assert at == pytest.approx(2 * np.pi * f_hz * h, abs=0.02 + 2 * np.pi * 0.5 * h)
        assert "joint 6's gear" in line and "joint 6's gear between its motor and the link" in why, (line, why)
        growth = float(re.search(r"it grows x([0-9.]+) a step", why).group(1))
        assert growth == pytest.approx(jm.spectral_radius(h), rel=1e-2) and growth > 1.0, why
        advice.add(advised)
    assert len(advice) == 1, advice  # the same advice from every refused step
    # the station's own choice, when the scenario gives no step, is the same step (up to its 2 ms cap)
    assert chosen_step(jm)[0] == pytest.approx(min(advice.pop(), 0.002))


def test_a_file_without_motor_inertias_is_told_the_assumed_value_and_the_key(tmp_path):
    r = _without_motor_inertia(tmp_path)
    sc = _scenario(tmp_path, 0.002)
    with pytest.raises(InputError) as e:
        check_plant_step(sc, r)
    line, why = str(e.value), e.value.why
    assert "\n" not in line and "motor_inertia_kgm2" in line and "assumed" in line, line
    jm = _joints(sc, r)
    assert f"{jm.motor_inertia_kgm2[5]:.3g} kg*m^2" in why and "datasheet" in why, why
    advised = _numbers(line, why)[0]
    check_plant_step(_scenario(tmp_path, advised), r)  # the advised step builds


def test_the_command_prints_the_line_then_the_why(tmp_path, capsys):
    """simulate's refusal: the error's line (what is wrong and the fix, <= LINE_CHARS after the file and key),
    then its why, indented, wrapped; exit 2, nothing else."""
    from robstiff_drake.commands.main import WHY_WIDTH, main

    sc = _scenario(tmp_path, 0.004)
    assert main(["simulate", str(sc.source), "--out", str(tmp_path / "out"), "--quiet"]) == 2
    err = capsys.readouterr().err.rstrip("\n").splitlines()
    head = f"robstiff: error: {sc.source}: plant_config.time_step: "
    assert err[0].startswith(head) and len(err[0]) - len(head) <= LINE_CHARS, err
    assert "a 4 ms plant step is unstable for the arm's 126 Hz mode" in err[0] and "use 2.4 ms" in err[0], err
    assert err[1].startswith("  why: the 126 Hz mode") and all(ln.startswith("       ") for ln in err[2:]), err
    assert all(len(ln) <= WHY_WIDTH for ln in err[1:]), err
    why = " ".join(ln.strip() for ln in err[1:])
    assert "omega h <= 1.93 (up to 2.44 ms)" in why and "(motor_inertia_kgm2)" in why, why
    assert not (tmp_path / "out").exists()


def test_a_file_with_motor_inertias_is_not_told_to_give_them(tmp_path, robot):
    line, why = _refusal(_joints(_scenario(tmp_path, 0.004), robot), 0.004)
    assert "assumed" not in line + why and "datasheet" not in line + why and "motor_inertia" not in line, line
    assert "(motor_inertia_kgm2)" in why, why


def test_the_figures_joint_dynamics_states(tmp_path):
    """model/joint_dynamics.py's ASSUMPTION and module docstring, docs/results.md and
    docs/assumptions.md quote these."""
    r = _without_motor_inertia(tmp_path)
    jm = _joints(_scenario(tmp_path, 0.002), r)
    line, why = _refusal(jm, 0.002, assumed=True)
    assert "191 Hz mode" in line and "49 % of its motion in joint 6's motor" in why and "9.4 % damped" in why, why
    assert "omega h <= 0.74 (up to 0.62 ms)" in why and "0.336 kg*m^2" in why, why
    # (and docs/results.md's IRB 6400 at 4 ms)
    line, why = _refusal(_joints(_scenario(tmp_path, 0.004), load_robot()), 0.004)
    assert line == ("a 4 ms plant step is unstable for the arm's 126 Hz mode (joint 6's gear and motor): use 2.4 ms "
                    "(plant_config.time_step: 0.0024)"), line
    assert "126 Hz mode (joint 6's gear between its motor and the link, 5.0 % damped, 3 % of its motion" in why, why
    assert "omega h <= 1.93 (up to 2.44 ms)" in why, why
