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
drags its link with a Coulomb torque of at most T_c
(model/transmission.gap_friction_Nm gives its size and source), a
discrete stick-slip law in the manner of Karnopp's ("Computer simulation of
stick-slip friction in mechanical dynamic systems", J. Dyn. Sys., Meas.,
Control 107(1):100-103, 1985; reviewed in Olsson, Astrom, Canudas de Wit,
Gafvert and Lischinsky, "Friction models and friction compensation",
European Journal of Control 4(3):176-195, 1998): each step the friction is
the torque that brings the twist rate phi' = theta' - q' to zero by the
next step, clipped at +-T_c (sticking inside the clip, sliding at T_c
outside it).  The twist obeys phi'' = a - tau / J_eff (1/J_eff =
(M^-1)_jj + 1/J_m,j, the link with the rest of the arm free, in series
with its motor; a: every other torque on the twist), and the rest's a is
read from the last step (the discrete state holds the gear's torque and
twist rate then: J_eff a = J_eff (phi'_k - phi'_k-1) / h + tau_k-1), so

    tau_k = clip(tau_k-1 + g J_eff (2 phi'_k - phi'_k-1) / h, -T_c, T_c),

g = HOLD_GAIN; on the first step after the flanks part (the last step's
torque beyond T_c: a contact's) the rest is taken as nil, tau_k =
clip(g J_eff phi'_k / h), since the contact's torque, which changed within
that step, says nothing about it.  With g J_eff the twist's true inertia over a step, a
constant a below T_c / J_eff would be held in one step (deadbeat); the law
is stable while g J_eff is below 4/3 of the true inertia.  J_eff (the rest
of the arm free) is not quite the plant's: at g = 1 joint 6 of the
IRB 6400 holding 2 N*m in its play chatters at period two without decay
(the true inertia over a step about 3/4 of J_eff), so g = 1/2: the twist
rate then decays by about 0.6 per step and the link stays put (0.01 b of
drift over a second, tests/test_gear_play_resolution.py).  Friction read
from the rate alone (at most J_eff |phi'| / h, before) let the link creep
through its play at about a h / 2.  Without friction a link released
from a flank rattles in its play until the impacts' own damping has taken
the energy.

Without play the gear is linear and the station uses a MatrixGain
instead (no Python in the step)."""

import numpy as np
from robstiff_drake.systems.leaf_system import LeafSystem

HOLD_GAIN = 0.5  # g of the stick-slip law: the share of J_eff taken as the twist's inertia (module docstring)


class GearPlay(LeafSystem):
    """Inputs ``motor_state`` (12: theta, theta' rad, rad/s) and
    ``link_state`` (12: q, q'); output ``gear_torque`` (6, N*m: on the link;
    the motor feels minus it).  With friction in the play, a discrete state
    (12: the last step's gear torque N*m and twist rate rad/s) updated
    every plant step."""

    def __init__(self, *, stiffness_Nm_per_rad, damping_Nms_per_rad, play_rad, gap_friction_Nm=None,
                 gap_inertia_kgm2=None, step_s=None):
        """``gap_friction_Nm`` (6,) the Coulomb torque inside the play (None:
        none), ``gap_inertia_kgm2`` (6,) J_eff of each gear's twist and
        ``step_s`` the plant's step (both needed with friction)."""
        super().__init__()
        self._Tc = None if gap_friction_Nm is None else np.asarray(gap_friction_Nm, dtype=float)
        self._K = np.asarray(stiffness_Nm_per_rad, dtype=float)
        self._D = np.asarray(damping_Nms_per_rad, dtype=float)
        self._b = np.asarray(play_rad, dtype=float)
        self._has_play = self._b > 0
        self._motor = self.DeclareVectorInputPort("motor_state", 12)
        self._link = self.DeclareVectorInputPort("link_state", 12)
        prerequisites = {self._motor.ticket(), self._link.ticket()}
        if self._Tc is not None:
            self._J_per_h = HOLD_GAIN * np.asarray(gap_inertia_kgm2, dtype=float) / float(step_s)
            self._last = self.DeclareDiscreteState(12)  # the last step's gear torque (6) and twist rate (6)
            self.DeclarePeriodicDiscreteUpdateEvent(float(step_s), 0.0, self._remember)
            prerequisites.add(self.discrete_state_ticket(self._last))
        self.DeclareVectorOutputPort("gear_torque", 6, self._calc, prerequisites_of_calc=prerequisites)

    def torque(self, motor_state, link_state, last=None):
        """The gears' torque (6, N*m) on the links at these states, ``last``
        (12) the last step's gear torque and twist rate (None: zeros, at
        rest)."""
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
            last = np.zeros(12) if last is None else np.asarray(last, dtype=float)
            # the torque that stops the twist by the next step, the rest's torque read from the last step; after
            # a step in contact (a torque beyond the friction's clip) the rest is taken as nil: the contact's
            # torque changed within that step, so reading the rest from it gave the flank's push (hundreds of
            # N*m) and a friction of the contact's sign for a step after the flanks separated, whatever the
            # twist's direction
            after_contact = np.abs(last[:6]) > self._Tc * (1.0 + 1e-9)
            hold = np.where(after_contact, self._J_per_h * rate, last[:6] + self._J_per_h * (2.0 * rate - last[6:]))
            tau = np.where(contact, tau, np.clip(hold, -self._Tc, self._Tc))
        return tau

    def _last_value(self, context):
        return context.get_discrete_state(self._last).get_value() if self._Tc is not None else None

    def _calc(self, context, output):
        output.SetFromVector(self.torque(self._motor.Eval(context), self._link.Eval(context),
                                         self._last_value(context)))

    def _remember(self, context, state):
        motor, link = self._motor.Eval(context), self._link.Eval(context)
        tau = self.torque(motor, link, self._last_value(context))
        state.get_mutable_vector(self._last).SetFromVector(np.concatenate([tau, motor[6:] - link[6:]]))
