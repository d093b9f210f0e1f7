"""Typical ranges for the sizes the diagnosis may find, with the reasoning
behind each, and the signs physics forbids.  A range is a prior, not a veto
(identification/diagnosis/selection.py): a term whose fitted size falls outside its
range counts against it, and it is kept only on decisive evidence, then
reported as what the size implies, most often a setup mistake (a tool point
not declared, a sensor not tared; identification/diagnosis/findings.py).  A sign
physics forbids (a negative compliance, a compliance matrix that is not
positive definite) is refused whatever the evidence: its reason says
"non-physical" (``forbidden``).  Plain numpy.

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
# bounds it below 1 (the compliance matrix is positive definite).  Between
# joints 2 and 3 a shared drive makes it large: axis 3 driven by a parallel
# rod from a gearbox at the turret deflects the forearm's absolute angle
# q2 + q3, which in the model's relative angles is c23 = -c2, c3 = c2 +
# c3_gear, i.e. |c23| / sqrt(c2 c3) = sqrt(c2 / (c2 + c3_gear)): 0.85 with
# the IRB 6400 file's own stiffness (1.1e6 and 0.8e6 N*m/rad), 0.7 when the
# gearbox is as compliant as joint 2's.  Bound: 0.9 (the compliance stays
# clearly positive definite).  Between other joints only the structure
# couples them: a fraction of the joints' own compliance, ASSUMPTION: half
# of the physical bound.
COUPLING_23_MAX = 0.9
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
# Measured point away from the loaded point (m).  The term says the point the
# instrument reads is not the point the user declared (the tool point, where
# the load acts): the largest such mix-up on one end effector is a target
# (tracker reflector, probe tip) on the spindle's nose while the load acts at
# the cutter's tip, the tool holder's gauge length plus the tool's stick-out:
# about 60-160 mm for HSK-63/SK-40 holders plus 30-100 mm of tool, so up to
# 0.2 m.  ASSUMPTION: catalogue holder lengths, no robot-specific source.
# The bound does not grow with the tool's length: a longer tool moves both
# points, not the distance between them; a point measured farther away than
# this is another point of the cell (a target on the flange, a second
# fixture), which the user states as the measured point rather than leaving
# it to a fit.  A fit beyond the bound is a lead (plausibility.check): on the
# FANUC campaign (a 0.40 m drilling tool, tool point (6.9, 245.3, 319.3) mm)
# the estimates of 200-370 mm put the measured point 100-250 mm beyond the
# drill's tip along the flange's axis, where no part of the tool is.
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
# Constant bias of the reported moment (N*m), files with mx,my,mz: the force
# bound at a wrist sensor's torque-to-force range (ATI Omega160 SI-1000-120:
# 120 N*m / 1000 N = 0.12 m; ASSUMPTION: its torque channels drift in that
# proportion): 2.4 N*m.
MOMENT_BIAS_MAX_NM = FORCE_BIAS_MAX_N * 0.12
# Force sensor / load cell frame turned against the base (rad).
FORCE_FRAME_MAX_RAD = 0.1
# Factor of the CCT term K_g: 1 is the physics; 0-3 allows for the loads'
# real lever arms differing from the model's.
GEOMETRIC_FACTOR_RANGE = (0.0, 3.0)


NON_PHYSICAL = "non-physical"


def forbidden(reason):
    """Does a plausibility reason say the size is forbidden by physics (not
    only beyond its typical range)?"""
    return NON_PHYSICAL in (reason or "")


def within(value, upper, what, unit, scale, lower=None):
    """(ok, reason) for |value| <= upper (or lower <= value <= upper); with
    ``lower`` 0 a negative value is non-physical (a negative compliance or
    factor)."""
    value = np.asarray(value, dtype=float)
    if lower is None:
        worst = float(np.max(np.abs(value)))
        ok = worst <= upper
        return ok, (f"{what} {worst * scale:.3g} {unit} {'within' if ok else 'beyond'} the typical bound "
                    f"{upper * scale:.3g} {unit}")
    ok = bool(np.all((value >= lower) & (value <= upper)))
    sign = f" ({NON_PHYSICAL}: negative)" if lower == 0 and np.any(value < 0) else ""
    return ok, (f"{what} {np.round(value * scale, 4).tolist()} {unit} {'within' if ok else 'outside'} the typical "
                f"range [{lower * scale:g}, {upper * scale:g}] {unit}{sign}")


def compliance_ratio(c0, dc):
    """(ok, reason) for a compliance c0 + dc (arrays over the campaign's rows)."""
    c = c0 + np.asarray(dc, dtype=float)
    lo, hi = float(np.min(c)), float(np.max(c))
    if lo <= 0:
        return False, f"needs a negative compliance at some rows ({NON_PHYSICAL})"
    ok = hi / lo <= COMPLIANCE_RATIO_MAX
    return ok, (f"compliance varies {hi / lo:.2f}x over the campaign ({'within' if ok else 'beyond'} the "
                f"{COMPLIANCE_RATIO_MAX:g}x of reducer torsion curves)")


def check(plausible, values, half_width, info):
    """(ok, reason) of a fitted size (SI ``values``) under its own check
    ``plausible(values, info)``, judged at the POINT ESTIMATE: a size beyond
    the physical range is implausible even when its 95 % interval (each
    parameter moved toward zero by its ``half_width``) reaches the range.
    Such a term is a lead, not a kept term: the fit the model would carry is
    the estimate, not the interval's end, and "the data do not exclude a
    physical size" is not evidence for one (an interval that wide also means
    the term is poorly determined).  The reason then says that the interval
    reaches the range, for the report."""
    v = np.asarray(values, dtype=float)
    ok, why = plausible(v, info)
    if ok:
        return True, why
    smallest = np.sign(v) * np.maximum(np.abs(v) - np.asarray(half_width, dtype=float), 0.0)
    if plausible(smallest, info)[0]:
        return False, why + " (its 95 % interval reaches the typical range, but the fit needs the size beyond it)"
    return False, why


def excess(plausible, values, info, iterations=30):
    """How far beyond its typical range a size is: 1 / the largest factor s
    in (0, 1] with ``plausible(s * values, info)`` ok (bisection on log s);
    1 when it is within, inf when no shrinking makes it so."""
    v = np.asarray(values, dtype=float)
    if plausible(v, info)[0]:
        return 1.0
    lo, hi = -12.0, 0.0  # log10 s: plausible at lo, not at hi
    if not plausible(v * 10.0**lo, info)[0]:
        return float("inf")
    for _ in range(iterations):
        mid = 0.5 * (lo + hi)
        if plausible(v * 10.0**mid, info)[0]:
            lo = mid
        else:
            hi = mid
    return float(10.0**-lo)


def check_term(term, values, half_width, info):
    """``check`` with a term's own plausibility check (``term.plausible``;
    None: any size is plausible)."""
    if term.plausible is None:
        return True, ""
    return check(term.plausible, values, half_width, info)
