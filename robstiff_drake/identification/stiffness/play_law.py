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
"""

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares


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
