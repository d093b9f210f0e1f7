"""A play campaign on the plant: one joint of the bare compliant arm
(diagrams/gear_impacts.joint_load_run), its controller holding the pose,
loaded by a staircase of torques of both signs (CAMPAIGN_LEVELS_NM, scaled,
each held HOLD_S), and its gear's twist theta - q read at rest at the end
of each hold: the samples identification/stiffness/play_law.fit_play_law
fits the compensator's lost-motion law to.  On a real arm the twist is
the encoder's motor angle less the link angle a tracker reads; here it is
read without noise (the scatter inside the play is the play's own)."""

import numpy as np
from robstiff_drake.systems.leaf_system import LeafSystem

from robstiff_drake.diagrams.gear_impacts import joint_load_run

# Alternating signs and growing sizes (times the campaign's scale), as a campaign that loads a joint both ways
# from small to large torques: each level approaches from the other side of the play.
CAMPAIGN_LEVELS_NM = (0.5, -0.5, 1.0, -1.0, 2.0, -2.0, 4.0, -4.0, 8.0, -8.0, 16.0, -16.0, 32.0, -32.0)
HOLD_S = 0.15  # each level held (s): the wrist's 126 Hz mode at 5 % rings down in 0.1 s


class JointStaircase(LeafSystem):
    """Torques ``levels_Nm`` on joint ``joint``'s link, each for ``hold_s``."""

    def __init__(self, joint, levels_Nm, hold_s):
        super().__init__()
        self._j, self._levels, self._hold = int(joint), np.asarray(levels_Nm, dtype=float), float(hold_s)
        self.DeclareVectorOutputPort("tau", 6, self._calc)

    def _calc(self, context, output):
        i = min(int(context.get_time() / self._hold + 1e-9), len(self._levels) - 1)
        tau = np.zeros(6)
        tau[self._j] = self._levels[i]
        output.SetFromVector(tau)


def play_campaign(robot, q_rad, *, joint, play_rad, step_s, servo, scale_Nm=1.0, gap_friction_Nm=None):
    """(torque on the gear (n,), twist at rest (n,)) of the staircase on
    ``joint`` (N*m, rad): the gear carries minus the load on its link, so
    the torque is -level."""
    levels = scale_Nm * np.asarray(CAMPAIGN_LEVELS_NM)
    t, phi, _ = joint_load_run(robot, q_rad, JointStaircase(joint, levels, HOLD_S), step_s=step_s,
                               play_rad=play_rad, joint=joint, initial_load_Nm=levels[0],
                               duration_s=HOLD_S * len(levels), servo=servo, gap_friction_Nm=gap_friction_Nm)
    ends = [int(np.searchsorted(t, (i + 1) * HOLD_S - 1e-9)) - 1 for i in range(len(levels))]
    return -levels, phi[ends]
