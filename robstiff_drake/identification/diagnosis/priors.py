"""A typical size is a prior, not a veto: the rule by which the diagnosis's
selection (identification/diagnosis/selection.py) keeps a term whose size lies beyond
its typical range (identification/diagnosis/plausibility.py).  Plain numpy + scipy.

Such a candidate is added only on decisive evidence (``decisive``):
  * its nested F-test and its pose-clustered test both at P_DECISIVE or
    below (about 5 sigma);
  * a held-out RMS lower on every fold, the mean gain FOLD_SPREAD_FACTOR
    times its standard error over the folds (their spread / sqrt(folds));
  * EXCESS_EXPLAINED of the held-out residual's variance above the noise
    floor taken out: it is THE explanation of what is left, as a wrong tool
    point or an untared sensor is, not one more term that fits part of a
    residual many times the noise (without a floor nothing is decisive);
  * its estimate not confounded (|r| >= CONFOUNDED_MIN) with a kept term.
    A correlation with a joint's stiffness does not stop it (a tool point
    along the flange's axis trades off against the wrist's stiffness in most
    campaigns); the diagnosis reports it with the plan that separates them.
Among the candidates that qualify it then pays PRIOR_PENALTY on its held-out
RMS per decade its size lies beyond the range (``score``), so that an
explanation of typical size that fits about as well is preferred.  The
report names what a kept term beyond its typical size implies
(identification/diagnosis/findings.py).  A sign physics forbids is never added,
whatever the evidence (selection.py).
"""

from dataclasses import dataclass

import numpy as np
from scipy import special

from robstiff_drake.identification.diagnosis.confounding import CONFOUNDED_MIN, correlation, design_covariance
from robstiff_drake.identification.diagnosis.cross_validation import rows_to_eq
from robstiff_drake.identification.diagnosis.terms import rms_mm

# Decisive evidence for a size beyond the typical: both tests at this level (about 5 sigma)
P_DECISIVE = 1e-6
# ... and the held-out gain over the folds: lower on every fold, its mean this many times its standard error
FOLD_SPREAD_FACTOR = 3.0
# ... and the share of the held-out residual's variance above the noise floor it takes out
EXCESS_EXPLAINED = 0.75
# the prior's weight in the choice: a term beyond its typical size competes with its held-out RMS raised by this
# fraction per decade of its size beyond the range (plausibility.excess)
PRIOR_PENALTY = 0.10


@dataclass
class Evidence:
    """What ``decisive`` reads of a candidate (candidate_evaluation.CandidateResult has
    these fields too) or of a kept term at the final fit."""

    rms_mm: float  # held out, with it
    p_value: float  # nested F-test
    p_grouped: float  # pose-clustered Wald test
    fold_gains: np.ndarray  # per fold: 1 - its held-out RMS / the RMS without it
    correlations: dict  # joint or term -> correlation of the estimates


def fold_consistent(gains):
    """Lower on every fold, the mean gain FOLD_SPREAD_FACTOR times its
    standard error over the folds (sample sd / sqrt(folds))."""
    g = np.asarray(gains, dtype=float)
    return bool(len(g) > 1 and np.all(g > 0)
                and np.mean(g) >= FOLD_SPREAD_FACTOR * np.std(g, ddof=1) / np.sqrt(len(g)))


def confounded_with(correlations):
    """(name, r) of the strongest correlation at CONFOUNDED_MIN or above, else None."""
    strong = [(k, v) for k, v in (correlations or {}).items() if abs(v) >= CONFOUNDED_MIN]
    return max(strong, key=lambda kv: abs(kv[1])) if strong else None


def excess_explained(rms_from, rms_to, floor_mm):
    """Share of the held-out residual's variance above the noise floor that
    going from ``rms_from`` to ``rms_to`` (mm) takes out (nan without a floor
    or without an excess)."""
    if floor_mm is None or rms_from <= floor_mm:
        return float("nan")
    return 1.0 - max(rms_to**2 - floor_mm**2, 0.0) / (rms_from**2 - floor_mm**2)


def decisive(r, current_rms, floor_mm):
    """Is the evidence for a candidate beyond its typical size decisive (module
    docstring)?  ``current_rms``: the held-out RMS (mm) without it; ``floor_mm``:
    the noise floor (None: unknown).  Returns (bool, why not)."""
    if floor_mm is None:
        return False, "beyond its typical size, and with no noise floor known the evidence cannot be judged decisive"
    share = excess_explained(current_rms, r.rms_mm, floor_mm)
    if not share >= EXCESS_EXPLAINED:
        return False, (f"beyond its typical size, and it takes out only {100 * max(share, 0):.0f} % of the residual "
                       f"above the noise floor ({100 * EXCESS_EXPLAINED:.0f} % needed for a size beyond the typical)")
    if not (r.p_value <= P_DECISIVE and r.p_grouped <= P_DECISIVE):
        return False, (f"beyond its typical size, and its tests are not decisive (F-test p = {r.p_value:.2g}, "
                       f"pose-clustered p = {r.p_grouped:.2g}; {P_DECISIVE:g} needed)")
    if r.fold_gains is not None and not fold_consistent(r.fold_gains):
        g = r.fold_gains
        return False, (f"beyond its typical size, and its held-out gain is not clear of the folds' spread "
                       f"({100 * np.min(g):.0f} to {100 * np.max(g):.0f} % over the folds)")
    conf = confounded_with({k: v for k, v in (r.correlations or {}).items() if not k.startswith("stiffness_j")})
    if conf:
        return False, (f"beyond its typical size, and confounded with {conf[0]} (correlation of the estimates "
                       f"{conf[1]:+.2f}): the data cannot tell the two apart")
    return True, ""


def refusal(r, current_rms, floor_mm):
    """Why a lead was not added, in words."""
    if r.physical is False or r.forbidden:
        return r.plausibility
    why = decisive(r, current_rms, floor_mm)[1]
    return f"{r.plausibility}; {why}" if why else r.plausibility


def score(r):
    """Held-out RMS with the prior's penalty for a size beyond the typical."""
    if r.plausible is not False:
        return r.rms_mm
    return r.rms_mm * (1 + PRIOR_PENALTY * max(np.log10(min(r.excess, 1e6)), 0.0))


def final_evidence(ctx, state, without, p_grouped, name, rows, folds):
    """A kept term judged at the final fit as ``decisive`` judges a candidate:
    an Evidence record of its F-test (the model against the model
    without it), pose-clustered p, per-fold gains and correlations."""
    f = state.full
    eq = rows_to_eq(rows)
    sl = f.slices[name]
    pe, n_eq = sl.stop - sl.start, len(eq)
    df2 = n_eq - f.X.shape[1]
    F = ((without.rss - state.rss) / pe) / (state.rss / df2) if state.rss > 0 and df2 > 0 else np.inf
    p = float(special.fdtrc(pe, df2, F)) if np.isfinite(F) else 0.0
    gains = np.array([1 - rms_mm(state.resid[rows_to_eq(te)]) / max(rms_mm(without.resid[rows_to_eq(te)]), 1e-300)
                      for _, te in folds])
    cov = design_covariance(f.X[eq])
    idx = np.arange(sl.start, sl.stop)
    corr = {f"stiffness_j{j + 1}": correlation(cov, idx, [i]) for i, j in enumerate(ctx.free)}
    corr.update({other: correlation(cov, idx, np.arange(s.start, s.stop)) for other, s in f.slices.items()
                 if other != name})
    return Evidence(state.rms_mm, p, p_grouped, gains, corr)
