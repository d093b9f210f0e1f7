"""The arm's joint-space inertia as a compensator would model it: rigid
links with the robot file's masses and inertias (the manufacturer's
nominal dynamic model), the payload on the flange, and nothing of the
plant's own code.  Plain numpy.

    M(q) = sum over bodies b of  m_b J_v,b^T J_v,b + J_w,b^T R_b I_b R_b^T J_w,b

with J_v,b the Jacobian of body b's centre of mass and J_w,b of its
rotation (only the joints before it move it).  Link i's frame is DH frame
i-1 turned by joint i (model/description.py writes the URDF so); the
payload hangs on the flange (DH frame 6).  Velocity-product (Coriolis)
terms are left out: at machining feeds (tens of mm/s) they are 1e-4 of
the inertial terms of a corner.

Tested against Drake's CalcMassMatrix of the robot file's plant
(tests/test_preview.py).

Units: q in rad (model angles), lengths m, masses kg, inertias kg m^2.
"""

import numpy as np

from robstiff_drake.model import kinematics as kin


def _rot_z(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


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

    def _body_frame(self, F, q, i, in_link_frame):
        """(R, p) of the frame a body's data is given in: link i's URDF frame
        (DH frame i-1 turned by joint i), or DH frame 6 (the payload)."""
        if not in_link_frame:
            return F[6, :3, :3], F[6, :3, 3]
        T = F[i - 1]
        return T[:3, :3] @ _rot_z(q[i - 1] + self.dh.home_rad[i - 1]), T[:3, 3]

    def mass_matrix(self, q_rad):
        """M(q) (6x6) at model angles q (6,)."""
        q = np.asarray(q_rad, dtype=float)
        F = kin.frames(self.dh, q)
        z = F[:6, :3, 2]  # joint j's axis: z of frame j-1
        o = F[:6, :3, 3]
        M = np.zeros((6, 6))
        for i, m, c, I, in_link in self._bodies:
            R, p = self._body_frame(F, q, i, in_link)
            pc = p + R @ c
            Jv = np.zeros((3, 6))
            Jw = np.zeros((3, 6))
            Jv[:, :i] = np.cross(z[:i], pc - o[:i]).T
            Jw[:, :i] = z[:i].T
            Iw = R @ I @ R.T
            M += m * Jv.T @ Jv + Jw.T @ Iw @ Jw
        return M

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
