"""The arm's joint-space inertia as a compensator would model it: rigid
links with the robot file's masses and inertias (the manufacturer's
nominal dynamic model), the payload on the flange, and nothing of the
plant's own code.  Plain numpy.

    M(q) = sum over bodies b of  m_b J_v,b^T J_v,b + J_w,b^T R_b I_b R_b^T J_w,b
    tau_g(q) = sum over bodies b of  m_b J_v,b^T g

with J_v,b the Jacobian of body b's centre of mass and J_w,b of its
rotation (only the joints before it move it).  Link i's frame is DH frame
i-1 turned by joint i (model/description.py writes the URDF so); the
payload hangs on the flange (DH frame 6).  Velocity-product (Coriolis)
terms are left out: at machining feeds (tens of mm/s) they are 1e-4 of
the inertial terms of a corner.

The same bodies give the joint torques of gravity.  The one numpy model of
the arm's rigid bodies: the preview compensator, the loop check and the
robot file's plausibility checks (model/robot_checks.py) all use it.
Tested against Drake's CalcMassMatrix and CalcGravityGeneralizedForces of
the robot file's plant for every library robot
(tests/test_robot_file_schema.py, tests/test_preview.py).

Units: q in rad (model angles), lengths m, masses kg, inertias kg m^2.
"""

import numpy as np

from robstiff_drake.model import kinematics as kin

GRAVITY_M_PER_S2 = 9.81


class ArmInertia:
    """M(q) (6x6, kg m^2) of a robot (its ``dh``, ``links`` 0..6 and ``payload``)."""

    def __init__(self, robot):
        self.dh = robot.dh
        motors = getattr(robot, "motor_inertia_kgm2", None)
        self._motors = None if motors is None else np.asarray(motors, dtype=float)
        self._bodies = []  # (index of the frame it moves with: link i -> i, mass, com, inertia, link frame?)
        for i, link in enumerate(robot.links[1:7], start=1):
            self._bodies.append((i, float(link.mass_kg), np.asarray(link.com_m, float), np.asarray(link.inertia_kgm2,
                                                                                                  float), True))
        pl = robot.payload
        self._bodies.append((6, float(pl.mass_kg), np.asarray(pl.com_m, float), pl.inertia_about_com_kg_m2, False))
        n = len(self._bodies)
        self._stack = {  # the bodies as arrays, for mass_matrix
            "prev": np.array([i - 1 if in_link else 0 for i, _, _, _, in_link in self._bodies]),
            "in_link": np.array([in_link for *_, in_link in self._bodies]),
            "mass": np.array([m for _, m, _, _, _ in self._bodies]),
            "com": np.array([c for _, _, c, _, _ in self._bodies]).reshape(n, 3),
            "inertia": np.array([np.asarray(I, float) for _, _, _, I, _ in self._bodies]).reshape(n, 3, 3),
            "mask": np.array([[j < i for j in range(6)] for i, *_ in self._bodies], dtype=float),
        }

    def _com_jacobians(self, q_rad):
        """(R (body, 3, 3): each body's frame in the base frame; Jv, Jw
        (body, joint, 3): the Jacobians of its centre of mass and of its
        rotation) at model angles q (6,), every body at once."""
        q = np.asarray(q_rad, dtype=float)
        F = kin.frames(self.dh, q)
        z = F[:6, :3, 2]  # joint j's axis: z of frame j-1
        o = F[:6, :3, 3]
        b = self._stack
        # each body's frame: link i's (DH frame i-1 turned by joint i) or DH frame 6 (the payload)
        a = q + np.asarray(self.dh.home_rad, dtype=float)
        c, s = np.cos(a), np.sin(a)
        Rz = np.zeros((6, 3, 3))
        Rz[:, 0, 0], Rz[:, 0, 1], Rz[:, 1, 0], Rz[:, 1, 1], Rz[:, 2, 2] = c, -s, s, c, 1.0
        R = np.where(b["in_link"][:, None, None], F[b["prev"], :3, :3] @ Rz[b["prev"]], F[6, :3, :3])
        p = np.where(b["in_link"][:, None], F[b["prev"], :3, 3], F[6, :3, 3])
        pc = p + np.einsum("bij,bj->bi", R, b["com"])
        Jv = np.cross(z[None, :, :], pc[:, None, :] - o[None, :, :]) * b["mask"][:, :, None]  # (body, joint, 3)
        Jw = z[None, :, :] * b["mask"][:, :, None]
        return R, Jv, Jw

    def mass_matrix(self, q_rad):
        """M(q) (6x6) at model angles q (6,): every body at once (the
        preview compensator refreshes it in its real-time cycle)."""
        R, Jv, Jw = self._com_jacobians(q_rad)
        b = self._stack
        Iw = R @ b["inertia"] @ R.transpose(0, 2, 1)
        return (np.einsum("b,bjk,blk->jl", b["mass"], Jv, Jv)
                + np.einsum("bjk,bkn,bln->jl", Jw, Iw, Jw))

    def gravity_torques(self, q_rad):
        """Joint torques (6,), N*m, that gravity (GRAVITY_M_PER_S2 along the
        base frame's -z) exerts on the links and the payload at model angles q (rad)."""
        _, Jv, _ = self._com_jacobians(q_rad)
        return -GRAVITY_M_PER_S2 * np.einsum("b,bj->j", self._stack["mass"], Jv[:, :, 2])

    def payload_com_jacobian(self, q_rad):
        """(R6 (3x3), Jacobian (3x6) of the payload's centre of mass): its
        linear acceleration is J q'' (velocity products left out)."""
        q = np.asarray(q_rad, dtype=float)
        F = kin.frames(self.dh, q)
        _, _, c, _, _ = self._bodies[-1]
        R6, p6 = F[6, :3, :3], F[6, :3, 3]
        pc = p6 + R6 @ c
        z, e = F[:6, :3, 2], pc - F[:6, :3, 3]
        J = np.empty((3, 6))  # columns z_j x (p_c - o_j)
        J[0] = z[:, 1] * e[:, 2] - z[:, 2] * e[:, 1]
        J[1] = z[:, 2] * e[:, 0] - z[:, 0] * e[:, 2]
        J[2] = z[:, 0] * e[:, 1] - z[:, 1] * e[:, 0]
        return R6, J

    def motor_inertia(self, q_rad):
        """(6,) the motors' rotor inertias reflected to the joints, kg m^2:
        the robot file's ``motor_inertia_kgm2`` (a datasheet's figures);
        a file without them: ASSUMPTION, each equal to its link's inertia
        on the joint at q (a load-to-motor inertia ratio of 1, inside the
        1-5 that servo axes are sized for)."""
        if self._motors is not None:
            return self._motors.copy()
        return np.diag(self.mass_matrix(q_rad)).copy()

    @property
    def payload(self):
        """(mass kg, centre of mass in the sensor frame m)."""
        _, m, c, _, _ = self._bodies[-1]
        return m, c
