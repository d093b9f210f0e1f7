"""The arm's damping that a machining run's face decides
(identification/runs/diagnosis.py, whose docstring describes the method):
the traced model refitted with the arm's response at each damping ratio of
a grid.  Plain numpy."""

import numpy as np

from robstiff_drake.identification.runs import scan_statistics as ss
from robstiff_drake.identification.runs.causes import EXPLAIN_ALPHA, Envelope, candidates, fit_model, rms
from robstiff_drake.identification.runs.signals import DAMPING_RATIO, signals_at

# The damping's profile (``profile_damping``): the ratios tried, and its likelihood interval (chi-square, one
# parameter, 95 %: the fit's residual sum of squares within 3.84 noise floors squared, per effective point,
# of the best).
DAMPING_GRID = np.array([0.02, 0.03, 0.05, 0.07, 0.10, 0.15, 0.20])
DAMPING_CHI2 = 3.84


def profile_damping(run_ctx, arm, scan, cutter_mm, y, floor_m, stats_ctx, model):
    """The gears' modal damping ratio that the run's face decides: the
    causes of ``model`` (a Fit: the loop's tracking error and the named
    causes) refitted with the arm's response at each ratio of DAMPING_GRID
    (the arm's own motion error and the loop's response ring more or less);
    the interval of ratios whose fit is within DAMPING_CHI2 noise floors
    squared (per effective point) of the best.  A dict: ratio (None when the
    interval covers the whole grid: the face does not decide it), interval,
    the fits' rms (mm) per ratio, source, used."""
    rss, residuals = [], []
    for z in DAMPING_GRID:
        sig = signals_at(run_ctx, arm, z)
        env = Envelope(scan, sig, cutter_mm)
        by_name = {c.name: c for c in candidates(sig)}
        causes = [by_name[c.name] for c in model.causes]
        r = (fit_model(env, causes, model.keep, y).residual if causes else env.surface(np.zeros_like(sig.t_s)) - y)
        residuals.append(r)
        rss.append(float(r @ r))
    rss = np.array(rss)
    i = int(np.argmin(rss))
    n_eff, _ = ss.effective_points(residuals[i] * 1e3, stats_ctx["segs"], stats_ctx["length_mm"], cutter_mm)
    chi2 = (rss - rss[i]) / floor_m**2 * n_eff / y.size
    inside = chi2 <= DAMPING_CHI2
    lo, hi = float(DAMPING_GRID[inside].min()), float(DAMPING_GRID[inside].max())
    # a fit that leaves more than the noise says the model lacks something: the damping would take its place
    explained = ss.consistent_with_floor(residuals[i] * 1e3, floor_m * 1e3, n_eff, EXPLAIN_ALPHA)
    # the grid's top (20 %) is past what an arm's modes show (about 2-10 %): a best fit there is no estimate
    at_top = i == len(DAMPING_GRID) - 1
    decided = explained and not at_top and not (lo == DAMPING_GRID[0] and hi == DAMPING_GRID[-1])
    ratio = float(DAMPING_GRID[i]) if decided else None
    if decided:
        source = "estimated from the run (the fit to the face at each ratio)"
    elif explained and at_top:
        source = (f"assumed ({DAMPING_RATIO:g}): the run does not decide it (the face fits best at "
                  f"{DAMPING_GRID[-1]:g} of critical or more, beyond the 0.02-0.10 an arm's modes show: the damping "
                  "would stand in for something the model lacks)")
    elif not explained:
        source = (f"assumed ({DAMPING_RATIO:g}): the run does not decide it (the best fit, at {DAMPING_GRID[i]:g}, "
                  f"leaves {rms(residuals[i]) * 1e3:.4f} mm, more than the noise: the model lacks something the "
                  "damping would stand in for)")
    else:
        source = (f"assumed ({DAMPING_RATIO:g}): the run does not decide it (every ratio from {lo:g} to {hi:g} fits "
                  "the face as well)")
    return {"ratio": ratio, "interval": [lo, hi], "grid": DAMPING_GRID.tolist(),
            "rms_mm": (np.sqrt(rss / y.size) * 1e3).tolist(), "used": ratio if decided else DAMPING_RATIO,
            "source": source}
