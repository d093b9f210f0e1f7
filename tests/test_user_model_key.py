"""The user model's cache key (diagrams/user_model_record.signature): what
the model is computed from must be in it, or a model made at another pose
or for another arm is read back from the cache."""

import shutil

import numpy as np

from robstiff_drake.diagrams.scenario import load_scenario
from robstiff_drake.diagrams.user_model_record import signature
from robstiff_drake.model.robot import load_robot
from robstiff_drake.paths import DIAGRAMS_DIR, robot_file


def test_another_start_pose_is_another_key():
    """block_milling with its sensor at 1 kHz and tests' short_block had one
    key before the start pose was in it (the bench rests, calibrates the
    payload and steps the servo at that pose)."""
    robot = load_robot()
    sc = load_scenario(DIAGRAMS_DIR / "block_milling.yaml")
    q0 = np.deg2rad([0.0, 30.0, 20.0, 0.0, 40.0, 0.0])
    assert signature(sc, robot, q0) == signature(sc, robot, q0.copy())
    assert signature(sc, robot, q0) != signature(sc, robot, q0 + np.deg2rad(0.5))


def test_an_edited_robot_file_is_another_key(tmp_path):
    """The same path with other content (a heavier payload) is another arm."""
    path = tmp_path / "my_robot.yaml"
    shutil.copyfile(robot_file("irb6400"), path)
    sc = load_scenario(DIAGRAMS_DIR / "block_milling.yaml")
    q0 = np.zeros(6)
    before = signature(sc, load_robot(path), q0)
    text = path.read_text()
    assert "mass_kg: 40" in text
    path.write_text(text.replace("mass_kg: 40", "mass_kg: 45", 1))
    assert signature(sc, load_robot(path), q0) != before


def test_asked_before_the_station_or_by_the_run_one_model():
    """`simulate` asks for the user model before any station is built (its checks: servo.velocity_integral_hz
    still the stated 7.5 Hz), the run after (the corner its station chose at the path's first pose written into
    the scenario): one key, one model, whose servo has the drives' corner (before: two keys, the bench campaigns
    measured twice per scenario, and the first model's servo kept 7.5 Hz)."""
    import copy

    from robstiff_drake.diagrams import user_model as um
    from robstiff_drake.diagrams.station import resolve_integral_corner

    robot = load_robot()
    sc = load_scenario(DIAGRAMS_DIR / "block_milling.yaml")
    ident = sc.model.identification
    ident.stiffness = ident.payload = ident.servo = "exact"  # (no bench: the key is under test, not a campaign)
    q0 = np.deg2rad([0.0, 30.0, 20.0, 0.0, 40.0, 0.0])
    first = um.user_model(sc, robot, q0)
    assert sc.servo.velocity_integral_hz == 7.5  # the caller's scenario as it was
    run = copy.deepcopy(sc)
    corner = resolve_integral_corner(run, robot, q0)
    assert corner < 7.5, corner
    assert um.user_model(run, robot, q0) is first
    assert first.servo.velocity_integral_hz == corner
