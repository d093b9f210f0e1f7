"""When can a stiffness campaign's confidence intervals be trusted?

The least-squares intervals (identification/stiffness/joint_stiffness.py) assume the
six-spring model is exact and the rows' errors independent.  A campaign's
design can make that assumption untestable, and then an interval is a
number without a meaning (a single pose gave k1 in [152k, 287k] N*m/rad
against a true 1.5e6):

* one pose: every row shares the pose's Jacobian, so a model error or a
  positioning error at that pose aliases into the stiffness unseen;
* one load direction (every wrench along one line): the rows cannot
  separate the joints' contributions beyond that line;
* no more poses than identified joints: the errors that are shared by the
  rows of a pose leave no degree of freedom to be estimated from;
* a tool point within MIN_TOOL_MM of the flange (but not at it): a length in
  metres; the torques are then 1000 times too small at the tool and the
  fit's stiffnesses wrong by a pattern no interval covers.

``interval_support`` returns the reasons (one phrase each; empty: the
intervals stand).  Plain numpy.
"""

import numpy as np

from robstiff_drake.model.robot_file import MIN_TOOL_MM

# Rows whose joint angles agree to this (deg) are one pose (a measurement
# program repeats a pose exactly; a controller reports to 1e-3 deg or so).
POSE_DECIMALS = 4
# Wrenches whose directions span one line to this relative singular value
# are one load direction.
ONE_LINE_REL = 1e-6


def count_poses(q_deg):
    """The number of distinct poses among rows of joint angles (deg)."""
    return len(np.unique(np.round(np.asarray(q_deg, dtype=float), POSE_DECIMALS), axis=0))


def tool_looks_like_metres(tool_m):
    """Whether a tool point (m) sits within MIN_TOOL_MM of the flange but
    not at it (a length written in metres into a mm field)."""
    d_mm = float(np.linalg.norm(tool_m)) * 1e3
    return 0.0 < d_mm < MIN_TOOL_MM


def one_load_line(wrench):
    """Whether every wrench (N, 6) is along one line (one load direction)."""
    W = np.asarray(wrench, dtype=float)
    W = W / np.maximum(np.linalg.norm(W, axis=1, keepdims=True), 1e-300)
    s = np.linalg.svd(W, compute_uv=False)
    return len(s) < 2 or s[1] <= ONE_LINE_REL * s[0]


def interval_support(campaign, tool_m, n_identified):
    """Why the campaign's intervals cannot be trusted (list of phrases;
    empty when they can).  ``n_identified``: joints the fit identified."""
    reasons = []
    if tool_looks_like_metres(tool_m):
        reasons.append(f"the tool point ({', '.join(f'{v * 1e3:g}' for v in tool_m)}) mm is "
                       f"{np.linalg.norm(tool_m) * 1e3:g} mm from the flange: a length in metres? (write mm)")
    poses = count_poses(campaign.q_deg)
    if poses == 1:
        reasons.append("every row is at one pose: a model or positioning error at that pose aliases into the "
                       "stiffness unseen; measure at several poses")
    elif poses <= n_identified:
        reasons.append(f"{poses} poses for {n_identified} identified joints: errors shared by a pose's rows leave "
                       "no degree of freedom to estimate them; measure at more poses than joints")
    if one_load_line(campaign.wrench):
        reasons.append("every load is along one line: the rows cannot separate the joints beyond it; load in "
                       "several directions")
    return reasons
