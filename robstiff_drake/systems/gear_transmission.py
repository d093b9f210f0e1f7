"""The gears' lost motion and joint coupling in the plant: the joint servo
spring is linear, K (theta - q); a gear with play or coupling transmits the
torque of model/transmission.py instead.  This system hands the spring the
motor angle that makes its linear torque equal the law's:

    theta_eff = q + c * torque(theta - q)

so the plant carries exactly one law, the one the compensator's model uses.
Only in the diagram when the plant has lost motion or coupling."""

import numpy as np
from pydrake.systems.framework import LeafSystem

from robstiff_drake.model import transmission


class GearTransmission(LeafSystem):
    """Inputs ``motor_state`` (12: theta, theta' rad, rad/s) and ``link_state``
    (12: q, q'); output ``spring_setpoint`` (12): (theta_eff, theta')."""

    def __init__(self, *, joint_stiffness_Nm_per_rad, lost_motion_rad, coupling_c23_rad_per_Nm):
        super().__init__()
        self._c = 1.0 / np.asarray(joint_stiffness_Nm_per_rad, dtype=float)
        self._b = np.asarray(lost_motion_rad if lost_motion_rad else np.zeros(6), dtype=float)
        self._c23 = float(coupling_c23_rad_per_Nm)
        self._motor = self.DeclareVectorInputPort("motor_state", 12)
        self._link = self.DeclareVectorInputPort("link_state", 12)
        self.DeclareVectorOutputPort("spring_setpoint", 12, self._calc,
                                     prerequisites_of_calc={self._motor.ticket(), self._link.ticket()})

    def _calc(self, context, output):
        m = self._motor.Eval(context)
        q = self._link.Eval(context)[:6]
        tau = transmission.torque(m[:6] - q, self._c, self._b, self._c23)
        out = m.copy()
        out[:6] = q + self._c * tau
        output.SetFromVector(out)
