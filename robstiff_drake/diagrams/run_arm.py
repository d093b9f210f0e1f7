"""The robot controller's model of the arm, as ``robstiff diagnose-run`` needs
it to read a run: the torques the gears carry along the logged path (the
arm's weight from the controller's gravity model, and its inertia) and the
arm's mass matrix, the weight's own stiffness and its modes at a pose.

Everything here comes from the robot file (masses, inertias, payload: the
Drake plant of robstiff_drake/plant.py, through diagrams/compliant_arm.py's
``controller_model``, diagrams/compliant_arm.py), never from a run's plant: a cell's controller knows
its arm's model, not its gears' truth.  The diagnosis itself
(identification/runs/diagnosis.py) is plain numpy and calls this through the
methods of ``ArmModel``.
"""

from dataclasses import replace

import numpy as np
from pydrake.multibody.tree import MultibodyForces

from robstiff_drake.model.loop_check import payload_inertial_wrench_map
from robstiff_drake.diagrams.compliant_arm import controller_model, joint_model
from robstiff_drake.model import joint_dynamics


class ArmModel:
    """The controller's model of ``robot`` (a continuous MultibodyPlant)."""

    def __init__(self, robot):
        self.robot = robot
        self.plant = controller_model(robot)
        self._ctx = self.plant.CreateDefaultContext()
        self._no_forces = MultibodyForces(self.plant)

    def gravity_torques(self, q_rad):
        """(n, 6) N*m: the torques that hold the arm and payload still at
        each row of q (n, 6) rad: what the gears carry at rest."""
        plant, ctx = self.plant, self._ctx
        plant.SetVelocities(ctx, np.zeros(6))
        out = []
        for q in np.atleast_2d(q_rad):
            plant.SetPositions(ctx, q)
            out.append(-plant.CalcGravityGeneralizedForces(ctx))  # as station.gravity_holding_torque
        return np.array(out)

    def inertia_torques(self, q_rad, v_rad_per_s, a_rad_per_s2):
        """(n, 6) N*m: M(q) q'' + c(q, q') along a path (n, 6 each): the
        torques the gears carry to move the arm, beyond its weight."""
        plant, ctx = self.plant, self._ctx
        out = np.empty((len(q_rad), 6))
        for i, (q, v, a) in enumerate(zip(q_rad, v_rad_per_s, a_rad_per_s2)):
            plant.SetPositions(ctx, q)
            plant.SetVelocities(ctx, v)
            out[i] = plant.CalcInverseDynamics(ctx, a, self._no_forces)  # M a + c v (force elements left out)
        return out

    def joints_at(self, q_rad, joint_stiffness_Nm_per_rad, damping_ratios, servo, design_q_rad=None):
        """The linear joints (model/joint_dynamics.JointModel) at q: the mass
        matrix and the weight's stiffness there, the gears' modal damping
        (``damping_ratios``) and the drives' velocity gains designed at
        ``design_q_rad`` (the station's start pose; default q), motors with
        the robot file's inertia."""
        K = joint_dynamics.stiffness_matrix(joint_stiffness_Nm_per_rad)
        here = joint_model(self.plant, self.robot, np.asarray(q_rad, dtype=float), K, damping_ratios, servo)
        if design_q_rad is None:
            return here
        design = joint_model(self.plant, self.robot, np.asarray(design_q_rad, dtype=float), K, damping_ratios, servo)
        return replace(design, M=here.M, G=here.G)

    def payload_map(self, q_rad):
        """L (6, 6): the payload's inertial wrench at the tool point (base
        frame) per joint acceleration at q, which the wrist sensor feels."""
        return payload_inertial_wrench_map(self.robot, np.asarray(q_rad, dtype=float))
