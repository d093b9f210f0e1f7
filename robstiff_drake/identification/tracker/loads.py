"""Tracker campaigns with applied loads (fx, fy, fz): every term of the
loaded diagnosis that describes how the arm answers a load (the named
library's and the dictionary's, identification/diagnosis/candidates.py, dictionary.py,
dictionary_loads.py) becomes a block of the tracker's search, its columns
the term's displacement under the applied loads at the robot file's
compliances (the rows without a load have none).  Terms about a
displacement measurement (its frame, its point, its offsets and drifts,
trends) are left out: a tracker campaign's registration, measured point and
drift blocks are those.  Plain numpy.
"""

import numpy as np

from robstiff_drake.identification.stiffness.campaign import StiffnessCampaign
from robstiff_drake.identification.diagnosis.candidates import CANDIDATES
from robstiff_drake.identification.diagnosis.dictionary import DICTIONARY
from robstiff_drake.identification.diagnosis.terms import GAUSS_NEWTON, GRID, Context, term_columns
from robstiff_drake.identification.tracker.terms import Block

# about the displacement measurement, not the arm's answer to a load: the tracker's own blocks cover them
NOT_A_LOAD_TERM = {"drift", "drift_quadratic", "drift_periodic", "drift_referenced", "displacement_offset",
                   "measured_point_offset", "measurement_frame_rotation", "order_trend", "order_periodic"}


def load_blocks(robot, campaign, tool_m):
    """[Block] of the loaded terms for a tracker campaign with applied loads."""
    if campaign.force_N is None:
        return []
    n = len(campaign)
    groups = None if campaign.pose is None else campaign.pose
    view = StiffnessCampaign(campaign.path, campaign.q_deg, campaign.force_N, np.zeros((n, 3)), np.zeros((n, 3)),
                             None, groups, campaign.seq, campaign.lines, [], False, t_s=campaign.t_s)
    ctx = Context(robot, view, tool_m, np.ones(6, dtype=bool))
    c = ctx.c_nom
    out = []
    for t in list(CANDIDATES.values()) + list(DICTIONARY.values()):
        if t.kind == GAUSS_NEWTON or t.name in NOT_A_LOAD_TERM or t.trend:
            continue
        if t.needs and t.needs(ctx):
            continue
        g = None
        if t.kind == GRID:
            grid = t.grid(ctx)
            g = grid[len(grid) // 2]
        Z = np.asarray(term_columns(ctx, t, c, None, g)[0], dtype=float).reshape(n, 3, -1)
        if not np.any(Z):
            continue
        info = {"ctx": ctx, "c": c, "g": g}
        out.append(Block(f"load:{t.name}", "base", list(t.params),
                         (lambda Z_: lambda ev: Z_[ev.rows])(Z),
                         (lambda t_, i_: lambda v, _info: t_.describe(v, i_) + " (under the applied loads)")(t, info),
                         (lambda t_, i_: lambda v, _info: t_.plausible(v, i_) if t_.plausible else (True, ""))(t, info)))
    return out
