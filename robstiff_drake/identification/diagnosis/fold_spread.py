"""How much a held-out figure depends on the folds: the six springs and the
final model's terms (refitted in every fold from its training rows, as in
the search) over several pose-grouped fold assignments.  Plain numpy.

One grouped k-fold assignment gives one number; on a small campaign (the
FANUC campaign's 43 poses) another assignment moves the held-out RMS and
the reduction by several points.  The spread is reported next to the number
so that no one reads a third digit that the folds do not carry.  The terms
are the ones the search chose on the first assignment (FOLD_SEED): the
spread measures the folds' share of the uncertainty, not the selection's
(a selection rerun per assignment is in studies/fanuc_folds.py).
"""

import numpy as np

from robstiff_drake.identification.diagnosis.cross_validation import FOLD_SEEDS, rows_to_eq, splits
from robstiff_drake.identification.diagnosis.terms import held_out, rms_mm


def fold_spread(ctx, terms, rows, units, seeds=FOLD_SEEDS):
    """{seeds, rms_before_mm, rms_after_mm (lists, one per assignment),
    reduction_min, reduction_median, reduction_max (fractions)} of the six
    springs and of the model with ``terms`` over the fold assignments
    ``seeds`` of ``rows`` grouped by ``units``."""
    eq = rows_to_eq(rows)
    before, after = [], []
    for s in seeds:
        folds = splits(rows, units, seed=s)
        r0, _ = held_out(ctx, [], folds)
        r1 = held_out(ctx, terms, folds)[0] if terms else r0
        before.append(rms_mm(r0[eq]))
        after.append(rms_mm(r1[eq]))
    red = 1.0 - np.asarray(after) / np.asarray(before)
    return {"seeds": [int(s) for s in seeds], "rms_before_mm": before, "rms_after_mm": after,
            "reduction_min": float(red.min()), "reduction_median": float(np.median(red)),
            "reduction_max": float(red.max())}


def describe(spread):
    """One line: the range of the figures over the assignments."""
    s = spread["seeds"]
    b, a = spread["rms_before_mm"], spread["rms_after_mm"]
    return (f"over {len(s)} fold assignments (seeds {s[0]}-{s[-1]}, the kept terms refitted in each fold): six "
            f"springs {min(b):.4f}-{max(b):.4f} mm, final model {min(a):.4f}-{max(a):.4f} mm, reduction "
            f"{100 * spread['reduction_min']:.0f}-{100 * spread['reduction_max']:.0f} % (median "
            f"{100 * spread['reduction_median']:.0f} %)")
