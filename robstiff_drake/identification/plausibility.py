"""Physical ranges for the sizes the diagnosis may find, with the reasoning
behind each.  A term (named or discovered) whose fitted size falls outside
its range is reported as implausible: it fits the residual, but not as the
physical effect it is named after, so the data carry something else that
looks like it.  Plain numpy.

Every number here is an engineering bound, not a measured property of one
robot: where it stands in for a missing fact, the comment says so.
"""

import numpy as np

# --- joints -------------------------------------------------------------
# Lost motion (backlash) and hysteresis at a joint, after its reducer (rad).
# RV (cycloidal) reducers of the main axes are catalogued with a lost motion
# of at most 1 arc-min (0.29 mrad) at +-3 % of rated torque; strain-wave gears
# in wrists list a hysteresis loss of 1-3 arc-min.  The lost motion seen at a
# robot's axis is typically 10-60 urad.  Above 3 arc-min (0.87 mrad) the gear
# would be worn out or loose: implausible.
LOST_MOTION_MAX_RAD = 8.7e-4

# A joint's compliance that changes with its torque or with the posture: it
# must stay positive over the campaign (a spring never pushes the wrong way),
# and the softest over the stiffest may differ by at most this factor, the
# ratio between the slopes of published reducer torsion curves (RV: the
# lost-motion region against the rated region; strain-wave gears: K1 against
# K3, about 1:3).  ASSUMPTION: no robot-specific source.
COMPLIANCE_RATIO_MAX = 3.0

# Off-diagonal joint compliance c_jk relative to sqrt(c_j c_k).  Physics
# bounds it below 1 (the compliance matrix is positive definite); coupling
# through a shared drive (e.g. a parallel rod driving axis 3 from the turret)
# or the structure is a fraction of the joints' own compliance.
# ASSUMPTION: half of the bound.
COUPLING_MAX = 0.5

# --- structure outside the joints ----------------------------------------
# Tilt compliance of the base on its foundation (rad/(N*m)).  A bolted base
# plate on concrete: anchor bolts (8 x M24, 0.3 m long, 0.4 m from the tilt
# axis) give about 1.5e8 N*m/rad, the rocking of a 1 m footing on stiff soil
# about 5e7 N*m/rad; a steel riser is softer.  Below 1e7 N*m/rad a 2 t robot
# (rocking inertia about 3e3 kg*m^2 about the floor) would rock at under
# 10 Hz, a foundation no machining cell accepts.
BASE_TILT_COMPLIANCE_MAX = 1.0e-7
# Sliding/shear compliance of the base (m/N): anchor bolts in shear and grout,
# of the order of 1e-9 m/N; 50x that is the bound.
BASE_SHEAR_COMPLIANCE_MAX = 5.0e-8
# Bending (and torsion) of a link, as a virtual joint at a third of the link
# from its root (rad/(N*m)).  The forearm as a steel tube (outer radius
# 120 mm, wall 20 mm, 1.3 m; EI = 1.7e7 N*m^2) gives 4EI/3L = 1.7e7 N*m/rad,
# i.e. 6e-8 rad/(N*m); the cast lower arm is stiffer.  Bound: ten times the
# tube's compliance.
LINK_BENDING_COMPLIANCE_MAX = 6.0e-7
# The named forearm compliance (link_compliance, m/N): the same tube as a
# cantilever, L^3/3EI = 4.4e-8 m/N; bound five times that.
LINK_COMPLIANCE_MAX_M_PER_N = 2.0e-7

# --- measurement setup ----------------------------------------------------
# Measuring frame turned against the robot base (rad): a frame taken from the
# cell drawings, or a base turned on its foundation, can be off by a few
# degrees; beyond about 6 deg someone would see the axes are wrong.
FRAME_ROTATION_MAX_RAD = 0.1
# Measured point away from the loaded point (m): a tracker target on the
# spindle housing while the load acts at the cutter: up to 0.2 m.
POINT_OFFSET_MAX_M = 0.2
# A constant offset between loaded and unloaded readings (m): a fixture or
# thermal shift within one pose's readings; 0.05 mm at most.
DISPLACEMENT_OFFSET_MAX_M = 5.0e-5
# Drift (m per measurement): warm-up of a large arm moves the tool point
# 0.1-0.5 mm over hours; at one or two measurements a minute, 5 um per
# measurement is a generous bound; the total over a campaign at most 0.5 mm.
DRIFT_MAX_M_PER_MEASUREMENT = 5.0e-6
DRIFT_TOTAL_MAX_M = 5.0e-4

# --- loads ---------------------------------------------------------------
# The loaded point's offset from the model's tool point (m): a TCP
# calibration error is a few mm; 20 mm means a wrong tool definition.
TOOL_OFFSET_MAX_M = 0.02
# Constant bias of the reported force (N): a tared load cell drifts by a few N.
FORCE_BIAS_MAX_N = 20.0
# Force sensor / load cell frame turned against the base (rad).
FORCE_FRAME_MAX_RAD = 0.1
# Factor of the CCT term K_g: 1 is the physics; 0-3 allows for the loads'
# real lever arms differing from the model's.
GEOMETRIC_FACTOR_RANGE = (0.0, 3.0)


def within(value, upper, what, unit, scale, lower=None):
    """(ok, reason) for |value| <= upper (or lower <= value <= upper)."""
    value = np.asarray(value, dtype=float)
    if lower is None:
        worst = float(np.max(np.abs(value)))
        ok = worst <= upper
        return ok, (f"{what} {worst * scale:.3g} {unit} {'within' if ok else 'beyond'} the physical bound "
                    f"{upper * scale:.3g} {unit}")
    ok = bool(np.all((value >= lower) & (value <= upper)))
    return ok, (f"{what} {np.round(value * scale, 4).tolist()} {unit} {'within' if ok else 'outside'} the physical "
                f"range [{lower * scale:g}, {upper * scale:g}] {unit}")


def compliance_ratio(c0, dc):
    """(ok, reason) for a compliance c0 + dc (arrays over the campaign's rows)."""
    c = c0 + np.asarray(dc, dtype=float)
    lo, hi = float(np.min(c)), float(np.max(c))
    if lo <= 0:
        return False, "needs a negative compliance at some rows (non-physical)"
    ok = hi / lo <= COMPLIANCE_RATIO_MAX
    return ok, (f"compliance varies {hi / lo:.2f}x over the campaign ({'within' if ok else 'beyond'} the "
                f"{COMPLIANCE_RATIO_MAX:g}x of reducer torsion curves)")


def check_term(term, values, half_width, info):
    """(ok, reason) of a term's fitted size (SI ``values``): its own check
    (``term.plausible``) at the estimate; a size beyond the physical range
    whose 95 % interval still reaches the range (each parameter moved toward
    zero by its ``half_width``) is not called implausible."""
    if term.plausible is None:
        return True, ""
    v = np.asarray(values, dtype=float)
    ok, why = term.plausible(v, info)
    if ok:
        return ok, why
    smallest = np.sign(v) * np.maximum(np.abs(v) - np.asarray(half_width, dtype=float), 0.0)
    if term.plausible(smallest, info)[0]:
        return True, why + ", but its 95 % interval reaches the physical range"
    return False, why
