"""The joints' linear model (model/joint_dynamics.py), the gear-play law
(model/transmission.py) and the robot file's motor inertias, in numbers."""

import numpy as np
import pytest

from robstiff_drake.errors import InputError
from robstiff_drake.model import joint_dynamics as jd
from robstiff_drake.model import transmission
from robstiff_drake.model.robot import load_robot
from robstiff_drake.paths import robot_file


def test_modal_damping_gives_each_mode_its_ratio(rng):
    A = rng.normal(size=(6, 6))
    M = A @ A.T + 6 * np.eye(6)
    K = np.diag(rng.uniform(1e5, 2e6, 6))
    G = 0.01 * rng.normal(size=(6, 6)) * 1e5
    ratios = [0.01, 0.02, 0.04, 0.08, 0.16, 0.32]
    D = jd.modal_damping_matrix(M, K, G, ratios)
    w, Phi = jd.held_modes(M, K, G)
    np.testing.assert_allclose(Phi.T @ D @ Phi, np.diag(2 * np.array(ratios) * w), atol=1e-8 * w.max())
    np.testing.assert_allclose(D, D.T, atol=1e-9 * np.abs(D).max())


def test_play_law_is_a_dead_zone():
    k, b = np.full(6, 1e6), np.full(6, 1e-4)
    phi = np.array([0.0, 5e-5, -9.9e-5, 1.5e-4, -3e-4, 1e-4])
    np.testing.assert_allclose(transmission.play_torque(phi, k, b), [0, 0, 0, 50.0, -200.0, 0.0], atol=1e-9)
    tau = np.array([0.0, 50.0, -200.0, 1e-9, 0.0, 0.0])
    np.testing.assert_allclose(transmission.play_twist(tau, 1 / k, b), [0, 1.5e-4, -3e-4, 1e-15, 0, 0],  # below 1e-6 N*m: unloaded
                               atol=1e-15)


def test_motor_inertias_out_of_range_are_one_line_with_file_line_and_range(tmp_path):
    text = robot_file("irb6400").read_text()
    bad = tmp_path / "bad.yaml"
    line = next(i for i, s in enumerate(text.splitlines(), 1) if s.startswith("motor_inertia_kgm2:"))
    bad.write_text(text.replace("motor_inertia_kgm2: [500.0, 500.0, 150.0, 20.0, 20.0, 10.0]",
                                "motor_inertia_kgm2: [500.0, 500.0, 150.0, 20.0, 20.0, 0.0]"))
    with pytest.raises(InputError) as e:
        load_robot(str(bad))
    msg = str(e.value)
    assert msg.startswith(f"{bad}:{line}: key 'motor_inertia_kgm2': joint 6:") and "[0.001, 10000] kg*m^2" in msg and "\n" not in msg
    assert load_robot("irb6400").motor_inertia_kgm2.tolist() == [500.0, 500.0, 150.0, 20.0, 20.0, 10.0]
