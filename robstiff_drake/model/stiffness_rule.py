"""The library's nominal-stiffness rule, and a warning when a robot file
follows it beyond the arms it was drawn from.  Plain numpy.

No maker publishes joint stiffnesses.  models/irb6400.yaml chooses the IRB
6400's (taken as a 200 kg arm of 2.4 m reach), and the other library files
scale them by one rule (docs/your_robot.md, section 0): the gearboxes are
sized for the rated payload, so joints 1-3 scale with the rated payload
moment (payload x reach) and the wrist joints with the rated payload.  The
rule was drawn from, and applied to, arms of 165-240 kg and 2.4-2.9 m (IRB
6400, IRB 6640-235/2.55, KR 240 R2900-2, R-2000iC/165F; the ratios among the
joints as published for 150-250 kg arms, Dumas et al., Robotica 2011).  A
user who applies it to a 25 kg arm of 1.8 m scales the IRB 6400 by about
0.1: 54 um/N at the tool (largest direction, at the R-2000iC/165F file's
reference pose: tests/test_stiffness_rule.py's small arm) where nothing
says whether such an arm is that soft (a small arm's gearboxes and links are not a large arm's scaled down).
A robot file whose stiffnesses are the IRB 6400's times one factor on
joints 1-3 and one on 4-6 follows the rule; when a factor lies outside the
library's, the file gets a warning naming the arms the rule is drawn from.
"""

import numpy as np

# models/irb6400.yaml's joint stiffness (N*m/rad): the rule's anchor
ANCHOR_NM_PER_RAD = np.array([1.5e6, 1.1e6, 0.8e6, 3.0e5, 3.0e5, 2.0e5])
ANCHOR_PAYLOAD_KG, ANCHOR_REACH_M = 200.0, 2.4  # ASSUMPTION of models/irb6400.yaml (its variant is not known)
# the files' factors (joints 1-3, wrist): R-2000iC/165F 0.91, 0.825; IRB 6640 1.25, 1.17; KR 240 1.45, 1.2
RULE_ARMS = "IRB 6400 (as 200 kg at 2.4 m), R-2000iC/165F, IRB 6640-235/2.55, KR 240 R2900-2: 165-240 kg, 2.4-2.9 m"
ARM_FACTOR_RANGE = (0.91, 1.45)
WRIST_FACTOR_RANGE = (0.825, 1.2)
# the library's arms' largest tool-point compliance at their reference machining poses (um/N;
# robot_checks.largest_compliance_um_per_N; tests/test_stiffness_rule.py recomputes it)
LIBRARY_COMPLIANCE_UM_PER_N = (3.6, 5.8)
# ASSUMPTION: within this fraction of the range still the library's arms (the files round to 3 figures: 1 %)
RANGE_SLACK = 0.1
# a file follows the rule when each group's ratios to the anchor agree to this fraction: the library's files to
# 1 % (rounding); an identified or a maker's stiffness is not proportional to the IRB 6400's to 3 %
SAME_FACTOR_REL = 0.03


def rule_factors(k_Nm_per_rad):
    """(joints 1-3 factor, wrist factor) when the stiffnesses are the
    anchor's times one factor per group (SAME_FACTOR_REL), else None."""
    r = np.asarray(k_Nm_per_rad, dtype=float) / ANCHOR_NM_PER_RAD
    groups = (r[:3], r[3:])
    if any(g.max() > (1 + SAME_FACTOR_REL) * g.min() for g in groups):
        return None
    return float(np.mean(r[:3])), float(np.mean(r[3:]))


def _outside(value, bounds):
    lo, hi = bounds
    return not (1 - RANGE_SLACK) * lo <= value <= (1 + RANGE_SLACK) * hi


def extrapolated_rule_warning(robot, compliance_um_per_N=None):
    """One line when the robot file's stiffnesses follow the library's rule
    with a factor outside the library's arms', else None.
    ``compliance_um_per_N``: the tool point's largest compliance at the
    reference pose, for the message (or None)."""
    factors = rule_factors(robot.joint_stiffness_Nm_per_rad)
    if factors is None:
        return None
    arm, wrist = factors
    if not (_outside(arm, ARM_FACTOR_RANGE) or _outside(wrist, WRIST_FACTOR_RANGE)):
        return None
    rated = getattr(robot, "rated_payload_kg", None)
    said = f" (its rated_payload_kg: {rated:g} kg)" if rated else ""
    lo, hi = LIBRARY_COMPLIANCE_UM_PER_N
    soft = (f"; {compliance_um_per_N:.3g} um/N at the tool at its reference machining pose (largest direction), the "
            f"library's arms {lo:g}-{hi:g}") if compliance_um_per_N is not None else ""
    return (f"{robot.source}: joint_stiffness_Nm_per_rad is the IRB 6400's scaled by {arm:.3g} (joints 1-3) and "
            f"{wrist:.3g} (wrist): the library's nominal-stiffness rule (gearboxes sized for the rated payload; "
            f"docs/your_robot.md) for an arm of about {wrist * ANCHOR_PAYLOAD_KG:.3g} kg and "
            f"{arm * ANCHOR_PAYLOAD_KG * ANCHOR_REACH_M:.3g} kg*m{said}{soft}; the rule is drawn from {RULE_ARMS} "
            f"(factors {ARM_FACTOR_RANGE[0]:g}-{ARM_FACTOR_RANGE[1]:g} and {WRIST_FACTOR_RANGE[0]:g}-"
            f"{WRIST_FACTOR_RANGE[1]:g}) and is unchecked this far from them: identify your arm's stiffness "
            "(robstiff identify) before trusting its deflections")
