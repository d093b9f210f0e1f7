"""The compensator's lost-motion law identified per joint from a campaign:
pairs of (torque on the gear, twist at rest) that load the joint both ways
fitted with the smooth law of model/transmission.twist,

    phi = c tau + b tanh(tau / tau_b),

the compliance c known (the stiffness identification's), the lost motion
b and its take-up torque tau_b fitted by least squares (scipy), tau_b on a
log scale so that it stays positive.  A gear with play and friction inside
it (the plant's: systems/gear_transmission.py) sits anywhere in its play
under a torque below the friction, so the fit's residual there is the
play's own scatter, not noise; what the fit gives is the law that predicts
the twist of a loaded joint best in the least-squares sense.  Without a
campaign the compensator uses transmission.fallback_take_up_Nm.

The same campaign gives the hysteretic law's parameters
(model/play_hysteresis.py; ``fit_hysteretic_play``): the play b from the
samples on the flank their torque presses, and the friction inside the
play from the reversals: each level of the staircase reverses the torque,
and a reversal from the other flank whose torque is below the friction
leaves the link there (or creeps it part of the way: the plant's friction
sticks only within its step), one above it carries the link across.  The
friction lies between the largest reversal that did not cross and the
smallest that did (the campaign's levels double, so that bracket is a
factor 2 wide); the estimate is its middle.
"""

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from robstiff_drake.model import play_hysteresis


@dataclass
class PlayLaw:
    lost_motion_rad: float  # b
    take_up_Nm: float  # tau_b
    rms_rad: float  # the fit's residual (rad)
    n: int  # samples


def fit_play_law(tau_Nm, twist_rad, compliance_rad_per_Nm, take_up_start_Nm=10.0):
    """The PlayLaw of one joint from its samples (torque N*m, twist rad, at
    rest) and its compliance (rad/(N*m)).  Raises ValueError without
    torques of both signs (the lost motion shows only between them)."""
    tau = np.asarray(tau_Nm, dtype=float)
    lost = np.asarray(twist_rad, dtype=float) - float(compliance_rad_per_Nm) * tau
    if not (np.any(tau > 0) and np.any(tau < 0)):
        raise ValueError("a play campaign needs torques of both signs on the joint")
    b0 = max(0.5 * (np.max(lost) - np.min(lost)), 1e-9)

    def residual(x):
        return x[0] * np.tanh(tau / np.exp(x[1])) - lost

    fit = least_squares(residual, [b0, np.log(take_up_start_Nm)], bounds=([0.0, np.log(1e-3)], [np.inf, np.log(1e5)]),
                        x_scale=[b0, 1.0])
    return PlayLaw(lost_motion_rad=float(fit.x[0]), take_up_Nm=float(np.exp(fit.x[1])),
                   rms_rad=float(np.sqrt(np.mean(fit.fun ** 2))), n=int(tau.size))


@dataclass
class HystereticPlayLaw:
    lost_motion_rad: float  # b, the play's half-width
    friction_Nm: float  # T_c, the friction inside the play (the middle of the bracket)
    friction_bracket_Nm: tuple  # (largest reversal that did not cross, smallest that did), N*m
    rms_rad: float  # the law's residual over the campaign, replayed in order (rad)
    n: int  # samples


def fit_hysteretic_play(tau_Nm, twist_rad, compliance_rad_per_Nm):
    """The HystereticPlayLaw of one joint from its campaign's samples in the
    order they were taken (torque N*m, twist rad, at rest, each level
    reached from the one before; the first from rest on its own flank) and
    its compliance (rad/(N*m)).  Raises ValueError without a reversal that
    crossed the play (the torques never overcame the friction)."""
    tau = np.asarray(tau_Nm, dtype=float)
    phi = np.asarray(twist_rad, dtype=float)
    c = float(compliance_rad_per_Nm)
    if not (np.any(tau > 0) and np.any(tau < 0)):
        raise ValueError("a play campaign needs torques of both signs on the joint")
    # the play offset on the side the torque presses: +b on that flank, -b - c|tau| on the other, -c|tau|
    # in the middle
    own = phi * np.sign(tau) - c * np.abs(tau)
    crossed = own > 0.5 * np.max(own)
    if not np.any(crossed) or np.max(own) <= 0.0:
        raise ValueError("no sample of the play campaign sits on the flank its torque presses")
    b = float(np.median(own[crossed]))
    # a reversal tests the friction when the link starts it on the other flank (where the torque before
    # pressed it): it crosses, or it stays
    reversal = np.r_[False, (np.sign(tau[1:]) != np.sign(tau[:-1])) & (phi[:-1] * np.sign(tau[1:]) < -0.5 * b)]
    if not np.any(reversal & crossed):
        raise ValueError(f"no reversal of the play campaign crossed the play (up to {np.max(np.abs(tau)):g} N*m): "
                         "the friction inside it is larger; load the joint harder")
    hi = float(np.min(np.abs(tau[reversal & crossed])))
    stuck = reversal & ~crossed & (np.abs(tau) < hi)
    lo = float(np.max(np.abs(tau[stuck]))) if np.any(stuck) else 0.0
    friction = 0.5 * (lo + hi)
    law = play_hysteresis.replay(tau[:, None], [b], [friction], [c])[:, 0]
    return HystereticPlayLaw(lost_motion_rad=b, friction_Nm=friction, friction_bracket_Nm=(lo, hi),
                             rms_rad=float(np.sqrt(np.mean((law - phi) ** 2))), n=int(tau.size))
