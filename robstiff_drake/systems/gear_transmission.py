"""The gears' torque when some have play: between the motor angle theta and
the link angle q each gear transmits

    tau = K dz(theta - q) + D_c (theta' - q')        in contact,
    tau = 0                                           inside its play,

dz the dead zone of half-width b (model/transmission.play_torque), K the
gears' (coupled) stiffness and D_c their damping (the station's modal
damping matrix) restricted to the gears in contact.  Which flank is in
contact is the link's own state: where it sits in the gap.

Impacts.  The flanks meet as a spring-damper (Kelvin-Voigt contact), and
the contact can only push: when the damper would pull the flanks together
as they separate, the torque is zero instead.  That is the "physical"
backlash model of Nordin, Galic and Gutman ("New models for backlash and
gear play", Int. J. Adaptive Control and Signal Processing 11(1):49-63,
1997; surveyed in Nordin and Gutman, "Controlling mechanical systems with
backlash - a survey", Automatica 38(10):1633-1649, 2002), which corrects
the plain dead-zone model's tension at separation.  An impact of a link
of inertia J on a gear of stiffness k then rebounds with the coefficient
of restitution exp(-pi zeta / sqrt(1 - zeta^2)), zeta = d / (2 sqrt(k J))
(d the gear's damping): the gear's own damping, no extra parameter.

Friction inside the play.  While the flanks are apart the gear still
drags its link with a Coulomb torque T_c (model/transmission.gap_friction_Nm
gives its size and source) against the twist rate, explicit like the rest:
at most the torque that stops the relative motion within the step
(J_eff |phi'| / h, 1/J_eff = (M^-1)_jj + 1/J_m,j), so it sticks instead of
chattering.  Without it a link released from a flank rattles in its play
until the impacts' own damping has taken the energy.

Without play the gear is linear and the station uses a MatrixGain
instead (no Python in the step)."""

import numpy as np
from pydrake.systems.framework import LeafSystem


class GearPlay(LeafSystem):
    """Inputs ``motor_state`` (12: theta, theta' rad, rad/s) and
    ``link_state`` (12: q, q'); output ``gear_torque`` (6, N*m: on the link;
    the motor feels minus it)."""

    def __init__(self, *, stiffness_Nm_per_rad, damping_Nms_per_rad, play_rad, gap_friction_Nm=None,
                 gap_inertia_kgm2=None, step_s=None):
        """``gap_friction_Nm`` (6,) the Coulomb torque inside the play (None:
        none), ``gap_inertia_kgm2`` (6,) J_eff of each gear's twist and
        ``step_s`` the plant's step (both needed with friction)."""
        super().__init__()
        self._Tc = None if gap_friction_Nm is None else np.asarray(gap_friction_Nm, dtype=float)
        if self._Tc is not None:
            self._stop = np.asarray(gap_inertia_kgm2, dtype=float) / float(step_s)
        self._K = np.asarray(stiffness_Nm_per_rad, dtype=float)
        self._D = np.asarray(damping_Nms_per_rad, dtype=float)
        self._b = np.asarray(play_rad, dtype=float)
        self._has_play = self._b > 0
        self._motor = self.DeclareVectorInputPort("motor_state", 12)
        self._link = self.DeclareVectorInputPort("link_state", 12)
        self.DeclareVectorOutputPort("gear_torque", 6, self._calc,
                                     prerequisites_of_calc={self._motor.ticket(), self._link.ticket()})

    def torque(self, motor_state, link_state):
        """The gears' torque (6, N*m) on the links at these states."""
        phi = motor_state[:6] - link_state[:6]
        rate = motor_state[6:] - link_state[6:]
        b = self._b
        dz = phi - np.clip(phi, -b, b)
        contact = ~self._has_play | (np.abs(phi) > b)
        tau = self._K @ dz + (self._D * np.outer(contact, contact)) @ rate
        # no tension: a flank in contact can only push (the sign of its dead-zone twist)
        pulls = self._has_play & (tau * dz < 0.0)
        tau = np.where(contact & ~pulls, tau, 0.0)
        if self._Tc is not None:
            gap = ~contact
            tau = np.where(gap, np.sign(rate) * np.minimum(self._Tc, self._stop * np.abs(rate)), tau)
        return tau

    def _calc(self, context, output):
        output.SetFromVector(self.torque(self._motor.Eval(context), self._link.Eval(context)))
