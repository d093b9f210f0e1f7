"""How much modal damping would make a chattering cut stable?  The number
that decides the chatter check's verdict (diagrams/chatter_check.py).

The check's root grows on a few of the arm's modes (``modes_involved``),
and rests on the scenario's modal damping ratio (an assumption unless
measured).  Here the arm's joints at the check's worst pose are given
other damping, and the least ratio at which the delay law's rightmost root
is stable is found by bisection (scipy's brentq: bisection safeguarding
secant steps, to RATIO_RESOLUTION):

- on the involved modes only, the others keeping the scenario's ratios;
- the same ratio on every mode.

The ratio is stated as the scenario states its damping (plant.damping_on:
on the drives-closed arm modes, model/joint_dynamics.realise_drives_closed,
or on the motors-held modes) and realised at the pose alone (the station
fits one gears' damping along the path; at the pose that fit's ratios are
within a few tenths of a percent of the stated ones).  Where the drives
alone damp a mode beyond the stated ratio (the arm's modes 4 and 5 near
39 Hz: about 10 % with 5 % stated), the stated ratio is not what a modal
test would measure, so the involved modes' drives-closed ratios at the
bisection's end are reported beside it (``realised``): what a modal test
of the arm with its drives on must find for the cut to be stable.

It assumes the cut, once stable, stays stable with more damping (a root
that another takes over from is bisected to where the rightmost one
crosses); MAX_RATIO bounds the search.
"""

import numpy as np
from scipy import optimize

from robstiff_drake.model import chip_coupling as cc
from robstiff_drake.model import joint_dynamics as jd

RATIO_RESOLUTION = 5e-4  # the bisection's resolution in the damping ratio (0.05 % of critical)
MAX_RATIO = 0.5  # the search's bound: half of critical damping (a robot's structure is far below it)


def with_damping(jm, ratios, damping_on="drives_closed"):
    """``jm`` (model/joint_dynamics.JointModel at a pose) with the gears'
    damping that gives its modes the damping ratios ``ratios`` (6,), stated
    on the drives-closed or the motors-held modes."""
    if damping_on == "motors_held":
        return jd.JointModel(**{**jm.__dict__, "D": jd.modal_damping_matrix(jm.M, jm.K, jm.G, ratios)})
    return jd.realise_drives_closed(jm, ratios)


def stabilising_ratio(jm, J, chip, root_of, assumed, modes=None, damping_on="drives_closed"):
    """(ratio, realised) or None: the least damping ratio (stated as
    ``damping_on`` says) on the modes ``modes`` (numbers from 1, the
    others keeping ``assumed`` (6,); None: the same ratio on every mode)
    at which the delay law's rightmost root ``root_of(arm, chip)`` (1/s, complex)
    of the arm ``jm`` (at the pose, tool Jacobian J) with the linearised
    ``chip`` is stable, and the drives-closed damping ratios of ``modes``
    (every mode when None) realised there; None when not even MAX_RATIO is.
    0.0 when no damping is needed."""
    idx = np.arange(6) if modes is None else np.asarray(modes, dtype=int) - 1
    base = np.broadcast_to(np.asarray(assumed, dtype=float), (6,)).copy()

    def arm_at(z):
        r = base.copy()
        r[idx] = z
        return with_damping(jm, r, damping_on)

    def growth(z):
        return root_of(cc.arm_from_joint_model(arm_at(z), J), chip).real

    if growth(MAX_RATIO) >= 0:
        return None
    lo = float(np.min(base[idx]))
    if growth(lo) < 0:  # (stable at the assumed ratio realised at the pose alone: the least below it)
        if growth(0.0) < 0:
            return 0.0, [float(v) for v in arm_at(0.0).arm_modes()[1][idx]]
        lo, hi = 0.0, lo
    else:
        hi = MAX_RATIO
    z = optimize.brentq(growth, lo, hi, xtol=RATIO_RESOLUTION)
    return float(z), [float(v) for v in arm_at(z).arm_modes()[1][idx]]


def damping_to_stabilise(jm, J, chip, root_of, assumed, modes, damping_on="drives_closed"):
    """The check's "damping_to_stabilise" (a dict): ``modes`` (the involved
    modes' numbers), ``ratio_now`` (their drives-closed ratios at the pose
    now), ``on_these_modes`` / ``realised_on_these_modes`` (the stated
    ratio on them alone that makes the cut stable, and their drives-closed
    ratios there; None: not within MAX_RATIO), ``on_every_mode`` (the same
    ratio on all six; None likewise), ``searched_up_to``."""
    now = jm.arm_modes()[1][np.asarray(modes, dtype=int) - 1]
    own = stabilising_ratio(jm, J, chip, root_of, assumed, modes, damping_on)
    every = stabilising_ratio(jm, J, chip, root_of, assumed, None, damping_on)
    return {"modes": [int(m) for m in modes], "ratio_now": [float(v) for v in now],
            "on_these_modes": None if own is None else own[0],
            "realised_on_these_modes": None if own is None else own[1],
            "on_every_mode": None if every is None else every[0], "searched_up_to": MAX_RATIO,
            "stated_on": damping_on}


def damping_phrase(d):
    """The warning's clause on ``damping_to_stabilise``'s result ``d``."""
    if not d:
        return ""
    order = np.argsort(d["modes"])
    ms = "-".join(str(d["modes"][i]) for i in order)
    now = [100 * d["ratio_now"][i] for i in order]
    if d["on_these_modes"] is None:
        out = f"; not stable with arm modes {ms} damped up to {100 * d['searched_up_to']:.0f} %"
    else:
        need = [100 * d["realised_on_these_modes"][i] for i in order]
        digits = 2 if min(abs(a - b) for a, b in zip(need, now)) < 0.1 else 1  # (the edge: what tells them apart)
        need_s = (f"{need[0]:.{digits}f}" if len({round(v, digits) for v in need}) == 1 else
                  " and ".join(f"{v:.{digits}f}" for v in need))
        out = (f"; stable if arm modes {ms} were damped at least {need_s} % (drives closed, as a modal test "
               f"measures; now {' and '.join(f'{v:.{digits}f}' for v in now)} % at this pose")
        stated = 100 * d["on_these_modes"]
        if abs(stated - max(need)) > 0.05:
            out += f", {stated:.{digits}f} % stated on the {d['stated_on'].replace('_', '-')} modes"
        out += ")"
    if d["on_every_mode"] is not None:
        out += f", or {100 * d['on_every_mode']:.1f} % stated on every mode"
    return out
