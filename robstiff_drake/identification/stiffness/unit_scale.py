"""A unit written as another, seen in the identified stiffness as a whole.
Plain numpy; no Drake.

A common scale of every force (lbf or kgf written in the N columns) or of
every displacement (inches written in the mm columns) scales every
identified stiffness alike and leaves the fit, its residual and the
diagnosis's verdict as they were (docs/diagnosis.md): the data alone cannot
tell.  What can is a stiffness known apart from the campaign: the robot
file's.  Its values are often a catalogue's or a paper's, within about 2x of
an arm's (the real FANUC R-2000iC campaign's joints lie 0.63-2.72x of its
file's), so a single joint off by a unit's factor says nothing; every
identified joint off the same way, their geometric mean within
``FACTOR_TOLERANCE`` of a unit's factor, is a possible setup mistake: a
warning (the file read as written is still what is identified), with the
measurement that decides it (a known weight on the sensor, a gauge block
under the instrument).
"""

import numpy as np

LBF_N = 4.4482216  # N per pound-force (NIST SP 811)
KGF_N = 9.80665  # N per kilogram-force (NIST SP 811); a decanewton (10 N) is within the tolerance of it
INCH_MM = 25.4
# (what was written as what, the factor the identified stiffness is off by: < 1 softer than the file, > 1 stiffer,
# the check that decides)
MISTAKES = (
    ("forces in lbf written as N", 1.0 / LBF_N,
     "hang a known weight on the sensor, or read the force unit configured in it"),
    ("forces in kgf (or daN) written as N", 1.0 / KGF_N,
     "hang a known weight on the sensor, or read the force unit configured in it"),
    ("displacements in inches written as mm", INCH_MM,
     "measure a gauge block with the instrument, or read the unit it exports"),
)
# ASSUMPTION: the geometric mean of the joints' ratios must lie within this factor of a unit's (the nearest unit is
# named).  The real R-2000iC campaign's joints lie 1.52x of its robot file's on average (geometric mean; 0.63-2.72x
# each), so a tolerance below that would miss a unit written as another on such a file; at 1.6, lbf's band is
# 2.8-7.1x softer, kgf's 6.1-15.7x softer (the nearer named where they touch), inches' 15.9-40.6x stiffer, and a
# file as far off as the FANUC's (1.52x) is not taken for a unit.
FACTOR_TOLERANCE = 1.6
MIN_JOINTS = 3  # fewer identified joints: no mean worth the name


def unit_scale_note(stiffness_Nm_per_rad, nominal_Nm_per_rad, identifiable, data_path, robot_source):
    """A warning (one line) when every identified joint's stiffness is off
    the robot file's the same way by about a unit's factor (module
    docstring), else None."""
    k = np.asarray(stiffness_Nm_per_rad, dtype=float)
    k0 = np.asarray(nominal_Nm_per_rad, dtype=float)
    use = np.asarray(identifiable, dtype=bool) & np.isfinite(k) & (k > 0) & (k0 > 0)
    if use.sum() < MIN_JOINTS:
        return None
    r = k[use] / k0[use]
    g = float(np.exp(np.mean(np.log(r))))
    near = [(abs(np.log(g / factor)), mistake, factor, check) for mistake, factor, check in MISTAKES
            if (np.all(r < 1.0) if factor < 1.0 else np.all(r > 1.0))
            and abs(np.log(g / factor)) <= np.log(FACTOR_TOLERANCE)]
    if not near:
        return None
    near.sort()
    way = f"{1 / g:.3g}x softer" if near[0][2] < 1.0 else f"{g:.3g}x stiffer"
    said = " or ".join(f"{mistake} (that gives {1 / f:.3g}x softer)" if f < 1.0 else
                       f"{mistake} (that gives {f:.3g}x stiffer)" for _, mistake, f, _ in near)
    checks = "; ".join(dict.fromkeys(check for *_, check in near))
    return (f"{data_path}: every identified joint is {way} than the robot file ({robot_source}) says "
            f"(geometric mean; joints {r.min():.2f}-{r.max():.2f}x the file's): possibly {said}, or the file's "
            f"stiffness is a guess that far off; the fit cannot tell them apart: {checks}")
