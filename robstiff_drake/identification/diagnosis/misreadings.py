"""Setup mistakes in how a stiffness campaign was written: the file read
another way.  Plain numpy; no Drake.

A sign, a unit or a column order is not a physical effect with a typical
size: it is a discrete alternative reading of the file.  The prior is that
the file means what its header says; the evidence against it is the six
springs' held-out fit (the same pose-grouped folds as the search) under the
other reading.  Each reading is tried:

  * ``force_sign_x/y/z``: one force axis (and its moment axis, when the file
    has moments) with the wrong sign (a sensor axis convention, or a
    transform to the base frame written with one sign wrong);
  * ``disp_sign_x/y/z``: one displacement axis with the wrong sign (the
    instrument's frame against the robot's);
  * ``radians_qJ``: joint J's column holds radians in a column of degrees,
    tried only where every value of that column could be radians
    (|q| <= RADIAN_MAX, a full turn);
  * ``swap_qJqK``: the columns of joints J and K interchanged.

A reading is reported as a setup finding (``screen``) when the six springs
fitted to it are better held out than the diagnosis's final model of the
file as written (its kept terms included: a physical effect that explains
the file as it is leaves no case for a misreading), on every fold, the mean gain
priors.FOLD_SPREAD_FACTOR times its standard error over the folds (the
rule that makes a size beyond the typical decisive, priors.py), and the
held-out RMS is lower by the gain a named effect needs (selection.MIN_GAIN,
10 %).  A reading that fits better by that gain but not on every fold is
reported as possible, with the data unable to decide (``decisive`` false),
as a lead of a size beyond the typical is.  The poses' paired one-sided t-test (the held-out squared residual as
written minus read that way) is reported with it, not used: on real data
the residual grows with the load and a few large loads carry it: a model that fits the file better when it is read another way is
evidence against the way it was written, whatever else the data hold.
Several readings that pass are all reported, best first: where two fit
about as well the data cannot decide between them, and the text names the
check that would (the sensor's axis convention, the controller's joint
order).  No reading changes the file; the diagnosis of the file as written
follows, and its terms may stand in for the mistake.
"""

from dataclasses import replace
from itertools import combinations

import numpy as np
from scipy import stats

from robstiff_drake.errors import InputError
from robstiff_drake.identification.diagnosis.cross_validation import rows_to_eq
from robstiff_drake.identification.diagnosis.priors import fold_consistent
from robstiff_drake.identification.diagnosis.selection import MIN_GAIN
from robstiff_drake.identification.diagnosis.terms import Context, held_out, rms_mm
from robstiff_drake.identification.stiffness.joint_stiffness import identify
from robstiff_drake.model import kinematics as kin

# A column of degrees whose every value lies within a full turn in radians (2 pi = 6.28 "deg") could hold
# radians: joint ranges of industrial arms reach +-360 deg at most (the wrist's last joint), so radians never
# exceed 2 pi; a real campaign in degrees keeps a joint inside +-6.3 deg only when that joint barely moves, and
# then the radian reading is tried and judged by the fit like any other.
RADIAN_MAX = 2 * np.pi
GAIN = MIN_GAIN["library"]  # the held-out gain a named effect needs (selection.py)


def joint_column_readings(q_deg):
    """[(kind, joints, q_deg read that way)] of a campaign's joint columns
    (N, 6) deg, in this order: ("radians", (j,), ...) for each column whose
    every value could be radians (|q| <= RADIAN_MAX) and that moves, then
    ("swap", (a, b), ...) for each pair of columns that differ.  Shared by
    the stiffness diagnosis (below) and the tracker's registration check
    (identification/tracker/angle_readings.py)."""
    q = np.asarray(q_deg, dtype=float)
    out = []
    for j in range(6):
        if np.all(np.abs(q[:, j]) <= RADIAN_MAX) and np.ptp(q[:, j]) > 0:
            qq = q.copy()
            qq[:, j] = np.rad2deg(q[:, j])
            out.append(("radians", (j,), qq))
    for a, b in combinations(range(6), 2):
        if not np.allclose(q[:, a], q[:, b]):
            qq = q.copy()
            qq[:, [a, b]] = q[:, [b, a]]
            out.append(("swap", (a, b), qq))
    return out


def _readings(campaign):
    """[(name, what was wrong, the check to make, the campaign read that way)]."""
    out = []
    for k, a in enumerate("xyz"):
        f, m = campaign.force_N.copy(), campaign.moment_Nm.copy()
        f[:, k] *= -1
        m[:, k] *= -1
        both = f"f{a}" + (f" and m{a}" if campaign.has_moments else "")
        out.append((f"force_sign_{a}", f"{both} with the wrong sign",
                    f"check the force sensor's {a} axis convention and its transform to the base frame",
                    replace(campaign, force_N=f, moment_Nm=m)))
    for k, a in enumerate("xyz"):
        d = campaign.disp_mm.copy()
        d[:, k] *= -1
        out.append((f"disp_sign_{a}", f"d{a} with the wrong sign",
                    f"check the instrument's {a} axis against the robot's base frame (loaded minus unloaded)",
                    replace(campaign, disp_mm=d)))
    for kind, joints, qq in joint_column_readings(campaign.q_deg):
        if kind == "radians":
            j = joints[0] + 1
            out.append((f"radians_q{j}", f"q{j} written in radians in a column of degrees",
                        f"check q{j}'s unit where the file was made (the controller gives degrees)",
                        replace(campaign, q_deg=qq)))
        else:
            a, b = joints[0] + 1, joints[1] + 1
            out.append((f"swap_q{a}q{b}", f"the columns q{a} and q{b} interchanged",
                        f"check the order of the joint columns where the file was made (q{a} is joint {a})",
                        replace(campaign, q_deg=qq)))
    return out


def _fold_rms(resid, fold_rows, units):
    """Held-out RMS (mm) of a held-out residual (3N,) m, per fold, and its sum of squares per test unit (pose)."""
    per = np.array([rms_mm(resid[rows_to_eq(te)]) for _, te in fold_rows])
    rows = np.concatenate([te for _, te in fold_rows])
    ss = np.sum(resid.reshape(-1, 3)[rows] ** 2, axis=1)
    keys, inv = np.unique(np.asarray(units)[rows], return_inverse=True)
    return rms_mm(resid[rows_to_eq(rows)]), per, np.bincount(inv, weights=ss, minlength=len(keys))


def paired_p(ss_written, ss_read):
    """One-sided p that the reading's held-out squared residual is lower,
    paired by pose (t over the poses' differences)."""
    d = np.asarray(ss_written) - np.asarray(ss_read)
    if len(d) < 3 or not np.any(d):
        return 1.0
    sd = np.std(d, ddof=1)
    if sd == 0:
        return 0.0 if np.mean(d) > 0 else 1.0
    return float(stats.t.sf(np.mean(d) / (sd / np.sqrt(len(d))), len(d) - 1))


def screen(ctx, fold_rows, units, resid_written):
    """The readings of ``ctx``'s campaign that the six springs fit better
    (module docstring), the decisive first, each best first: [{name,
    mistake, check, held_out_mm, as_written_mm, fold_gains, p_paired,
    decisive, text}].  ``ctx``: the diagnosis's
    Context; ``fold_rows``: its folds; ``units``: the test units (poses) of
    every row; ``resid_written``: the held-out residual (3N,) m of the best
    model of the file as written (the diagnosis's final model: a physical
    effect that explains the file as written leaves no case for misreading
    it)."""
    base, base_per, base_ss = _fold_rms(resid_written, fold_rows, units)
    readings = _readings(ctx.campaign)
    found = []
    for name, mistake, check, other in readings:
        try:
            # (the kinematics once per reading of the angles: a sign read another way keeps the file's)
            if other.q_deg is ctx.campaign.q_deg:
                T, J = ctx.frames, ctx.J
            else:
                q = ctx.robot.joint_rad(other.q_deg)
                T = kin.frames(ctx.robot.dh, q)
                J = kin.jacobian(ctx.robot.dh, q, ctx.tool, T=T)
            alt = Context(ctx.robot, other, ctx.tool, identify(ctx.robot, other, tool_m=ctx.tool, J=J).identifiable,
                          J=J, frames=T)
            rms, per, ss = _fold_rms(held_out(alt, [], fold_rows)[0], fold_rows, units)
        except (InputError, ValueError, np.linalg.LinAlgError):  # a reading the model refuses (its units) or cannot fit
            continue
        gains = 1.0 - per / np.maximum(base_per, 1e-300)
        if np.isfinite(rms) and rms <= (1 - GAIN) * base:
            found.append({"name": name, "mistake": mistake, "check": check, "held_out_mm": rms,
                          "as_written_mm": base, "fold_gains": [float(g) for g in gains],
                          "p_paired": paired_p(base_ss, ss), "decisive": fold_consistent(gains)})
    found.sort(key=lambda r: (not r["decisive"], r["held_out_mm"]))
    for r in found:
        g = r["fold_gains"]
        folds = (f"lower on every fold ({100 * min(g):.0f}-{100 * max(g):.0f} %)" if r["decisive"] else
                 f"lower on {sum(x > 0 for x in g)} of {len(g)} folds, so not decisive")
        r["text"] = (f"the file fits {'far ' if r['decisive'] else ''}better read with {r['mistake']}: six springs "
                     f"held out {r['held_out_mm']:.4f} mm against {r['as_written_mm']:.4f} mm for the final model of "
                     f"the file as written, {folds}: {r['check']}")
    return found


def sentence(found):
    """The verdict's words for the readings found ('' when none)."""
    if not found:
        return ""
    if not found[0]["decisive"]:
        return ("possibly a setup mistake (the file read another way; the data cannot decide): "
                + "; ".join(r["text"] for r in found[:3])
                + "; the diagnosis below is of the file as written: check before trusting its terms")
    head = f"setup finding (the file read another way): {found[0]['text']}"
    rivals = [r for r in found[1:] if r["decisive"] and r["held_out_mm"] <= 1.05 * found[0]["held_out_mm"]]
    if rivals:
        head += ("; about as good (the data cannot decide between them): "
                 + "; ".join(f"{r['mistake']} ({r['held_out_mm']:.4f} mm)" for r in rivals))
    return head + "; the diagnosis below is of the file as written, and its terms may stand in for this mistake"
