"""Setup mistakes of a tracker campaign that the declared sag carries, as
candidates of the tracker search (identification/tracker/diagnosis.py),
and the setup findings they make.  Plain numpy; no Drake.

The measurements come from the real arm with its real payload, standing as
it stands; the declared model computes the sag from the robot file's
masses and a gravity direction.  Two declarations a user gets wrong:

  payload_mass   the payload acting on the arm differs from the robot
                 file's (``payload.mass_kg``: a 5 kg tool declared as 2 kg,
                 or none declared): the sag changes by
                 dq_j = c_j dm (g . Jv_j(payload's centre of mass)),
                 dm (kg) at the declared centre of mass; its column is
                 that sag's displacement through the fitted compliances.
  gravity_tilt   the gravity the arm feels is turned from the one the
                 model used (a base mounted 0.5-1 deg off level while the
                 instrument's frame is not levelled, or the frame the
                 points are in was aligned to a tilted base): two small
                 angles about the base's x and y axes, g' = g + a x g.
                 The registration takes the rigid turn of the points; the
                 sag's changed torques are what is left.

Both are physical quantities of the set-up, not of the arm: beyond their
typical size (PAYLOAD_TYPICAL_*, TILT_TYPICAL_RAD) they are kept when the
held-out evidence is decisive and named as a SETUP FINDING with the check
to make; only a non-physical size (a negative total mass, a payload
heavier than the arm, a tilt beyond the model's LEVEL_DEG) makes them a
lead.  ``findings`` adds, for each, the held-out RMS of the alternatives
the data may not separate (the joints' compliance scale) and the
measurement that decides.
"""

import numpy as np

from robstiff_drake.identification.tracker.model import LEVEL_DEG, jacobian_v
from robstiff_drake.identification.tracker.terms import Block

# A payload's mass as declared from a datasheet or a scale: cables, an
# adapter plate or a tracker target add a few hundred grams (ASSUMPTION:
# 0.5 kg, or a quarter of the declared mass when that is more).
PAYLOAD_TYPICAL_KG = 0.5
PAYLOAD_TYPICAL_SHARE = 0.25
# ASSUMPTION: an arm carries less than its own links' mass (rated payloads
# are 10-40 % of it: a UR10 10 kg of 28 kg, an IRB 6400 120-200 kg of about
# 2 t); a fitted payload beyond that is another effect (a lead).
# A levelled base or tracker: a machinist's level reads 0.02 mm/m (0.001
# deg), a base grouted by eye is within about 0.3 deg (the generator's
# bound, tracker_world.py); beyond 0.3 deg the set-up is worth checking.
TILT_TYPICAL_RAD = np.deg2rad(0.3)
TILT_MAX_RAD = np.deg2rad(LEVEL_DEG)
SAME_MIN = 0.02  # two alternatives within 2 % of held-out RMS: the data do not separate them


def payload_torque_per_kg(ev):
    """(N, 6) N*m per kg: the torques of 1 kg at the robot file's payload
    centre of mass under gravity ev.g_base, at the frames ev.T."""
    c = ev.T[:, 6, :3, 3] + ev.T[:, 6, :3, :3] @ ev.robot.payload.com_m
    return np.einsum("k,nkj->nj", ev.g_base, jacobian_v(ev.T, c))


def tilt_torques(ev):
    """(N, 6, 2) N*m per rad: the weight's torques (links and payload) of
    gravity turned about the base's x and y axes."""
    from robstiff_drake.identification.tracker.model import gravity

    out = []
    for axis in np.eye(3)[:2]:
        tau, _ = gravity(ev.robot, ev.T, ev.q_rad, g_base=np.cross(axis, ev.g_base))
        out.append(tau)
    return np.stack(out, axis=-1)


def _sag_columns(ev, tau):
    """(N, 3, p) base-frame displacement of joint torques tau (N, 6, p) through the sag's compliances."""
    return np.einsum("nkj,njp->nkp", ev.Jv, ev.c_sag[None, :, None] * tau)


def payload_typical_kg(declared_kg):
    return max(PAYLOAD_TYPICAL_KG, PAYLOAD_TYPICAL_SHARE * declared_kg)


def payload_mass_block(robot):
    declared = float(robot.payload.mass_kg)
    arm = float(sum(link.mass_kg for link in robot.links))
    typical = payload_typical_kg(declared)

    def describe(v, info):
        return (f"the payload acting on the arm is about {declared + v[0]:.3g} kg, the robot file declares "
                f"{declared:.3g} kg (payload.mass_kg; at its centre of mass)")

    def plausible(v, info):
        total = declared + v[0]
        if total < 0:
            return False, f"needs a payload of {total:.3g} kg (non-physical: negative)"
        if total > arm:
            return False, (f"a payload of {total:.3g} kg, heavier than the arm's links ({arm:.3g} kg): more likely "
                           "another effect")
        if abs(v[0]) > typical:
            return True, (f"SETUP FINDING: the payload acting on the arm is about {total:.3g} kg, the robot file "
                          f"declares {declared:.3g} kg ({v[0]:+.3g} kg, beyond the typical {typical:.3g} kg of a "
                          "datasheet's tool): weigh the tool and write payload.mass_kg")
        return True, f"payload {v[0]:+.3g} kg against the file's, within the typical {typical:.3g} kg"

    return Block("payload_mass", "base", [("dm", "kg", 1.0)],
                 lambda ev: _sag_columns(ev, payload_torque_per_kg(ev)[:, :, None]), describe, plausible)


def gravity_tilt_block():
    params = [("tilt_x", "deg", np.rad2deg(1.0)), ("tilt_y", "deg", np.rad2deg(1.0))]

    def size_deg(v):
        return float(np.rad2deg(np.hypot(v[0], v[1])))

    def describe(v, info):
        return (f"the gravity the arm feels is turned by {size_deg(v):.3g} deg from the direction the model used "
                f"(about the base's x {np.rad2deg(v[0]):+.3g} deg, y {np.rad2deg(v[1]):+.3g} deg): the base is not "
                "level, or the instrument's frame is not")

    def plausible(v, info):
        a = np.hypot(v[0], v[1])
        if a > TILT_MAX_RAD:
            return False, (f"a gravity turned by {size_deg(v):.3g} deg, beyond {LEVEL_DEG:g} deg (the model's own "
                           "test of a levelled instrument): a wall or ceiling mount, or another effect")
        if a > TILT_TYPICAL_RAD:
            return True, (f"SETUP FINDING: the arm's base stands about {size_deg(v):.2g} deg off the vertical the "
                          f"model used (about base x {np.rad2deg(v[0]):+.2g} deg, y {np.rad2deg(v[1]):+.2g} deg; "
                          f"beyond the typical {np.rad2deg(TILT_TYPICAL_RAD):g} deg): level the tracker (its frame's z "
                          "is taken as the vertical) or measure the base plate's tilt with a level")
        return True, f"a tilt of {size_deg(v):.3g} deg, within the typical {np.rad2deg(TILT_TYPICAL_RAD):g} deg"

    return Block("gravity_tilt", "base", params, lambda ev: _sag_columns(ev, tilt_torques(ev)), describe, plausible,
                 needs=lambda ev: None if np.any(ev.tau) else "the robot file's masses carry no torque")


def setup_blocks(ev):
    """The setup mistakes' blocks for a campaign at ``ev`` (tried by the search as any other)."""
    return [payload_mass_block(ev.robot), gravity_tilt_block()]


# what measurement tells each from the alternative the data may not separate
DECIDES = {
    "payload_mass": ("joint_compliance", "the joints' compliance scaled (the links' own weight sags more)",
                     "measure the same poses with and without a known extra weight at the flange (e.g. 5 kg): the "
                     "difference is the compliances' alone, which then fixes the payload"),
    "gravity_tilt": ("base_tilt", "the base tilting under the weight's moment",
                     "measure the base plate's tilt with a precision level (or level the tracker and repeat a few "
                     "poses): a tilt of the base is seen there, a compliance only under load"),
}


def findings(cv, cols, kept, cands, fit, info):
    """[{name, text, estimate, alternatives: [{model, heldout_rms_mm}], separated, decides}] for the setup
    blocks kept: each against the model without it and with its alternative in its place (held out, the
    search's linearised folds ``cv``; ``cols(names)`` their columns; ``info`` the search's).  The data
    separate the two when the alternative's held-out RMS is SAME_MIN worse, or its own fit is not physical."""
    out = []
    by_name = {b.name: b for b, _ in cands}
    for name, (alt, alt_words, decides) in DECIDES.items():
        if name not in kept:
            continue
        b = by_name[name]
        v = fit.coef[name]
        ok, why = b.plausible(v, None)
        rest = [n for n in kept if n != name]
        rms = {"with": cv.heldout_rms(cols(kept)), "without": cv.heldout_rms(cols(rest))}
        alts = [{"model": f"{name} ({b.describe(v, None)})", "heldout_rms_mm": rms["with"] * 1e3},
                {"model": f"without {name}", "heldout_rms_mm": rms["without"] * 1e3}]
        # (with the alternative kept, the model without the mistake is the alternative's: refitted there)
        separated = alt not in rest or rms["without"] > (1 + SAME_MIN) * rms["with"]
        if alt in by_name and alt not in rest:
            swap = rest + [alt]
            r_alt = cv.heldout_rms(cols(swap))
            a = by_name[alt]  # the alternative's own size at its fit: a non-physical one is no alternative
            coef = cv.fit(cols(swap))[0][-len(a.params):] + a.start
            a_ok, a_why = a.plausible(coef, info)
            a_ok = a_ok and (alt != "joint_compliance" or bool(np.all(coef > 0)))
            alts.append({"model": f"{alt} in its place ({alt_words})" + ("" if a_ok else f" [not physical: {a_why}]"),
                         "heldout_rms_mm": r_alt * 1e3, "physical": a_ok})
            separated = r_alt > (1 + SAME_MIN) * rms["with"] or not a_ok
        text = why if why.startswith("SETUP FINDING") else f"{name}: {b.describe(v, None)} ({why})"
        if not separated:
            text += f"; the data do not separate it from {alt_words} (held out within {100 * SAME_MIN:g} %): {decides}"
        out.append({"name": name, "text": text, "estimate": {f"{lab} ({u})": float(x * s) for (lab, u, s), x in
                                                             zip(b.params, v)},
                    "beyond_typical": why.startswith("SETUP FINDING"), "alternatives": alts, "separated": separated,
                    "decides": decides})
    return out
