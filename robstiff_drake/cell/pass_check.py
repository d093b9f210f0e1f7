"""Did the simulated controller's arm travel the pass?  (`robstiff
sim-cell`'s health, commands/sim_cell.py.)

The controller counts answers: fresh, late, missing.  A compensator that
answers every message on time but with targets that do not travel the
path (the arm held at its start, a reference played at half speed by a
--period-ms that is not the controller's cycle, another reference file)
ends the pass part-way with every answer fresh, and sim-cell said "health
GOOD" (a compensator holding the start pose of tests/data/short_block.yaml:
1063 fresh answers, nothing cut, GOOD, exit 0).  Here the targets the arm
was commanded, engaged cycle by engaged cycle, are compared with the
path's reference at the station's time: a target further from it than a
correction can be is a pass the arm did not travel.
"""

import numpy as np

# How far (deg, the controller's joints) a commanded target may be from the path's reference at its time and still
# be the reference plus a correction.  ASSUMPTION: compensate clamps its correction at 0.5 deg a joint
# (--saturation-deg's default), mapped to the controller's joints (a parallelogram's coupled joint may carry two
# joints' clamps: 1 deg), and the answer lags the reference by the transport delay (a few periods at the path's
# speed: 0.03 deg on the short block); twice the coupled clamp.  A path that moves less than this in all is not
# judged by it.
FOLLOW_TOL_DEG = 2.0


def left_path(t_s, q_cmd_deg, t_ref_s, q_ref_deg, tol_deg=FOLLOW_TOL_DEG):
    """None when every commanded target (rows of ``q_cmd_deg``, applied from
    the station's times ``t_s``, s from engagement) is within ``tol_deg`` of
    the reference (rows ``q_ref_deg`` at ``t_ref_s``, held at its last row
    after its end) on every joint; else (the first such time s, how far deg,
    the joint index, the reference's time the target is nearest s): where
    the arm stopped travelling the pass."""
    q = np.asarray(q_cmd_deg, dtype=float).reshape(-1, 6)
    ref = np.asarray(q_ref_deg, dtype=float).reshape(-1, 6)
    tr = np.asarray(t_ref_s, dtype=float)
    if not len(q) or not len(ref):
        return None
    at = np.column_stack([np.interp(np.asarray(t_s, dtype=float), tr, ref[:, j]) for j in range(6)])
    dev = np.abs(q - at)
    off = np.flatnonzero(dev.max(axis=1) > tol_deg)
    if not len(off):
        return None
    i = int(off[0])
    j = int(np.argmax(dev[i]))
    nearest = float(tr[int(np.argmin(np.abs(ref - q[-1]).max(axis=1)))])
    return float(t_s[i]), float(dev[i, j]), j, nearest
