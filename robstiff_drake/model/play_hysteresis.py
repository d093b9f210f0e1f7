"""The compensator's hysteretic play law: where each gear sits in its gap,
tracked from the history of the torque it carries.  Plain numpy.

A gear with play of half-width b (rad) and Coulomb friction T_c (N*m)
inside the gap (the plant's: systems/gear_transmission.py) holds its link
on a flank while the torque presses that flank; when the torque reverses,
the flanks part but the friction holds the link where it is until the
torque passes T_c the other way, and then the link crosses the gap to the
other flank.  While |torque| <= T_c the link stays wherever it is in the
gap.  So the gear's position in its gap, p in [-b, b], is a state:

    p <- +b          if tau > T_c
    p <- -b          if tau < -T_c
    p <- p           otherwise

and the twist is the elastic twist C tau of the gears in contact (on the
flank their torque presses; none inside the gap, where the friction
carries the torque) plus p:

    phi = C (tau * in_contact) + p.

A joint without play (b = 0) is always in contact.  No single-valued law
of the torque (model/transmission.twist's smooth one) can follow this:
between -T_c and T_c the twist depends on which way the torque came.

At the touch-off the arm stands still under its weight, each gear on the
flank its holding torque presses (in the middle of its gap where it
carries none: model/transmission.play_twist's convention): ``start``.
The touch-off takes up that position (``reference``); what the
compensator corrects is the process load's twist and how far each gear
has moved in its gap since (``deflection``).
"""

import numpy as np

from robstiff_drake.model import transmission

# The compensator's crossing lands on its flank decelerating at no more than this fraction of |tau| / J (``crossing_step``'s
# soft_landing).  CHOSEN, with its evidence, not derived: the correction reaches the motor through the rate limit,
# the delay and the servo, and the arm rings on its flank after the impact, so the link keeps less than the whole
# pressing torque to follow a decelerating motor.  On the balanced pass (studies/play_diagnosis.py, joint 2, 20-300
# urad) 1 leaves the link lifting 19 urad off its flank at 150 urad and 0.098 mm rms; 0.5: 0.080; 0.25: 0.056; 0.1:
# 0.046 (the face without play: 0.049).  0.25, not less: a slower landing lags a plant that has landed already.
LANDING_FRACTION = 0.25


def start(tau_Nm, play_rad):
    """(6,) the gears' positions in their gaps (rad) at rest under the
    torque ``tau_Nm``: on the flank the torque presses, in the middle where
    the gear carries none (below transmission.PLAY_UNLOADED_NM)."""
    tau = np.asarray(tau_Nm, dtype=float)
    b = np.asarray(play_rad, dtype=float)
    return b * np.sign(tau) * (np.abs(tau) > transmission.PLAY_UNLOADED_NM)


def step(position_rad, tau_Nm, play_rad, friction_Nm):
    """(6,) the gears' positions in their gaps (rad) after they carry
    ``tau_Nm`` from ``position_rad``: on the flank the torque presses where
    it exceeds the friction ``friction_Nm`` (N*m), else where they were."""
    tau = np.asarray(tau_Nm, dtype=float)
    b = np.asarray(play_rad, dtype=float)
    fr = np.asarray(friction_Nm, dtype=float)
    p = np.clip(np.asarray(position_rad, dtype=float), -b, b)
    return np.where(tau > fr, b, np.where(tau < -fr, -b, p))


def in_contact(position_rad, tau_Nm, play_rad):
    """(6,) bool: the gears whose teeth carry the torque: no play, or on the
    flank the torque presses (a gear at rest on a flank with no torque
    counts as in contact: its twist is the same either way)."""
    tau = np.asarray(tau_Nm, dtype=float)
    b = np.asarray(play_rad, dtype=float)
    p = np.asarray(position_rad, dtype=float)
    flank = np.abs(p) >= b * (1.0 - 1e-12)
    return (b <= 0.0) | (flank & (p * tau >= 0.0))


def twist(tau_Nm, position_rad, compliance_rad_per_Nm, play_rad, coupling_c23_rad_per_Nm=0.0):
    """(6,) the gears' twist (rad) carrying ``tau_Nm`` at positions
    ``position_rad`` in their gaps (the positions after this torque:
    ``step``): the elastic twist of the gears in contact plus the position."""
    tau = np.asarray(tau_Nm, dtype=float)
    loaded = np.where(in_contact(position_rad, tau, play_rad), tau, 0.0)
    return transmission.twist(loaded, compliance_rad_per_Nm, None, coupling_c23_rad_per_Nm) + \
        np.asarray(position_rad, dtype=float)


def deflection(tau_hold_Nm, tau_process_Nm, position_rad, reference_rad, compliance_rad_per_Nm, play_rad,
               coupling_c23_rad_per_Nm=0.0):
    """(6,) the link's deflection (rad) the compensator corrects: the gears
    hold the arm with ``tau_hold_Nm`` (gravity, N*m) and carry
    ``tau_hold - tau_process`` now, at ``position_rad`` in their gaps; the
    touch-off took up ``reference_rad`` and the controller's gravity model
    the elastic twist of the holding torque.  Without play: C tau_process."""
    th = np.asarray(tau_hold_Nm, dtype=float)
    carried = th - np.asarray(tau_process_Nm, dtype=float)
    held = transmission.twist(th, compliance_rad_per_Nm, None, coupling_c23_rad_per_Nm)
    return held + np.asarray(reference_rad, dtype=float) - twist(carried, position_rad, compliance_rad_per_Nm,
                                                                 play_rad, coupling_c23_rad_per_Nm)


def replay(tau_Nm, play_rad, friction_Nm, compliance_rad_per_Nm, coupling_c23_rad_per_Nm=0.0):
    """(n, 6) the twist (rad) of a sequence of torques ((n, 6) N*m, each
    reached at rest from the one before), the gears starting at rest under
    the first."""
    taus = np.atleast_2d(np.asarray(tau_Nm, dtype=float))
    p = start(taus[0], play_rad)
    out = np.empty_like(taus)
    for i, tau in enumerate(taus):
        p = step(p, tau, play_rad, friction_Nm)
        out[i] = twist(tau, p, compliance_rad_per_Nm, play_rad, coupling_c23_rad_per_Nm)
    return out


def crossing_step(position_rad, rate_rad_per_s, tau_Nm, play_rad, friction_Nm, inertia_kgm2, dt_s, soft_landing=False):
    """(positions (6, rad), rates (6, rad/s)) of the gears in their gaps
    after ``dt_s`` carrying ``tau_Nm``, the link crossing its gap under the
    torque beyond the friction, ``inertia_kgm2`` (6,) the link's inertia
    about its joint (its motor held by the servo): phi'' = (tau - T_c
    sign(phi')) / J while moving, no motion while |tau| <= T_c at rest; a
    flank stops it.  The quasi-static ``step`` crosses at once instead; a
    link of an arm takes a few hundred ms to cross a few hundred urad.

    ``soft_landing``: the compensator's crossing (model/compensator.
    DeflectionModel.play_crossing) ends at rest on the flank ahead: its speed
    is held to what the torque pressing the link onto that flank, a
    fraction of |tau| (LANDING_FRACTION), can take off over the distance
    left (v <= sqrt(2 LANDING_FRACTION |tau| / J d)).  The
    correction follows this position, and a correction that stops dead at
    the flank drives the motor into a stop the lightly pressed link cannot
    follow: in studies/play_diagnosis.py's pass (b2 = 150 urad) the plant's
    link then lifts about 70 urad off its flank for about 0.1 s and the face
    keeps that overcut."""
    tau = np.asarray(tau_Nm, dtype=float)
    b = np.asarray(play_rad, dtype=float)
    fr = np.asarray(friction_Nm, dtype=float)
    v = np.asarray(rate_rad_per_s, dtype=float)
    moving = v != 0.0
    net = np.where(moving, tau - fr * np.sign(v), np.where(np.abs(tau) > fr, tau - fr * np.sign(tau), 0.0))
    v_new = v + net / np.asarray(inertia_kgm2, dtype=float) * dt_s
    v_new = np.where(moving & (v_new * v < 0.0), 0.0, v_new)  # friction stops it, never reverses it
    if soft_landing:
        # the flank ahead reached at rest: at most sqrt(2 a d) + a dt, d the distance left, a = f |tau| / J the
        # deceleration the torque pressing the link onto that flank can give it (the a dt: one step's worth,
        # so that the flank is reached in a finite number of steps)
        p0 = np.asarray(position_rad, dtype=float)
        ahead = np.maximum(np.where(v_new > 0.0, b - p0, p0 + b), 0.0)
        a = LANDING_FRACTION * np.abs(tau) / np.asarray(inertia_kgm2, dtype=float)
        v_new = np.sign(v_new) * np.minimum(np.abs(v_new), np.sqrt(2.0 * a * ahead) + a * dt_s)
    p = np.asarray(position_rad, dtype=float) + v_new * dt_s
    hit = (p >= b) & (v_new > 0.0) | (p <= -b) & (v_new < 0.0)
    return np.clip(p, -b, b), np.where(hit | (b <= 0.0), 0.0, v_new)
