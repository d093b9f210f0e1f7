"""The joint transmission between motor and link: one law for the plant and
for every model of it.

A joint's gear twists by ``phi = theta - q`` (motor angle minus link angle,
rad) under the torque ``tau`` it transmits (N*m): the total torque on the
link side, gravity, inertia and process load together, which is what a
gear actually carries.

    phi = c tau + b tanh(tau / TAU_B_j)        (each joint)
    phi_2 += c23 tau_3,  phi_3 += c23 tau_2     (the 2-3 coupling)

``c`` is the joint compliance (rad/(N*m)), ``b`` the lost motion (rad: half
the backlash or the gear's play, taken up in the direction of the load).
The sign of the load is smoothed over TAU_B_j (per joint: identified from a
campaign, else ``fallback_take_up_Nm``, which diagnose-run uses too):
near zero torque the play is
taken up gradually (friction and the gear's preload), not in a jump that a
few newton-metres either way would flip.  Where the total torque keeps its
sign, the lost motion is a constant offset that any static model absorbs;
it shows only where the total torque changes sign.

Plain numpy.  That smooth law is ``diagnose-run``'s lost-motion cause and
one of the compensator's two laws (the other, hysteretic:
model/play_hysteresis.py).  The plant's gears have play
(``play_torque``): a dead zone of total width 2b in which the gear
transmits no torque, the gear's stiffness outside it; which flank is in
contact is the link's own state (where it sits in the gap), so a load that
reverses slowly leaves a hysteresis loop of width 2b and slopes 1/k, and a
load that falls to zero leaves the link on the flank it last pressed.
How the impacts at the flanks are damped: systems/gear_transmission.py.
"""

import numpy as np

TAU_B_NM = 50.0  # the former take-up torque (tanh scale) of every joint, N*m: twist's default without take_up_Nm

# The compensator's take-up torque TAU_B per joint is identified from a campaign that loads each joint both ways
# (identification/stiffness/play_law.py; diagrams/play_campaign.py runs one on the plant).  Without one, the
# FALLBACK: the play is taken up by the torque at which reducer makers measure lost motion, 3 % of the rated
# torque (RV reducer test practice, see GAP_FRICTION_FRACTION), tanh(tau / TAU_B) = 0.96 there: TAU_B = 1.5 %
# of the rated torque (rated: K * RATED_TWIST_RAD).  IRB 6400 joint 6: 3.3 N*m, against the 50 N*m that
# predicted 8.6e-5 rad at 8 N*m where the play plant twists 3.3e-4 rad.
LOST_MOTION_TEST_FRACTION = 0.03


def fallback_take_up_Nm(compliance_rad_per_Nm):
    """(6,) the take-up torque TAU_B (N*m) without a campaign (see
    LOST_MOTION_TEST_FRACTION) for the compliances (rad/(N*m))."""
    return 0.5 * LOST_MOTION_TEST_FRACTION * RATED_TWIST_RAD / np.asarray(compliance_rad_per_Nm, dtype=float)


def twist(tau_Nm, compliance_rad_per_Nm, lost_motion_rad=None, coupling_c23_rad_per_Nm=0.0, take_up_Nm=None):
    """Gear twist phi (rad) of joint torques ``tau_Nm`` ((..., 6) N*m);
    ``take_up_Nm`` the tanh scale TAU_B per joint ((6,) N*m; None:
    TAU_B_NM for every joint)."""
    tau = np.asarray(tau_Nm, dtype=float)
    phi = np.asarray(compliance_rad_per_Nm, dtype=float) * tau
    if lost_motion_rad is not None and np.any(np.asarray(lost_motion_rad) != 0):
        tb = TAU_B_NM if take_up_Nm is None else np.asarray(take_up_Nm, dtype=float)
        phi = phi + np.asarray(lost_motion_rad, dtype=float) * np.tanh(tau / tb)
    if coupling_c23_rad_per_Nm:
        phi = phi.copy()
        phi[..., 1] += coupling_c23_rad_per_Nm * tau[..., 2]
        phi[..., 2] += coupling_c23_rad_per_Nm * tau[..., 1]
    return phi


def torque(phi_rad, compliance_rad_per_Nm, lost_motion_rad=None, coupling_c23_rad_per_Nm=0.0, iterations=30,
           tol_Nm=1e-9, take_up_Nm=None):
    """The torque (N*m) a gear twisted by ``phi_rad`` (6,) transmits: the
    inverse of ``twist`` (Newton's method; the law is strictly monotonic, so
    the answer is unique)."""
    phi = np.asarray(phi_rad, dtype=float)
    c = np.asarray(compliance_rad_per_Nm, dtype=float)
    b = np.zeros(6) if lost_motion_rad is None else np.asarray(lost_motion_rad, dtype=float)
    c23 = float(coupling_c23_rad_per_Nm)
    C = np.diag(c)
    C[1, 2] = C[2, 1] = c23
    tau = np.linalg.solve(C, phi)  # the linear answer, exact without lost motion
    if not np.any(b):
        return tau
    for _ in range(iterations):
        tb = TAU_B_NM if take_up_Nm is None else np.asarray(take_up_Nm, dtype=float)
        r = twist(tau, c, b, c23, take_up_Nm) - phi
        th = np.tanh(tau / tb)
        Jac = C + np.diag(b * (1.0 - th * th) / tb)
        step = np.linalg.solve(Jac, r)
        tau = tau - step
        if np.max(np.abs(step)) < tol_Nm:
            break
    return tau


def static_deflection(tau_hold_Nm, tau_process_Nm, compliance_rad_per_Nm, lost_motion_rad=None,
                      coupling_c23_rad_per_Nm=0.0, take_up_Nm=None):
    """The link's deflection (rad) under a process load ``tau_process_Nm``
    (J^T W, N*m) when the gears already hold the arm with ``tau_hold_Nm``
    (the gravity-holding torque, as InverseDynamics' gravity compensation
    gives it, N*m): the gear then carries tau_hold - tau_process and the link
    moves by -(twist(tau_hold - tau_process) - twist(tau_hold)).  Linear:
    C tau_process.  With a large holding torque of one sign the lost motion
    cancels out."""
    args = (compliance_rad_per_Nm, lost_motion_rad, coupling_c23_rad_per_Nm, take_up_Nm)
    th = np.asarray(tau_hold_Nm, dtype=float)
    return twist(th, *args) - twist(th - np.asarray(tau_process_Nm, dtype=float), *args)


# Below this torque (N*m) a gear counts as unloaded: its link sits in the middle of its play at rest.
PLAY_UNLOADED_NM = 1e-6


def play_torque(phi_rad, stiffness_Nm_per_rad, play_rad):
    """The elastic torque (N*m) of gears with play: K dz(phi), dz the dead
    zone of half-width b (phi - b above b, phi + b below -b, 0 inside);
    ``stiffness_Nm_per_rad`` (6, 6) (the coupled stiffness matrix) or (6,)."""
    phi = np.asarray(phi_rad, dtype=float)
    b = np.asarray(play_rad, dtype=float)
    dz = phi - np.clip(phi, -b, b)
    K = np.asarray(stiffness_Nm_per_rad, dtype=float)
    return dz @ K.T if K.ndim == 2 else K * dz


# Friction inside the play.  ASSUMPTION (reasoned, not measured on this arm): while the flanks are apart the
# gear still drags its link along with a Coulomb torque of GAP_FRICTION_FRACTION of the gear's rated torque.
# Reducer makers measure lost motion at +-3 % of the rated torque, the load that "overcomes the internal
# friction" and brings the flanks into contact (RV reducer test practice; e.g. the backlash test of RV reducers
# in zhygear.com's "Research on Backlash and Stiffness Measurement System for RV Reducers"): the friction inside
# the play is below that; half of it, 1.5 %, is taken.  The rated torque is not in the robot file: it is taken
# as the torque that twists the gear by RATED_TWIST_RAD, 1.1 mrad (3.8 arcmin): Nabtesco's RV-E catalogue gives
# a torsional rigidity in N*m/arcmin of about a quarter of the rated torque in N*m (RV-40E: 412 N*m rated,
# 108 N*m/arcmin).  IRB 6400 joint 6 (2e5 N*m/rad): 220 N*m rated, 3.3 N*m of friction in the play.
GAP_FRICTION_FRACTION = 0.015
RATED_TWIST_RAD = 1.1e-3


def gap_friction_Nm(stiffness_Nm_per_rad):
    """The Coulomb torque (N*m, (6,)) inside each gear's play for its
    stiffness (N*m/rad, (6,) or the (6, 6) matrix: its diagonal): see
    GAP_FRICTION_FRACTION."""
    K = np.asarray(stiffness_Nm_per_rad, dtype=float)
    k = np.diag(K) if K.ndim == 2 else K
    return GAP_FRICTION_FRACTION * k * RATED_TWIST_RAD


def play_twist(tau_Nm, compliance_rad_per_Nm, play_rad, coupling_c23_rad_per_Nm=0.0):
    """The twist (rad) at rest of gears with play carrying ``tau_Nm``: the
    elastic twist C tau, plus the play b on the side the elastic twist
    presses (none where the gear is unloaded: the link then sits in the
    middle of its play)."""
    tau = np.asarray(tau_Nm, dtype=float)
    elastic = twist(tau, compliance_rad_per_Nm, None, coupling_c23_rad_per_Nm)
    b = np.zeros(6) if play_rad is None or not len(play_rad) else np.asarray(play_rad, dtype=float)
    c = np.asarray(compliance_rad_per_Nm, dtype=float)
    loaded = np.abs(elastic) > PLAY_UNLOADED_NM * c
    return elastic + b * np.sign(elastic) * loaded
