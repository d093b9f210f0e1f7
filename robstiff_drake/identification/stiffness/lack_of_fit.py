"""Whether the six springs (Eq. 8) explain a stiffness campaign: the fit's
residual scatter against the campaign's noise floor.  Plain numpy + scipy.

`robstiff identify` estimates its noise from the residual of its own fit
(sigma^2 = |r|^2 / dof): that is the instrument's noise only when the model
is right.  Play in a gear (lost motion), a loose base or a sensor's
crosstalk add a residual the springs cannot absorb, and the fit then comes
out biased (a lost-motion campaign: J1 11 % low with a +-4 % interval that
misses the true value) with nothing in the output to say so.  Against an
independent floor the misfit shows:

  * stated: ``--noise-mm``, or the file's ``# noise_mm:`` line before its
    header row (the instrument's 1-sigma noise of one displacement
    component, mm; `robstiff synth stiffness` writes it);
  * else estimated from replicate rows (same pose, same load:
    diagnosis/noise_floor.py, as `robstiff diagnose` does);
  * else unknown: no test (the JSON says so).

The intervals are left as they are and the warning says they assume the
model is right, rather than widened by the ratio: they already scale with
the fit's own sigma (the residual, not the floor), so a widening by the
ratio would count the misfit twice, and a missing effect biases the
estimate by an amount no multiple of the residual bounds (the lost-motion
campaign's J1 sits 11 % low, 3.2 half-widths of its interval away).
"""

import numpy as np
from scipy import stats

from robstiff_drake.errors import InputError, excerpt
from robstiff_drake.identification.stiffness.measurement_table import header_line

NOISE_KEY = "noise_mm"
# the same range as diagnose's --noise-mm (commands/diagnose.py MAX_NOISE_MM): a CMM's or a tracker's noise
MAX_NOISE_MM = 10.0

# ASSUMPTION: a fit whose noise estimate is more than RATIO_LIMIT times the
# floor is not explained by the springs.  2, not nearer 1, because (a) a
# displacement is loaded minus unloaded reading, and rows that share one
# unloaded reading make its noise up to sqrt(2) (1.41) times an
# instrument's stated figure (diagnosis/noise_floor.py), and (b) a stated
# figure is rounded: `robstiff diagnose` takes a stated floor and the
# replicates' estimate within a factor 2 of each other as agreeing.  A right
# model's ratio exceeds 2 by chance with probability chi2.sf(4 dof, dof):
# 7e-3 at 3 degrees of freedom, 1e-5 at 10, nil at 100; P_LIMIT below keeps
# the few-row case honest.
RATIO_LIMIT = 2.0
P_LIMIT = 1e-3


def read_noise_header(path):
    """The noise (mm) of a campaign file's ``# noise_mm: SIGMA`` line before
    its header row, or None without one; InputError (file and line) for a
    malformed, out-of-range or repeated line."""
    found = header_line(path, NOISE_KEY)
    if found is None:
        return None
    lineno, value = found
    try:
        sigma = float(value)
    except ValueError:
        sigma = float("nan")
    if not 0.0 < sigma <= MAX_NOISE_MM:
        raise InputError(f"{path}:{lineno}: '# {NOISE_KEY}:' expects the 1-sigma noise of one displacement "
                         f"component in (0, {MAX_NOISE_MM:g}] mm, got {excerpt(value)}")
    return sigma


def stated_noise(campaign, stated_mm=None):
    """(sigma_mm or None, where it came from in words, or None): the stated
    floor of a stiffness campaign, ``stated_mm`` (--noise-mm) first, else
    the file's ``# noise_mm:`` line (InputError for a malformed one).  The
    one reading of both `robstiff identify` and `robstiff diagnose`."""
    if stated_mm is not None:
        return float(stated_mm), "stated (--noise-mm)"
    in_file = read_noise_header(campaign.path)
    if in_file is not None:
        return in_file, f"stated in {campaign.path}'s '# {NOISE_KEY}:' line"
    return None, None


def noise_floor(campaign, stated_mm=None):
    """(sigma_mm or None, source phrase or None): ``stated_noise`` (--noise-mm,
    else the file's ``# noise_mm:`` line), else the replicate rows' estimate
    (diagnosis/noise_floor.py), else (None, None)."""
    from robstiff_drake.identification.diagnosis.cross_validation import pose_groups
    from robstiff_drake.identification.diagnosis.noise_floor import estimate_floor

    stated, by = stated_noise(campaign, stated_mm)
    if stated is not None:  # (identify's floor: no replicate estimate beside a stated one)
        return stated, by
    floor = estimate_floor(campaign, pose_groups(campaign), np.arange(len(campaign)))
    return floor.sigma_mm, floor.source_text


def lack_of_fit(fit, floor_mm, source):
    """The JSON block of the test: the fit's noise estimate over the floor,
    the chance of a ratio that large under a right model (chi-square with
    the fit's dof), and whether the springs fail to explain the data."""
    if floor_mm is None or not np.isfinite(fit.sigma_mm) or fit.dof <= 0:
        return {"noise_floor_mm": floor_mm, "noise_floor_source": source, "residual_to_noise_ratio": None,
                "p_value": None, "explained_by_springs": None, "ratio_limit": RATIO_LIMIT}
    ratio = fit.sigma_mm / floor_mm
    p = float(stats.chi2.sf(fit.dof * ratio**2, fit.dof))
    return {"noise_floor_mm": floor_mm, "noise_floor_source": source, "residual_to_noise_ratio": float(ratio),
            "p_value": p, "explained_by_springs": not (ratio > RATIO_LIMIT and p < P_LIMIT),
            "ratio_limit": RATIO_LIMIT}


def _p(p):
    return f"= {p:.2g}" if p >= 1e-16 else "< 1e-16"


def lack_of_fit_warning(test, data):
    """One line when the springs do not explain the campaign, else None."""
    if test["explained_by_springs"] is not False:
        return None
    return (f"{data}: the fit is not explained by joint springs alone: its residual scatter (sigma "
            f"{test['noise_floor_mm'] * test['residual_to_noise_ratio']:.4f} mm) is "
            f"{test['residual_to_noise_ratio']:.1f}x the noise floor {test['noise_floor_mm']:.4f} mm "
            f"({test['noise_floor_source']}; more than {RATIO_LIMIT:g}x is implausible for a right model, "
            f"p {_p(test['p_value'])}): the model lacks an effect (gear play, a loose base, a sensor error) that "
            "biases the stiffnesses; their std errors and 95 % intervals assume the model is right and do not "
            "cover that bias; run `robstiff diagnose "
            f"{data} --noise-mm {test['noise_floor_mm']:.4g}` to find the effect")
