"""The arm's response that diagnose-run predicts from a run's logs
(identification/runs/arm_response.py with diagrams/run_arm.py) against Drake's
plant of the station (diagrams/station.py: the gears in a discrete
MultibodyPlant, the interpolator's hold and delay line, the motors with
their inertia and the drives):
a correction step and a force step at the tool, each on the arm at rest."""

import numpy as np
import pytest
from arm_helpers import add_constant_tool_force
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import (
    ConstantVectorSource,
    TrajectorySource,
    ZeroOrderHold,
)
from pydrake.trajectories import PiecewisePolynomial

from robstiff_drake.diagrams.run_arm import ArmModel
from robstiff_drake.diagrams.scenario import load_scenario, scenario_robot
from robstiff_drake.diagrams.scenario_models import plant_damping_ratios
from robstiff_drake.diagrams.station import (
    add_compliant_arm,
    gravity_holding_torque,
    servo_parameters,
    set_drives_at_rest,
)
from robstiff_drake.identification.runs import arm_response as ar
from robstiff_drake.model import kinematics as kin
from robstiff_drake.paths import REPO_ROOT

STEP_AT_S = 0.5
Q0 = np.deg2rad([0.0, 7.86, 28.57, 0.0, 53.56, 0.0])  # the short block's first pose


@pytest.fixture(scope="module")
def setup():
    sc = load_scenario(REPO_ROOT / "tests" / "data" / "short_block.yaml")
    return sc, scenario_robot(sc)


def drake_tool_z(sc, robot, *, correction=None, force=None, t_end=1.5):
    """(times, tool z - its start (m)) of the station's arm at rest on Q0 with
    a correction step added to the command at STEP_AT_S (a discrete signal
    that changes at an interpolator tick, as a compensator's does) or a
    constant force at the tool from the start."""
    k = robot.joint_stiffness_Nm_per_rad
    builder = DiagramBuilder()
    arm = add_compliant_arm(builder, robot=robot, plant_config=sc.plant_config, joint_stiffness_Nm_per_rad=k,
                            damping_ratios=plant_damping_ratios(sc), q_modes_rad=Q0, servo=servo_parameters(sc),
                            interpolator_period_s=sc.servo.interpolator_period_ms / 1e3)
    plant = arm["plant"]
    step = np.zeros(6) if correction is None else np.asarray(correction, dtype=float)
    # the command jumps at STEP_AT_S, a controller tick, from a discrete state as the compensator's
    # correction does (its update and the interpolator's hold fall on the same instant)
    traj = PiecewisePolynomial.ZeroOrderHold([0.0, STEP_AT_S, 10.0], np.column_stack([Q0, Q0 + step, Q0 + step]))
    src = builder.AddSystem(TrajectorySource(traj))
    held = builder.AddSystem(ZeroOrderHold(sc.controller.period_ms / 1e3, 6))
    builder.Connect(src.get_output_port(), held.get_input_port())
    builder.Connect(held.get_output_port(), arm["position_command"])
    builder.Connect(builder.AddSystem(ConstantVectorSource(np.zeros(6))).get_output_port(), arm["velocity_command"])
    if force is not None:
        add_constant_tool_force(builder, plant, robot, force)
    sim = Simulator(builder.Build())
    root = sim.get_mutable_context()
    theta = Q0 + gravity_holding_torque(arm["controller_plant"], Q0) / k
    plant.SetPositions(plant.GetMyMutableContextFromRoot(root), Q0)
    set_drives_at_rest(arm, root, theta, Q0)
    held.GetMyMutableContextFromRoot(root).SetDiscreteState(Q0)
    sim.Initialize()
    tool = robot.payload.tool_point_m
    z0 = kin.tool_position(robot.dh, Q0, tool)[2]
    times, z = np.arange(0.0, t_end, 0.002), []
    for t in times:
        sim.AdvanceTo(t)
        z.append(kin.tool_position(robot.dh, plant.GetPositions(plant.GetMyContextFromRoot(root)), tool)[2] - z0)
    return times, np.array(z)


def model_tool_z(sc, robot, *, correction=None, force=None, dead_time_s, t_end=1.5):
    """The same from the linear model diagnose-run uses."""
    k = robot.joint_stiffness_Nm_per_rad
    joints = ArmModel(robot).joints_at(Q0, k, plant_damping_ratios(sc), servo_parameters(sc))
    h = ar.STEP_S
    t = np.arange(0.0, t_end, h)
    J = kin.jacobian(robot.dh, Q0, robot.payload.tool_point_m)
    systems = [ar.arm_matrices(joints, h)]
    if correction is not None:
        u = ar.delayed(np.where(t[:, None] >= STEP_AT_S, correction, 0.0), int(round(dead_time_s / h)))
        channel = (None, u, None)
    else:
        channel = (np.tile(J.T @ np.r_[force, 0.0, 0.0, 0.0], (t.size, 1)), None, None)
    dev = ar.responses(systems, np.zeros(t.size, dtype=int), [channel])[..., 0]
    return t, dev @ J[2]


def test_a_correction_reaches_the_tool_as_the_station_moves_it(setup):
    """A correction step of 0.1 mrad on joints 2 and 3 (about 0.25 mm at the
    tool), with the dead time compensator.yaml states for a simulated run:
    the interpolator's 12 ms, one interpolator period for the hold to take a
    discrete command and one plant step (diagrams/cell_record.servo_settings)."""
    sc, robot = setup
    step = [0.0, 1e-4, 1e-4, 0.0, 0.0, 0.0]
    dead = (sc.servo.interpolator_delay_ms + sc.servo.interpolator_period_ms) / 1e3 + sc.plant_config.time_step
    t, z = drake_tool_z(sc, robot, correction=step)
    tm, zm = model_tool_z(sc, robot, correction=step, dead_time_s=dead)
    zm = np.interp(t, tm, zm)
    assert np.abs(z).max() > 2e-4  # a quarter of a millimetre, with the first mode's overshoot
    assert np.sqrt(np.mean((z - zm) ** 2)) < 0.05 * np.sqrt(np.mean(z**2))
    # without the hold's period and the plant step the model would lead the station visibly
    tm, early = model_tool_z(sc, robot, correction=step, dead_time_s=sc.servo.interpolator_delay_ms / 1e3)
    assert np.sqrt(np.mean((z - np.interp(t, tm, early)) ** 2)) > 2 * np.sqrt(np.mean((z - zm) ** 2))


def test_a_force_at_the_tool_deflects_it_as_the_station_does(setup):
    """300 N down at the tool from rest: the ringing at the first mode, the
    motors giving way and the drives' integrals bringing them back, and the
    static deflection through the gears and the weight's stiffness."""
    sc, robot = setup
    force = [0.0, 0.0, -300.0]
    t, z = drake_tool_z(sc, robot, force=force)
    tm, zm = model_tool_z(sc, robot, force=force, dead_time_s=0.0)
    # the plant's symplectic step answers a force half a step early (q_n = F h^2 n (n + 1) / 2m: t^2 + t h)
    zm = np.interp(t + 0.5 * sc.plant_config.time_step, tm, zm)
    assert np.abs(z).max() > 5e-4
    assert np.sqrt(np.mean((z - zm) ** 2)) < 0.02 * np.sqrt(np.mean(z**2))
