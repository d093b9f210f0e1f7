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

import numpy as np

from robstiff_drake.errors import InputError
from robstiff_drake.identification.diagnosis.misreadings import joint_column_readings

BETTER = 3.0  # registered this many times better than as written (diagnosis._check_angles's factor)


def readings(q_deg):
    """[(what, check, q_deg read that way)]."""
    out = []
    for kind, joints, q in joint_column_readings(q_deg):  # (the stiffness diagnosis's readings of the columns)
        if kind == "radians":
            out.append((f"q{joints[0] + 1} in radians", f"check q{joints[0] + 1}'s unit where the file was made", q))
        else:
            a, b = joints[0] + 1, joints[1] + 1
            out.append((f"q{a} and q{b} interchanged", "check the order of the joint columns", q))
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
