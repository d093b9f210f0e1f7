"""The YAML parameter file: content and error messages."""

import numpy as np
import pytest
import yaml

from robstiff_drake.errors import InputError
from robstiff_drake.model.robot import load_robot
from robstiff_drake.paths import DEFAULT_ROBOT_YAML


def test_table1_is_what_the_seed_prints(robot):
    np.testing.assert_allclose(robot.dh.d_m * 1000, [900, 0, 0, 1300, 0, 200])
    np.testing.assert_allclose(robot.dh.a_m * 1000, [188, 950, 225, 0, 0, 0])
    np.testing.assert_allclose(np.rad2deg(robot.dh.alpha_rad), [-90, 0, -90, -90, 90, 0])
    np.testing.assert_allclose(np.rad2deg(robot.dh.home_rad), [0, -90, 0, 180, 0, 0])


def test_inertias_are_physical(robot):
    for link in robot.links:
        w = np.linalg.eigvalsh(link.inertia_kgm2)
        assert w.min() > 0
        # triangle inequality of principal moments
        assert w[0] + w[1] >= w[2] - 1e-12


def _write(tmp_path, mutate):
    doc = yaml.safe_load(DEFAULT_ROBOT_YAML.read_text())
    mutate(doc)
    path = tmp_path / "robot.yaml"
    path.write_text(yaml.safe_dump(doc))
    return path


@pytest.mark.parametrize(
    "mutate, message",
    [
        (lambda d: d.update(extra=1), "key 'extra': unknown key"),
        (lambda d: d["dh"].pop("a_mm"), "key 'dh.a_mm': missing"),
        (lambda d: d["dh"].update(d_mm=[1, 2, 3]), "key 'dh.d_mm': expected 6 numbers, got 3"),
        (lambda d: d.update(joint_stiffness_Nm_per_rad=[1e6, 1e6, 0, 1e5, 1e5, 1e5]),
         "key 'joint_stiffness_Nm_per_rad': joint 3: 0 is outside the allowed range [1000, 1e+09] N*m/rad"),
        (lambda d: d["links"][2].update(mass_kg=-1),
         "key 'links[2].mass_kg': -1 is outside the allowed range [0.01, 20000] kg"),
        (lambda d: d["joint_limits"].update(lower_deg=[0, 80, 0, 0, 0, 0]),
         "key 'joint_limits.lower_deg': joint 2: lower 80 >= upper 70 deg"),
    ],
)
def test_bad_robot_file_names_the_key(tmp_path, mutate, message):
    path = _write(tmp_path, mutate)
    with pytest.raises(InputError) as err:
        load_robot(path)
    assert message in str(err.value)
    assert str(path) in str(err.value)


def test_invalid_yaml_names_line_and_column(tmp_path):
    path = tmp_path / "bad.yaml"
    path.write_text("name: x\ndh: [1, 2\n")
    with pytest.raises(InputError, match=r"bad.yaml:\d+: column \d+: invalid YAML"):
        load_robot(path)


def test_joint_limit_message_names_value_and_limit(robot):
    with pytest.raises(InputError, match=r"q5 = 130 deg is outside the joint limit \[-120, 120\] deg"):
        robot.check_q_deg([0, 0, 0, 0, 130, 0])
