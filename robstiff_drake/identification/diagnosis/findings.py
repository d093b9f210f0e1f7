"""What a term of the diagnosis implies when its size is beyond the typical:
the setup finding and the check to make, and each term's typical range (its
prior size) in words.  Plain numpy.

A size beyond the typical range (identification/diagnosis/plausibility.py) that the
evidence insists on is rarely a robot that is physically unusual; most
often the user's declaration differs from what the cell did: the load acts
at another point than the declared tool point, the force sensor was not
tared, the displacements are read at another point or in another frame.
The finding says so in the words of the setup, with the check that settles
it.  ``finding`` returns None for a term within its typical range.
"""

import numpy as np

from robstiff_drake.identification.diagnosis import plausibility as pl
from robstiff_drake.identification.diagnosis.dictionary_loads import CROSSTALK_MAX, HISTORY_SHARE_MAX, PERIODIC_DRIFT_MAX_M

LOST = f"<= {pl.LOST_MOTION_MAX_RAD * 1e6:.0f} urad (3 arc-min; beyond it a reducer is worn)"
RATIO = f"compliance positive and within {pl.COMPLIANCE_RATIO_MAX:g}x over the campaign (reducer torsion curves)"

# term name (or the prefix of a per-joint family) -> its typical range, in words
PRIOR = {
    "lost_motion": LOST,
    "backlash_j": LOST,
    "hysteresis_j": LOST,
    "play_j": LOST,
    "joint_coupling": f"|c23| <= {pl.COUPLING_23_MAX:g} sqrt(c2 c3) (axis 3 driven by a rod from the turret)",
    "coupling_j": f"|c| <= {pl.COUPLING_MAX:g} sqrt(cj ck)",
    "load_dependent_stiffness": RATIO,
    "posture_dependent_stiffness": RATIO,
    "nonlinear_stiffness_j": RATIO,
    "angle_compliance_j": RATIO,
    "load_size_compliance": RATIO,
    "geometric_stiffness": f"lambda in [{pl.GEOMETRIC_FACTOR_RANGE[0]:g}, {pl.GEOMETRIC_FACTOR_RANGE[1]:g}] "
                           "(1 is the physics of the load's lever arm)",
    "link_compliance": f"0-{pl.LINK_COMPLIANCE_MAX_M_PER_N * 1e6:g} um/N (the forearm as a steel tube: 0.044 um/N)",
    "force_frame_rotation": f"<= {pl.FORCE_FRAME_MAX_RAD * 1e3:g} mrad (a sensor mounted by eye)",
    "force_bias": f"<= {pl.FORCE_BIAS_MAX_N:g} N (a tared load cell's drift)",
    "moment_bias": f"<= {pl.MOMENT_BIAS_MAX_NM:g} N*m (a tared wrist sensor's torque drift)",
    "tool_offset": f"<= {pl.TOOL_OFFSET_MAX_M * 1e3:g} mm (a TCP calibration error)",
    "drift": f"<= {pl.DRIFT_MAX_M_PER_MEASUREMENT * 1e6:g} um per measurement (a large arm's warm-up)",
    "drift_referenced": f"<= {pl.DRIFT_MAX_M_PER_MEASUREMENT * 1e6:g} um per step",
    "drift_quadratic": f"<= {pl.DRIFT_TOTAL_MAX_M * 1e3:g} mm over the campaign",
    "order_trend": f"<= {pl.DRIFT_TOTAL_MAX_M * 1e3:g} mm over the campaign",
    "drift_periodic": f"amplitude <= {PERIODIC_DRIFT_MAX_M * 1e3:g} mm",
    "order_periodic": f"amplitude <= {PERIODIC_DRIFT_MAX_M * 1e3:g} mm",
    "base_tilt": f"0-{pl.BASE_TILT_COMPLIANCE_MAX:g} rad/(N*m) (a bolted base plate on concrete)",
    "base_shear": f"0-{pl.BASE_SHEAR_COMPLIANCE_MAX * 1e6:g} um/N (anchor bolts in shear)",
    "_bending": f"0-{pl.LINK_BENDING_COMPLIANCE_MAX:g} rad/(N*m) (ten times a steel tube's)",
    "lower_arm_torsion": f"0-{pl.LINK_BENDING_COMPLIANCE_MAX:g} rad/(N*m)",
    "measurement_frame_rotation": f"<= {pl.FRAME_ROTATION_MAX_RAD * 1e3:g} mrad (a frame from the cell drawings)",
    "measured_point_offset": f"<= {pl.POINT_OFFSET_MAX_M * 1e3:g} mm (a target on the spindle's nose)",
    "displacement_offset": f"<= {pl.DISPLACEMENT_OFFSET_MAX_M * 1e3:g} mm (a fixture's or thermal shift)",
    "load_history_j": f"remembered share <= {HISTORY_SHARE_MAX:g} of the joint's compliance",
    "force_crosstalk": f"<= {100 * CROSSTALK_MAX:g} % per entry of the sensor's calibration matrix",
}


def _key(name):
    if name in PRIOR:
        return name
    for k in sorted(PRIOR, key=len, reverse=True):
        if name.startswith(k) or (k.startswith("_") and name.endswith(k)):
            return k
    return None


def prior_size(name):
    """The term's typical range in words ('' when it has none)."""
    k = _key(name)
    return PRIOR[k] if k else ""


def _joint(name):
    digits = [ch for ch in name.split("_j")[-1] if ch.isdigit()] if "_j" in name else []
    return f"joint {digits[0]}" if digits else "a joint"


def _vec(v, scale):
    return "(" + ", ".join(f"{x * scale:.0f}" if abs(x * scale) >= 10 else f"{x * scale:.2g}" for x in v) + ")"


def finding(name, values, info, why):
    """The setup finding of term ``name`` at its fitted ``values`` (SI),
    beyond its typical range (``why``: the plausibility reason): what the
    size implies and the check to make."""
    v = np.asarray(values, dtype=float)
    tool = info.get("tool_m")
    if name == "tool_offset":
        n = np.linalg.norm(v)
        where = "beyond" if v[2] > 0.8 * n else ("short of" if v[2] < -0.8 * n else "away from")
        at = "" if tool is None else f", at {_vec(np.asarray(tool) + v, 1e3)} mm on the flange"
        return (f"the load acts {n * 1e3:.0f} mm {where} the declared tool point (offset {_vec(v, 1e3)} mm in the "
                f"flange frame{at}): check the `# tool_mm:` line (or --tool) against the tool actually mounted")
    if name == "measured_point_offset":
        return (f"the instrument reads a point {np.linalg.norm(v) * 1e3:.0f} mm from the loaded point (offset "
                f"{_vec(v, 1e3)} mm in the flange frame): check which point the target or probe is on, and declare "
                "the loaded point as the tool point")
    if name == "force_bias":
        return (f"the force reads {np.linalg.norm(v):.0f} N with no load (bias {_vec(-v, 1.0)} N in the base frame): "
                "tare the sensor before the campaign, or subtract its unloaded reading")
    if name == "moment_bias":
        return (f"the moment reads {np.linalg.norm(v):.3g} N*m with no load (bias {_vec(-v, 1.0)} N*m in the base "
                "frame): tare the sensor's torque channels before the campaign, or subtract its unloaded reading")
    if name == "force_frame_rotation":
        return (f"the forces are reported in a frame turned {np.rad2deg(np.linalg.norm(v)):.1f} deg against the "
                "robot's base: check the sensor's mounting angle and the frame its readings are given in")
    if name == "force_crosstalk":
        return "the force sensor's calibration matrix is off (crosstalk): recalibrate the sensor or check its cable"
    if name == "measurement_frame_rotation":
        return (f"the displacements are measured in a frame turned {np.rad2deg(np.linalg.norm(v)):.1f} deg against "
                "the robot's base: register the instrument's frame to the base")
    if name == "displacement_offset":
        return (f"the displacements carry a constant offset of {np.linalg.norm(v) * 1e3:.3g} mm: check that each "
                "pose's unloaded reading is taken at the same point and with the same probe as its loaded ones")
    if name in ("drift", "drift_quadratic", "drift_referenced", "drift_periodic", "order_trend", "order_periodic"):
        return "the instrument or the cell drifts more than an arm's warm-up: check the temperature and the " \
               "instrument's stability (re-measure a fixed reference during the campaign)"
    if name == "link_compliance":
        return (f"the tool point moves {v[0] * 1e6:.2g} um/N across the forearm, "
                f"{v[0] / pl.LINK_COMPLIANCE_MAX_M_PER_N:.1f}x the typical bound: a soft forearm or a loose joint: "
                "check the wrist's mounting bolts and joint 4's bearing preload")
    if name.endswith("_bending") or name == "lower_arm_torsion":
        link = name.replace("_bending", "").replace("_torsion", "").replace("_", " ")
        return (f"the {link} gives more than ten times a steel link's compliance: a loose joint or a cracked or "
                "loosely bolted link: check the bolts and bearings at its ends")
    if name in ("base_tilt", "base_shear"):
        return "the base moves on its foundation more than a bolted plate on concrete: check the anchor bolts, the " \
               "grout and the riser"
    if name in ("lost_motion",) or name.startswith(("backlash_j", "hysteresis_j", "play_j")):
        return (f"{'joints 1-3' if name == 'lost_motion' else _joint(name)}: lost motion beyond a worn reducer's: a "
                "loose joint (gear preload, bearing) or a brake that slips: check the joint")
    if name == "joint_coupling" or name.startswith("coupling_j"):
        return ("the joints' deflections are coupled more than a drive through a rod or the structure gives: a "
                "loose joint or a worn drive between them: check the rod's, the gearboxes' and the bearings' mountings")
    if name in ("load_dependent_stiffness", "posture_dependent_stiffness", "load_size_compliance") or \
            name.startswith(("nonlinear_stiffness_j", "angle_compliance_j", "load_size_compliance_j",
                             "load_history_j")):
        who = _joint(name) if "_j" in name else "a joint"
        return (f"{who}'s compliance varies more than a reducer's torsion curve allows: a loose joint (a gear's "
                "preload, a bearing), a brake that slips or a balancer out of adjustment: check the joint")
    if name == "geometric_stiffness":
        return "the loads' lever arms differ from the model's: check the tool point and the load's point of action"
    return f"beyond its typical size ({why}): check the joint or the setup it names"


__all__ = ["prior_size", "finding", "PRIOR"]


def alternatives(kept, rms_after_mm, rivals, confounded, tool_m):
    """The explanations the data cannot decide between, side by side: the
    kept model, then the model with each lead beyond its typical size (not
    forbidden by physics) that fits better held out but was not added, with
    its held-out RMS, what it would imply and the measurement that would
    separate it from what it is confounded with.  [] when there is none.
    ``rivals``: [(CandidateResult of the lead, held-out RMS (mm) and SI
    values of the lead refitted with the kept model)]."""
    better = [(r, rms, v) for r, rms, v in rivals if rms < rms_after_mm]
    if not better:
        return []
    out = [{"terms": list(kept), "held_out_mm": float(rms_after_mm), "kept": True, "beyond_typical": False}]
    for r, rms, v in sorted(better, key=lambda x: x[1]):
        alt = {"terms": list(kept) + [r.name], "held_out_mm": float(rms), "kept": False,
               "beyond_typical": r.plausible is False, "reason": r.refusal or r.plausibility}
        if r.plausible is False:
            alt["finding"] = finding(r.name, v, {"tool_m": tool_m}, r.plausibility)
        pair = next((c for c in confounded if r.name in c["terms"]), None)
        if pair is not None:
            other = next(t for t in pair["terms"] if t != r.name)
            alt.update(confounded_with=other, correlation=float(pair["correlation"]),
                       plan=f"robstiff plan-poses 24 --separate {r.name},{other} --campaign DATA.csv")
        out.append(alt)
    return out


def describe_alternatives(alts):
    """Report lines: the alternatives side by side."""
    if not alts:
        return []
    lines = ["explanations the data cannot decide between (none is picked; held-out RMS side by side):"]
    for a in alts:
        tag = "kept model" if a["kept"] else ("beyond typical size" if a["beyond_typical"] else "not added")
        lines.append(f"  {a['held_out_mm']:.4f} mm  {' + '.join(a['terms']) or 'six springs'}  ({tag})")
        if a.get("finding"):
            lines.append(f"      would mean: {a['finding']}")
        if a.get("confounded_with"):
            lines.append(f"      confounded with {a['confounded_with']} (r = {a['correlation']:+.2f}); to separate "
                         f"them: {a['plan']}")
    return lines
