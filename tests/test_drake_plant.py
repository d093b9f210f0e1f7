"""The Drake MultibodyPlant, parsed from the URDF generated out of the
robot file, agrees with the numpy model (the other library robots:
tests/test_robot_library.py)."""

import numpy as np
import pytest
from conftest import random_q
from pydrake.autodiffutils import ExtractGradient, ExtractValue, InitializeAutoDiff
from pydrake.multibody.tree import JacobianWrtVariable

from robstiff_drake.model import kinematics as kin
from robstiff_drake.plant import make_irb6400_plant, tool_position_and_jacobian


@pytest.fixture(scope="module")
def plant():
    plant, _ = make_irb6400_plant()
    return plant


def test_plant_structure_and_mass(plant, robot):
    assert plant.num_positions() == 6
    assert [plant.GetJointByName(f"joint_{i}").type_name() for i in range(1, 7)] == ["revolute"] * 6
    ctx = plant.CreateDefaultContext()
    # about 2 t of robot, plus the payload on the flange
    assert plant.CalcTotalMass(ctx) == pytest.approx(robot.total_mass_kg + robot.payload.mass_kg, rel=1e-12)
    assert 1800 < robot.total_mass_kg < 2300
    lower = plant.GetPositionLowerLimits()
    upper = plant.GetPositionUpperLimits()
    np.testing.assert_allclose(lower, robot.q_lower_rad, atol=1e-15)
    np.testing.assert_allclose(upper, robot.q_upper_rad, atol=1e-15)


def test_drake_fk_and_jacobian_match_dh_chain(plant, robot, rng):
    ctx = plant.CreateDefaultContext()
    flange = plant.GetFrameByName("flange")
    for q in random_q(robot, rng, 50):
        for tool in (np.zeros(3), robot.payload.tool_point_m, np.array([0.05, -0.02, 0.3])):
            p, J = tool_position_and_jacobian(plant, ctx, q, tool)
            np.testing.assert_allclose(p, kin.tool_position(robot.dh, q, tool), atol=1e-9)
            np.testing.assert_allclose(J, kin.jacobian(robot.dh, q, tool), atol=1e-9)
        X = plant.CalcRelativeTransform(ctx, plant.world_frame(), flange)
        np.testing.assert_allclose(X.rotation().matrix(), kin.frames(robot.dh, q)[6, :3, :3], atol=1e-12)


def test_geometric_stiffness_matches_drake_autodiff(plant, robot, rng):
    plant_ad = plant.ToAutoDiffXd()
    ctx = plant_ad.CreateDefaultContext()
    flange = plant_ad.GetFrameByName("flange")
    tool = robot.payload.tool_point_m
    for q in random_q(robot, rng, 5):
        F = rng.normal(size=6) * 300.0
        plant_ad.SetPositions(ctx, InitializeAutoDiff(q))
        Jw = plant_ad.CalcJacobianSpatialVelocity(
            ctx, JacobianWrtVariable.kQDot, flange, tool, plant_ad.world_frame(), plant_ad.world_frame())
        J = np.vstack([Jw[3:], Jw[:3]])  # linear rows first, the project's convention
        tau = J.T @ F
        np.testing.assert_allclose(ExtractValue(tau).ravel(), kin.jacobian(robot.dh, q, tool).T @ F, atol=1e-9)
        np.testing.assert_allclose(ExtractGradient(tau), kin.geometric_stiffness(robot.dh, q, F, tool), atol=1e-8)
