"""Gross errors in a stiffness campaign: a robust fit that names the rows a
handful of bad readings come from.  Plain numpy + scipy.

A row is one loaded reading (three displacement components); a gross error
(a probe that slipped, a mistyped digit, a target knocked) spoils the row,
so rows are weighted whole.  The six-spring model is fitted by iteratively
reweighted least squares with Tukey's biweight on each row's residual
length, in units of a robust scale (the median row length, as for a 3-D
Gaussian; never below the stated noise floor).  A row is an outlier when its
squared residual length exceeds the chi-square(3) quantile at
ALPHA_OUTLIER / N (a Bonferroni level over the rows: a clean campaign has
a ALPHA_OUTLIER chance of any false flag).  Effects the model lacks widen
the robust scale instead of being flagged.

``screen_rows`` works from any fitted prediction (the six springs at the
start, the diagnosis's final model at the end).
"""

import numpy as np
from scipy import stats

from robstiff_drake.identification.diagnosis.cross_validation import rows_to_eq
from robstiff_drake.identification.diagnosis.terms import lstsq

ALPHA_OUTLIER = 0.01
# The first screen, against the six springs alone, flags only rows beyond
# this many robust sigma (an effect the springs lack leaves large but not
# gross residuals); the final model's screen uses the chi-square level.
PRE_SCREEN_SIGMAS = 8.0
# A gross error is also at least this long against the final model (a row the
# final model merely fits less well, at a few sigma, is not a gross error).
POST_SCREEN_SIGMAS = 6.0
TUKEY_C = 6.0  # biweight cut-off, in robust sigma per component (about 4.685 scaled to a 3-D length)
_CHI2_3_MEDIAN = stats.chi2.ppf(0.5, 3)


def robust_scale(row_lengths):
    """Per-component sigma from the median squared row length (3-D Gaussian)."""
    return float(np.sqrt(np.median(np.asarray(row_lengths) ** 2) / _CHI2_3_MEDIAN))


def threshold(n_rows):
    """Squared row length / sigma^2 above which a row is an outlier."""
    return float(stats.chi2.isf(ALPHA_OUTLIER / max(n_rows, 1), 3))


def screen_rows(resid_rows_m, fit_rows, floor_m=None, min_sigmas=0.0):
    """Flag rows whose residual (N, 3) is gross against the robust scale of
    ``fit_rows``' residuals (and longer than ``min_sigmas`` of it).  Returns
    (flagged row indices, sigma_m)."""
    lengths = np.linalg.norm(resid_rows_m, axis=1)
    s = robust_scale(lengths[fit_rows])
    if floor_m is not None:
        s = max(s, floor_m)
    if s == 0:
        return np.array([], dtype=int), s
    flagged = np.flatnonzero(lengths**2 / s**2 > max(threshold(len(lengths)), min_sigmas**2))
    return flagged, s


def tukey_springs(ctx, rows, floor_m=None, iterations=30):
    """IRLS (Tukey biweight on whole rows) of the six springs on ``rows``.
    Returns the residuals of all rows, (N, 3) m."""
    eq = rows_to_eq(rows)
    A, b = ctx.A, ctx.b
    x = lstsq(A[eq], b[eq])
    for _ in range(iterations):
        r = (b - A @ x).reshape(-1, 3)
        lengths = np.linalg.norm(r[rows], axis=1)
        s = robust_scale(lengths)
        if floor_m is not None:
            s = max(s, floor_m)
        if s == 0:
            break
        u = lengths / (TUKEY_C * s)
        w = np.where(u < 1, (1 - u**2) ** 2, 0.0)
        sw = np.repeat(np.sqrt(w), 3)
        x_new = lstsq(A[eq] * sw[:, None], b[eq] * sw)
        done = np.max(np.abs(x_new - x) / np.maximum(np.abs(x), 1e-12)) < 1e-9
        x = x_new
        if done:
            break
    return (b - A @ x).reshape(-1, 3)
