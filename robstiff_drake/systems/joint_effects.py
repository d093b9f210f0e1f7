"""Effects of the plant's joints beyond its six springs, for simulating a
robot that the compensator's model does not fully describe: lost motion
(backlash: the link lags the motor by b_i in the direction of the joint
load) and coupling between joints 2 and 3 (the parallel arm).  They shift
the servo's set-point, which in the servo-spring joint model is the same as an extra
deflection: dq_i = b_i sign(tau_i) and dq_2 = c23 tau_3, dq_3 = c23 tau_2,
with tau the process load's joint torques.  The sign is smoothed,
tanh(tau / 50 N*m): near zero load the backlash is taken up gradually (by
friction and the gear's preload), not in a jump that a torque of a few
newtons either way would flip.  The laws are model/joint_effects.py's."""

import numpy as np
from pydrake.systems.framework import LeafSystem

from robstiff_drake.model.joint_effects import LOST_MOTION_TORQUE_NM, effect_dq

__all__ = ["JointEffects", "LOST_MOTION_TORQUE_NM", "effect_dq"]


class JointEffects(LeafSystem):
    """Inputs ``desired_state`` (12: q, v commanded) and ``joint_torque`` (6,
    the process load's joint torques); output ``desired_state`` (12) with
    the positions shifted by effect_dq.  Recomputed when an input changes."""

    def __init__(self, *, lost_motion_rad, coupling_c23_rad_per_Nm):
        super().__init__()
        self._b = np.asarray(lost_motion_rad, dtype=float)
        self._c23 = float(coupling_c23_rad_per_Nm)
        self._x = self.DeclareVectorInputPort("desired_state", 12)
        self._tau = self.DeclareVectorInputPort("joint_torque", 6)
        self.DeclareVectorOutputPort("desired_state", 12, self._calc,
                                     prerequisites_of_calc={self._x.ticket(), self._tau.ticket()})

    def _calc(self, context, output):
        x = self._x.Eval(context).copy()
        x[:6] += effect_dq(self._tau.Eval(context), self._b, self._c23)
        output.SetFromVector(x)
