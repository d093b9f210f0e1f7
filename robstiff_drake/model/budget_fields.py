"""The error budget's arithmetic, in plain numpy: a split of the error
field itself, and the one-at-a-time split of a statistic it replaces.

The field split.  ``e_full`` is the cut's error along the scan (mm, one
value per scan point), ``e_without[i]`` the error at the same points with
source i alone removed, ``e_floor`` with every source removed.  Source
i's field is ``e_i = e_full - e_without[i]`` and its share of the mean
square is ``<e_i, e_full> / ||e_full||^2``; the floor's share is
``<e_floor, e_full> / ||e_full||^2``.  When the sources' effects add
(``e_full = e_floor + sum_i e_i``) the shares add to 1 exactly, whatever
the fields' correlations; what they leave, ``1 - floor - sum_i share_i``,
is the true interaction: the part of the field that is not any single
source's effect.  In mm of RMS each share is its fraction times the RMS
of ``e_full`` (these add to the RMS the way the fractions add to 1), and
for the mean the fields' means add exactly (``mean_mm``).

The one-at-a-time split of a statistic (``one_at_a_time``: share = the
statistic less the statistic with the source removed, interaction = total
- floor - the shares) does not add for the RMS even when the effects add:
n equal uncorrelated sources give RMS sqrt(n) s, and removing one leaves
sqrt(n - 1) s, so the shares sum to n (sqrt(n) - sqrt(n - 1)) s, and the
"interaction" is 41-49 % of total - floor for n = 2..10, an artefact of
the metric (quadrature), not physics.
"""

import numpy as np


def common_points(fields):
    """The mask of the scan points finite in every field (equal lengths)."""
    arrays = [np.asarray(f, dtype=float) for f in fields]
    n = {a.shape for a in arrays}
    if len(n) != 1:
        raise ValueError(f"the error fields have different shapes {sorted(n)}: they are not on the same scan points")
    return np.logical_and.reduce([np.isfinite(a) for a in arrays])


def field_shares(e_full, e_without, e_floor):
    """The field split (module docstring): a dict ``shares`` ({source:
    fraction of the mean square}), ``floor`` (the floor field's fraction),
    ``interaction`` (1 - floor - the shares), ``rms_mm`` (of ``e_full``),
    ``shares_mm`` / ``floor_mm`` / ``interaction_mm`` (the fractions times
    the RMS: they add to it), ``mean_mm`` ({source: mean of its field}, with
    "floor", "interaction" and "total": these add exactly) and ``points``.
    ``e_without`` {source: field}; fields in mm on the same scan points
    (points not finite in every field are left out)."""
    names = list(e_without)
    mask = common_points([e_full, e_floor] + [e_without[k] for k in names])
    if not mask.any():
        raise ValueError("the error fields have no scan point in common")
    full = np.asarray(e_full, dtype=float)[mask]
    floor = np.asarray(e_floor, dtype=float)[mask]
    fields = {k: full - np.asarray(e_without[k], dtype=float)[mask] for k in names}
    norm2 = float(full @ full)
    if norm2 == 0.0:
        raise ValueError("the full cut's error field is zero: there is nothing to split")
    shares = {k: float(v @ full) / norm2 for k, v in fields.items()}
    floor_share = float(floor @ full) / norm2
    interaction = 1.0 - floor_share - sum(shares.values())
    rms = float(np.sqrt(norm2 / full.size))
    means = {k: float(v.mean()) for k, v in fields.items()}
    means["floor"] = float(floor.mean())
    means["total"] = float(full.mean())
    means["interaction"] = means["total"] - means["floor"] - sum(means[k] for k in names)
    return {"shares": shares, "floor": floor_share, "interaction": interaction, "rms_mm": rms,
            "shares_mm": {k: v * rms for k, v in shares.items()}, "floor_mm": floor_share * rms,
            "interaction_mm": interaction * rms, "mean_mm": means, "points": int(full.size)}


def one_at_a_time(total, without, floor):
    """The one-at-a-time split of a statistic: ({source: total - the
    statistic with it removed}, interaction = total - floor - their sum)."""
    contributions = {k: float(total - v) for k, v in without.items()}
    return contributions, float(total - floor - sum(contributions.values()))


def rms(field):
    """RMS of the finite values of a field."""
    f = np.asarray(field, dtype=float)
    f = f[np.isfinite(f)]
    return float(np.sqrt(np.mean(f * f)))
