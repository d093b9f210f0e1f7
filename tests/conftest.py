import numpy as np
import pytest

from robstiff_drake.model.robot import load_robot


@pytest.fixture(scope="session")
def robot():
    return load_robot()


@pytest.fixture
def rng():
    return np.random.default_rng(20261121)


def random_q(robot, rng, n=None):
    """Random configurations inside the joint limits (rad)."""
    size = (6,) if n is None else (n, 6)
    return rng.uniform(robot.q_lower_rad, robot.q_upper_rad, size=size)
