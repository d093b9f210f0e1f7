"""Setup mistakes of a tracker campaign that the declared sag carries, as
candidates of the tracker search (identification/tracker/diagnosis.py),
and the setup findings they make.  Plain numpy; no Drake.

The measurements come from the real arm with its real payload, standing as
it stands; the declared model computes the sag from the robot file's
masses and a gravity direction.  Three declarations a user gets wrong:

  payload_mass   the payload acting on the arm differs from the robot
                 file's (``payload.mass_kg``: a 5 kg tool declared as 2 kg,
                 or none declared): the sag changes by
                 dq_j = c_j dm (g . Jv_j(payload's centre of mass)),
                 dm (kg) at the declared centre of mass; its column is
                 that sag's displacement through the fitted compliances.
  payload_com    the payload's centre of mass differs from the robot
                 file's (``payload.com_mm``: a spindle mounted on an
                 adapter plate, its centre of mass taken from the bare
                 spindle's datasheet, 100-200 mm off along the tool axis):
                 dq_j = c_j m (dc . (g x z_j)), dc (m, flange axes) at the
                 declared mass m; three columns, one per flange axis.
  gravity_tilt   the gravity the arm feels is turned from the one the
                 model used (a base mounted 0.5-1 deg off level while the
                 instrument's frame is not levelled, or the frame the
                 points are in was aligned to a tilted base): two small
                 angles about the base's x and y axes, g' = g + a x g.
                 The registration takes the rigid turn of the points; the
                 sag's changed torques are what is left.

All are physical quantities of the set-up, not of the arm: beyond their
typical size (PAYLOAD_TYPICAL_*, PAYLOAD_COM_TYPICAL_*, TILT_TYPICAL_RAD)
they are kept when the held-out evidence is decisive and named as a SETUP
FINDING with the check to make; only a non-physical size (a negative total
mass, a payload heavier than the arm, a centre of mass past the tool point
or PAYLOAD_COM_MAX_M from the flange, a tilt beyond the model's LEVEL_DEG)
makes them a lead.  ``findings`` adds, for each, the held-out RMS of the
alternatives the data may not separate (the joints' compliance scale; for
the centre of mass also the payload's mass) and the measurement that
decides.
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
# A payload's centre of mass as declared from a CAD model or a datasheet: the
# cables, an adapter plate or a sensor move it by a few centimetres
# (ASSUMPTION: 25 mm, or 15 % of the declared distance from the flange when
# that is more: 27 mm for the IRB 6400's spindle at 180 mm).  The common
# mistake is larger: a spindle's own centre of mass written for the mounted
# tool, 100-200 mm off along the tool axis.
PAYLOAD_COM_TYPICAL_M = 0.025
PAYLOAD_COM_TYPICAL_SHARE = 0.15
# ASSUMPTION: a payload's centre of mass lies within 1 m of the flange (the
# makers' load diagrams stop at 0.3-0.8 m; a spindle or gripper is within its
# own length); beyond it the fitted shift is another effect (a lead).
PAYLOAD_COM_MAX_M = 1.0
# ASSUMPTION: the tool point is the tool's far end, so the payload's centre of
# mass lies no farther from the flange than it (a spindle's between the flange
# and the cutter): a fitted centre of mass beyond the file's tool point (or its
# declared centre of mass, if farther) by more than the typical shift is
# another effect taken for it (a lead).  Without a tool point, PAYLOAD_COM_MAX_M.
PAYLOAD_MIN_KG = 1e-3  # a payload lighter than a gram has no centre of mass the sag could show
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


def payload_com_torques(ev):
    """(N, 6, 3) N*m per m: the torques' change when the payload's centre of
    mass moves along the flange's x, y, z axes (its declared mass under
    gravity ev.g_base): tau_j = z_j . ((c - o_j) x m g), so d tau_j = dc . (m g x z_j)."""
    from robstiff_drake.identification.tracker.model import cross

    mg = float(ev.robot.payload.mass_kg) * ev.g_base
    lever = cross(np.broadcast_to(mg, ev.T[:, :6, :3, 2].shape), ev.T[:, :6, :3, 2])  # (N, 6, 3): m g x z_j
    return np.einsum("nji,nik->njk", lever, ev.T[:, 6, :3, :3])


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


def payload_com_typical_m(declared_com_m):
    return max(PAYLOAD_COM_TYPICAL_M, PAYLOAD_COM_TYPICAL_SHARE * float(np.linalg.norm(declared_com_m)))


def payload_com_reach_m(payload):
    """m: how far from the flange the payload's centre of mass can lie (PAYLOAD_COM_MAX_M; the tool point)."""
    tip = payload.tool_point_m if payload.tool_point_m is not None else payload.measured_point_m
    if tip is None:
        return PAYLOAD_COM_MAX_M
    reach = max(float(np.linalg.norm(tip)), float(np.linalg.norm(payload.com_m)))
    return min(PAYLOAD_COM_MAX_M, reach + payload_com_typical_m(payload.com_m))


def payload_com_block(robot):
    declared = np.asarray(robot.payload.com_m, dtype=float)
    mass = float(robot.payload.mass_kg)
    typical = payload_com_typical_m(declared)
    reach = payload_com_reach_m(robot.payload)
    params = [("dx", "mm", 1e3), ("dy", "mm", 1e3), ("dz", "mm", 1e3)]

    def mm(v):
        return ", ".join(f"{x * 1e3:.3g}" for x in v)

    def describe(v, info):
        return (f"the payload's centre of mass is about ({mm(declared + v)}) mm on the flange, the robot file "
                f"declares ({mm(declared)}) mm (payload.com_mm; with its {mass:.3g} kg)")

    def plausible(v, info):
        new = declared + np.asarray(v, dtype=float)
        shift = float(np.linalg.norm(v))
        if np.linalg.norm(new) > reach:
            return False, (f"a payload centre of mass at ({mm(new)}) mm, {np.linalg.norm(new) * 1e3:.3g} mm from "
                           f"the flange, beyond {reach * 1e3:.3g} mm (" + ("no tool's" if reach >= PAYLOAD_COM_MAX_M
                                                                           else "past the tool point, the tool's "
                                                                           "far end")
                           + "): more likely another effect")
        if shift > typical:
            return True, (f"SETUP FINDING: the payload's centre of mass is about ({mm(new)}) mm on the flange, the "
                          f"robot file declares ({mm(declared)}) mm ({shift * 1e3:.3g} mm off, beyond the typical "
                          f"{typical * 1e3:.3g} mm of a datasheet's tool): weigh the tool on two supports or run the "
                          "controller's load identification, and write payload.com_mm")
        return True, (f"payload centre of mass {shift * 1e3:.3g} mm from the file's, within the typical "
                      f"{typical * 1e3:.3g} mm")

    return Block("payload_com", "base", params, lambda ev: _sag_columns(ev, payload_com_torques(ev)), describe,
                 plausible, needs=lambda ev: None if float(ev.robot.payload.mass_kg) >= PAYLOAD_MIN_KG else
                 "the robot file declares no payload mass (a centre of mass of nothing)")


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
    return [payload_mass_block(ev.robot), payload_com_block(ev.robot), gravity_tilt_block()]


# what measurement tells each from the alternatives the data may not separate: (alternatives [(name, words)],
# the measurement)
COM_DECIDES = ("run the controller's load identification (ABB LoadIdentify, KUKA's load data determination, "
               "FANUC's payload identification: it turns the wrist to separate the mass from its centre of mass), "
               "or weigh the tool on two supports a known distance apart")
DECIDES = {
    "payload_mass": ([("joint_compliance", "the joints' compliance scaled (the links' own weight sags more)")],
                     "measure the same poses with and without a known extra weight at the flange (e.g. 5 kg): the "
                     "difference is the compliances' alone, which then fixes the payload"),
    "payload_com": ([("payload_mass", "the payload's mass, at the declared centre of mass"),
                     ("joint_compliance", "the joints' compliance scaled")], COM_DECIDES),
    "gravity_tilt": ([("base_tilt", "the base tilting under the weight's moment")],
                     "measure the base plate's tilt with a precision level (or level the tracker and repeat a few "
                     "poses): a tilt of the base is seen there, a compliance only under load"),
}


def com_shift(fit, kept, info):
    """(3,) m: the payload's centre of mass's shift the fit found (flange axes).  The two payload blocks are
    linear in the mass m and the first moment m c the sag sees: with the mass's dm kept too, the fitted
    first moment m0 c0 + dm c0 + m0 dc is a payload of m0 + dm at c0 + m0 dc / (m0 + dm)."""
    v = np.asarray(fit.coef["payload_com"], dtype=float)
    if "payload_mass" not in kept:
        return v
    m0 = float(info["ev"].robot.payload.mass_kg)
    return v * m0 / (m0 + float(fit.coef["payload_mass"][0]))


def findings(cv, cols, kept, cands, fit, info):
    """[{name, text, estimate, alternatives: [{model, heldout_rms_mm}], separated, decides}] for the setup
    blocks kept: each against the model without it and with its alternative in its place (held out, the
    search's linearised folds ``cv``; ``cols(names)`` their columns; ``info`` the search's).  The data
    separate the two when the alternative's held-out RMS is SAME_MIN worse, or its own fit is not physical."""
    out = []
    by_name = {b.name: b for b, _ in cands}
    for name, (alternatives, decides) in DECIDES.items():
        if name not in kept:
            continue
        b = by_name[name]
        v = com_shift(fit, kept, info) if name == "payload_com" else fit.coef[name]
        ok, why = b.plausible(v, None)
        rest = [n for n in kept if n != name]
        rms = {"with": cv.heldout_rms(cols(kept)), "without": cv.heldout_rms(cols(rest))}
        alts = [{"model": f"{name} ({b.describe(v, None)})", "heldout_rms_mm": rms["with"] * 1e3},
                {"model": f"without {name}", "heldout_rms_mm": rms["without"] * 1e3}]
        # (with an alternative kept, the model without the mistake is the alternative's: refitted there)
        separated = all(alt not in rest for alt, _ in alternatives) or rms["without"] > (1 + SAME_MIN) * rms["with"]
        close = []  # the alternatives the data do not separate from it
        for alt, alt_words in alternatives:
            if alt not in by_name or alt in rest:
                continue
            swap = rest + [alt]
            r_alt = cv.heldout_rms(cols(swap))
            a = by_name[alt]  # the alternative's own size at its fit: a non-physical one is no alternative
            coef = cv.fit(cols(swap))[0][-len(a.params):] + a.start
            a_ok, a_why = a.plausible(coef, info)
            a_ok = a_ok and (alt != "joint_compliance" or bool(np.all(coef > 0)))
            alts.append({"model": f"{alt} in its place ({alt_words})" + ("" if a_ok else f" [not physical: {a_why}]"),
                         "heldout_rms_mm": r_alt * 1e3, "physical": a_ok})
            if not (r_alt > (1 + SAME_MIN) * rms["with"] or not a_ok):
                close.append(alt_words)
        if any(alt not in rest and alt in by_name for alt, _ in alternatives):
            separated = not close
        alt_words = " or ".join(close) if close else alternatives[0][1]
        text = why if why.startswith("SETUP FINDING") else f"{name}: {b.describe(v, None)} ({why})"
        if not separated:
            text += f"; the data do not separate it from {alt_words} (held out within {100 * SAME_MIN:g} %): {decides}"
        out.append({"name": name, "text": text, "estimate": {f"{lab} ({u})": float(x * s) for (lab, u, s), x in
                                                             zip(b.params, v)},
                    "beyond_typical": why.startswith("SETUP FINDING"), "alternatives": alts, "separated": separated,
                    "decides": decides})
    return out
