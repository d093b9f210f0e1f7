"""The joint effects beyond the six springs, as laws (plain numpy): lost
motion (backlash: the link lags the motor by b_i in the direction of the
joint load) and coupling between joints 2 and 3.  dq_i = b_i sign(tau_i)
and dq_2 = c23 tau_3, dq_3 = c23 tau_2, with tau the process load's joint
torques.  The sign is smoothed, tanh(tau / 50 N*m): near zero load the
backlash is taken up gradually (by friction and the gear's preload), not in
a jump that a torque of a few newtons either way would flip.  The plant's
block (systems/joint_effects.py) and the compensator's model both use it."""

import numpy as np

LOST_MOTION_TORQUE_NM = 50.0  # torque over which the backlash is taken up (tanh scale)


def effect_dq(tau, lost_motion_rad, coupling_c23):
    """Extra joint deflection (rad) of lost motion and 2-3 coupling for joint torques tau (N*m)."""
    dq = np.asarray(lost_motion_rad, dtype=float) * np.tanh(np.asarray(tau) / LOST_MOTION_TORQUE_NM)
    dq[1] += coupling_c23 * tau[2]
    dq[2] += coupling_c23 * tau[1]
    return dq
