"""The gears' lost motion in the station against the compensator's model of
it: a noted discrepancy (docs/run_diagnosis.md, "What it does not do").

The station's gear carries weight - J^T W (the cut's generalized force W on
the links is held back by the gear); the compensator's DeflectionModel
predicts the extra twist of weight + J^T W (model/compensator.py, with the
holding torque from the controller's model as its static torque).  With
lost motion the two differ unless the weight on the joint is near zero.
This script settles the station's arm (Drake's plant, 40 urad of lost
motion in joint 2) at a pose where joint 2 holds about 155 N*m of weight,
with a constant force of -300 N and +300 N along z at the tool, and prints
joint 2's deflection next to both laws (model/transmission.py).

    python3 studies/compensator_lost_motion_sign.py
"""

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.multibody.math import SpatialForce
from pydrake.multibody.plant import ExternallyAppliedSpatialForce_
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantValueSource, ConstantVectorSource

from robstiff_drake.diagrams.scenario import load_scenario, scenario_robot
from robstiff_drake.diagrams.station import (
    add_compliant_arm,
    gravity_holding_torque,
    servo_parameters,
    static_link_angles,
)
from robstiff_drake.model import ik, transmission
from robstiff_drake.model import kinematics as kin
from robstiff_drake.paths import REPO_ROOT

LOST_MOTION_RAD = np.array([0.0, 4e-5, 0.0, 0.0, 0.0, 0.0])
TOOL_POINT_M = (1.075, 0.0, 0.7)  # joint 2 holds about +155 N*m of the arm's weight here


def settle(sc, robot, q0, force_N):
    """Joint angles (rad) of the station's arm at rest, commanded to q0, with
    a constant force at the tool point (base frame)."""
    k = robot.joint_stiffness_Nm_per_rad
    builder = DiagramBuilder()
    arm = add_compliant_arm(builder, robot=robot, plant_config=sc.plant_config, joint_stiffness_Nm_per_rad=k,
                            damping_ratio=0.5, q_modes_rad=q0, servo=servo_parameters(sc),
                            interpolator_period_s=sc.servo.interpolator_period_ms / 1e3,
                            lost_motion_rad=list(LOST_MOTION_RAD))
    plant = arm["plant"]
    builder.Connect(builder.AddSystem(ConstantVectorSource(q0)).get_output_port(), arm["position_command"])
    builder.Connect(builder.AddSystem(ConstantVectorSource(np.zeros(6))).get_output_port(), arm["velocity_command"])
    f = ExternallyAppliedSpatialForce_[float]()
    f.body_index = plant.GetBodyByName("spindle").index()
    f.p_BoBq_B = robot.payload.tool_point_m
    f.F_Bq_W = SpatialForce(np.zeros(3), np.asarray(force_N, dtype=float))
    builder.Connect(builder.AddSystem(ConstantValueSource(AbstractValue.Make([f]))).get_output_port(),
                    plant.get_applied_spatial_force_input_port())
    sim = Simulator(builder.Build())
    root = sim.get_mutable_context()
    theta = q0 + gravity_holding_torque(arm["controller_plant"], q0) / k
    plant.SetPositions(plant.GetMyMutableContextFromRoot(root),
                       static_link_angles(arm["controller_plant"], theta, 1.0 / k, LOST_MOTION_RAD))
    arm["servo"].GetMyMutableContextFromRoot(root).SetDiscreteState(np.r_[theta, np.zeros(6)])
    for block in arm["interpolator"]:
        ctx = block.GetMyMutableContextFromRoot(root)
        ctx.SetDiscreteState(np.tile(np.r_[theta, np.zeros(6)], ctx.get_discrete_state_vector().size() // 12))
    sim.Initialize()
    sim.AdvanceTo(4.0)
    return plant.GetPositions(plant.GetMyContextFromRoot(root)), arm["controller_plant"]


def main():
    sc = load_scenario(REPO_ROOT / "tests" / "data" / "short_block.yaml")
    robot = scenario_robot(sc)
    tool = robot.payload.tool_point_m
    c = 1.0 / robot.joint_stiffness_Nm_per_rad
    q0 = ik.solve_ik(robot.dh, ik.tool_down_pose(np.array(TOOL_POINT_M), 0.0), tool)
    q_rest, ctrl = settle(sc, robot, q0, [0.0, 0.0, 0.0])
    weight = gravity_holding_torque(ctrl, q0)
    J = kin.jacobian(robot.dh, q0, tool)
    print(f"joint 2 holds {weight[1]:+.1f} N*m of the arm's weight; lost motion {LOST_MOTION_RAD[1] * 1e6:g} urad")
    print("| force at the tool (N, z) | J^T W on joint 2 (N*m) | station: joint 2 moves (urad) | "
          "law of weight - J^T W (urad) | compensator's law, weight + J^T W (urad) |")
    print("|---|---|---|---|---|")
    for fz in (-300.0, 300.0):
        q, _ = settle(sc, robot, q0, [0.0, 0.0, fz])
        tau = J.T @ np.r_[0.0, 0.0, fz, 0.0, 0.0, 0.0]
        station = -(transmission.twist(weight - tau, c, LOST_MOTION_RAD)
                    - transmission.twist(weight, c, LOST_MOTION_RAD))
        model = transmission.static_deflection(weight, tau, c, LOST_MOTION_RAD)
        print(f"| {fz:+.0f} | {tau[1]:+.1f} | {(q - q_rest)[1] * 1e6:+.1f} | {station[1] * 1e6:+.1f} | "
              f"{model[1] * 1e6:+.1f} |")


if __name__ == "__main__":
    main()
