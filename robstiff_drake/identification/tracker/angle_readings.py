"""A tracker campaign the nominal arm cannot register: is one joint column
misread?  Plain numpy; no Drake.

When the measured points match no length unit, or register to the robot
file's nominal arm more than identification/tracker/diagnosis.py's limit
off, the refusal names the robot file or the angle convention.  A joint's
column in radians (tried where every value lies within 2 pi, a full turn in
radians) or two joint columns interchanged give the same refusal; each such
reading is registered as the file was (closed-form registration and the
measured point, then Gauss-Newton), and the best is named in the refusal
when it registers within the limit and 3x better than the file as written
(the factor diagnosis.py's check of all angles in radians uses).  Nothing
is changed: the user fixes the file.
"""

from itertools import combinations

import numpy as np

from robstiff_drake.errors import InputError

RADIAN_MAX = 2 * np.pi  # radians never exceed a full turn (joint ranges reach +-360 deg at most)
BETTER = 3.0  # registered this many times better than as written (diagnosis._check_angles's factor)


def readings(q_deg):
    """[(what, check, q_deg read that way)]."""
    out = []
    for j in range(6):
        if np.all(np.abs(q_deg[:, j]) <= RADIAN_MAX) and np.ptp(q_deg[:, j]) > 0:
            q = q_deg.copy()
            q[:, j] = np.rad2deg(q_deg[:, j])
            out.append((f"q{j + 1} in radians", f"check q{j + 1}'s unit where the file was made", q))
    for a, b in combinations(range(6), 2):
        if not np.allclose(q_deg[:, a], q_deg[:, b]):
            q = q_deg.copy()
            q[:, [a, b]] = q_deg[:, [b, a]]
            out.append((f"q{a + 1} and q{b + 1} interchanged", "check the order of the joint columns", q))
    return out


def hint(q_deg, registered_rms_mm, as_written_mm, limit_mm):
    """' ; read with ...' for the refusal's message, or ''.
    ``registered_rms_mm(q_deg)``: the registration's RMS (mm) of the points
    at those angles (InputError or a non-finite value: not registrable);
    ``as_written_mm``: the file's own (inf when it did not register)."""
    best = None
    for what, check, q in readings(np.asarray(q_deg, dtype=float)):
        try:
            rms = float(registered_rms_mm(q))
        except (InputError, ValueError, np.linalg.LinAlgError):
            continue
        if np.isfinite(rms) and (best is None or rms < best[0]):
            best = (rms, what, check)
    if best is None or best[0] > limit_mm or not best[0] * BETTER < as_written_mm:
        return ""
    written = f"as written {as_written_mm:.4g} mm" if np.isfinite(as_written_mm) else "as written they match no unit"
    return f"; read with {best[1]}, the points register to {best[0]:.3g} mm RMS ({written}): {best[2]}"
