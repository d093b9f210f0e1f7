"""Joint-stiffness identification by least squares (the paper's Section 3, Eq. 8).

The conventional model is linear in the joint compliances c = 1/k:
    d_i = J_v(q_i) diag(c) J(q_i)^T W_i        (tool-point displacement)
    r_i = J_w(q_i) diag(c) J(q_i)^T W_i        (tool rotation, when measured)
so each measurement adds the rows A_i = J_v(q_i) diag(tau_i), tau_i = J^T W_i,
and c follows from stacked least squares.  Columns are scaled by the nominal
compliance (x_j = c_j / c_nom_j), so the condition number compares joints on
an equal footing.  Plain numpy + scipy; no Drake.
"""

from dataclasses import dataclass, field

import numpy as np
from scipy import optimize, stats

from robstiff_drake.errors import InputError
from robstiff_drake.identification.stiffness.interval_support import one_load_line
from robstiff_drake.model import kinematics as kin

# A joint whose (nominal-scaled) regressor column is below this fraction of
# the largest gets no torque from the campaign's loads: no information at all.
ZERO_COLUMN_REL = 1e-9
# A joint whose largest torque is below this fraction of the campaign's
# largest (any joint) carries none: what is left is round-off (8.7e-14 N*m on
# joint 6 with the tool on its axis against 1e3 N*m on joint 2), and no term
# (springs or the diagnosis's dictionary) is built on it.
TORQUE_REL_MIN = 1e-6


def carrying_joints(tau):
    """(6,) bool: the joints whose largest |torque| (tau (N, 6)) is at least
    TORQUE_REL_MIN of the campaign's largest."""
    tmax = np.max(np.abs(tau), axis=0) if len(tau) else np.zeros(6)
    return tmax > TORQUE_REL_MIN * max(float(tmax.max()), 1e-300)
# A joint whose column is nearly a combination of the others: variance
# inflation factor above this (sqrt: its standard error is amplified > 1000x).
MAX_VIF = 1e6
# A joint whose compliance the data pin down to worse than this relative
# standard error is reported as not identifiable (kept at nominal).
MAX_REL_STD = 0.5


@dataclass
class StiffnessFit:
    """The identified joint stiffness and what the data say about it."""

    stiffness_Nm_per_rad: np.ndarray  # (6,) identified, nominal where not identifiable
    stiffness_std_Nm_per_rad: np.ndarray  # (6,) NaN where not identifiable
    stiffness_ci95_Nm_per_rad: np.ndarray  # (6, 2); upper bound inf when c's interval reaches 0
    compliance_rad_per_Nm: np.ndarray
    compliance_std_rad_per_Nm: np.ndarray
    identifiable: np.ndarray  # (6,) bool
    reasons: list  # (6,) str: why a joint is not identifiable ("" if it is)
    non_physical: list  # 1-based joints with a negative identified compliance
    condition_number: float
    rms_residual_mm: float
    residuals_mm: np.ndarray  # (N, 3)
    residuals_rot_mrad: np.ndarray | None
    n_measurements: int
    dof: int
    sigma_mm: float
    sigma_rot_mrad: float | None
    robust: bool
    outlier_rows: list = field(default_factory=list)
    predicted_mm: np.ndarray | None = None
    input_warnings: list = field(default_factory=list)  # what the data look like (a unit mix), one line each


def regressor(dh, q_rad, wrench, tool_m=None, J=None):
    """Per-measurement regressor blocks: (A_d, A_r), each (N, 3, 6), with
    d = A_d @ c (m) and r = A_r @ c (rad) for compliances c (rad/(N*m)).
    ``J``: the tool point's Jacobians (N, 6, 6) at ``q_rad``, when the caller
    has them (they are the same whatever the loads)."""
    J = kin.jacobian(dh, q_rad, tool_m) if J is None else J  # (N, 6, 6)
    tau = np.einsum("nrj,nr->nj", J, wrench)  # (N, 6)
    A = J * tau[:, None, :]
    return A[:, :3, :], A[:, 3:, :]


def check_displacement_units(campaign, predicted_nominal_mm):
    """Refuse displacements that look like metres or micrometres: compare the
    measured magnitudes with what the nominal model predicts for these loads."""
    meas = np.linalg.norm(campaign.disp_mm, axis=1)
    pred = np.linalg.norm(predicted_nominal_mm, axis=1)
    use = pred > 1e-6 * max(pred.max(), 1e-300)
    if not np.any(use) or np.median(meas[use]) == 0:
        return
    ratio = np.median(meas[use]) / np.median(pred[use])
    said = (f"median |d| = {np.median(meas[use]):.3g}, the nominal model predicts {np.median(pred[use]):.3g} mm for "
            "these loads")
    # the ratio is of displacement per force: a force unit off by the same factor looks the same (kN written in the
    # N columns is 1000x; lbf 4.45x, within what a real arm's stiffness spreads, so not caught here)
    f_med = float(np.median(np.linalg.norm(campaign.force_N[use], axis=1)))
    if ratio < 0.02:
        raise InputError(f"{campaign.path}: displacements dx,dy,dz look like metres, not mm, or fx,fy,fz are "
                         f"{1 / ratio:.3g}x too large (median |F| = {f_med:.3g} N): {said} (the readings are "
                         f"1/{1 / ratio:.3g} of that); check the units of dx,dy,dz (the file holds mm) and of "
                         "fx,fy,fz (N)")
    if ratio > 50:
        # about 1000x: a reading in mm taken for metres somewhere before the file, then written in mm; or forces in kN
        # written in the N columns (the same ratio of displacement to force)
        what = "millimetres read as metres (or micrometres)" if 300 <= ratio <= 3000 else "micrometres"
        kn = " (forces in kN written as N give 1000x)" if 300 <= ratio <= 3000 else ""
        raise InputError(f"{campaign.path}: displacements dx,dy,dz look like {what}, not mm, or fx,fy,fz are "
                         f"{ratio:.3g}x too small{kn}, median |F| = {f_med:.3g} N: {said} (the readings are "
                         f"{ratio:.3g}x that); check the units of dx,dy,dz (the file holds mm) and of fx,fy,fz (N)")


# Rows whose measured displacement per predicted one sits this many decades
# apart from the other rows' (a gap in the sorted ratios; noise spreads them by
# well under one) are in another unit: forces in kN among N, or mm among um.
UNIT_GAP_DECADES = 1.5
UNIT_GROUP_MIN = 3  # rows on each side of the gap (and 5 % of the rows)


def unit_mix_warning(campaign, predicted_nominal_mm):
    """A warning (one line) when the rows fall into two groups whose
    measured displacement per nominal prediction differ by more than
    UNIT_GAP_DECADES decades (half the rows with forces in kN, say), or
    None."""
    meas = np.linalg.norm(campaign.disp_mm, axis=1)
    pred = np.linalg.norm(predicted_nominal_mm, axis=1)
    use = np.flatnonzero((pred > 1e-6 * max(pred.max(), 1e-300)) & (meas > 0))
    if len(use) < 2 * UNIT_GROUP_MIN:
        return None
    r = np.log10(meas[use] / pred[use])
    order = np.argsort(r)
    gaps = np.diff(r[order])
    k = int(np.argmax(gaps))
    low, high = order[: k + 1], order[k + 1:]
    need = max(UNIT_GROUP_MIN, int(np.ceil(0.05 * len(use))))
    if gaps[k] < UNIT_GAP_DECADES or len(low) < need or len(high) < need:
        return None
    factor = 10 ** (np.median(r[high]) - np.median(r[low]))
    few = high if len(high) <= len(low) else low
    lines = sorted(int(campaign.lines[use[i]]) if hasattr(campaign, "lines") else int(use[i]) + 1 for i in few)
    shown = ", ".join(map(str, lines[:6])) + (f" and {len(lines) - 6} more" if len(lines) > 6 else "")
    return (f"{campaign.path}: a unit mix? {len(high)} rows move {factor:.3g} x more per predicted displacement than "
            f"the other {len(low)} (lines {shown}): forces in kN among N (or displacements in um among mm); the fit "
            "mixes them; write every row in one unit")


# A file whose angles all lie within +-2 pi (a wrist joint's range in
# radians: FANUC's J6 of a real R-2000iC campaign reaches 4.15 rad) is
# tested as radians too: if the six springs fit it this many times better
# so, the angles are radians.
RADIANS_FIT_FACTOR = 3.0
# ... or this many times better, with every compliance positive read as
# radians and some negative read as degrees: a real campaign's model error
# keeps the radians fit's advantage small (that R-2000iC campaign: 0.215 mm
# as radians, 0.374 mm as degrees, with joints 3 and 6 negative).
RADIANS_FIT_FACTOR_NON_PHYSICAL = 1.5


def _linear_fit(robot, q_rad, campaign, tool_m):
    """(RMS residual mm, number of negative compliances) of the six springs fitted to ``campaign`` at ``q_rad``."""
    A_d, _ = regressor(robot.dh, q_rad, campaign.wrench, tool_m)
    A = (A_d / robot.joint_stiffness_Nm_per_rad).reshape(-1, 6)
    b = campaign.disp_mm.reshape(-1) * 1e-3
    x, *_ = np.linalg.lstsq(A, b, rcond=None)
    return float(np.sqrt(np.mean((b - A @ x) ** 2))) * 1e3, int(np.sum(x < 0))


def check_angle_units(robot, campaign, tool_m=None):
    """Refuse joint angles written in radians: when every angle lies within
    +-2 pi, fit the six springs to the file read both ways; radians that fit
    RADIANS_FIT_FACTOR times better, or RADIANS_FIT_FACTOR_NON_PHYSICAL
    times better where degrees need a negative compliance and radians do
    not, are what the file holds."""
    q = campaign.q_deg
    if np.max(np.abs(q)) > 2.0 * np.pi + 1e-9 or np.max(np.abs(q)) == 0:
        return
    # both readings through the robot file's controller map (signs, offsets, FANUC's J2/J3 coupling), as identify
    as_deg, negative_deg = _linear_fit(robot, robot.joint_rad(q), campaign, tool_m)
    as_rad, negative_rad = _linear_fit(robot, robot.joint_rad(np.rad2deg(q)), campaign, tool_m)
    physical = negative_deg > 0 and negative_rad == 0
    if as_rad * RADIANS_FIT_FACTOR < as_deg or (physical and as_rad * RADIANS_FIT_FACTOR_NON_PHYSICAL < as_deg):
        why = (f", and as degrees {negative_deg} joint compliance(s) turn negative, as radians none"
               if physical else "")
        raise InputError(f"{campaign.path}: joint angles q1..q6 look like radians, not degrees: every angle is within "
                         f"+-2 pi, and read as radians the six springs fit with {as_rad:.4f} mm RMS against "
                         f"{as_deg:.4f} mm as degrees{why}; write the controller's degrees (or name the unit in the "
                         "header: q1 [rad])")


def check_signs(fit, campaign):
    """Refuse a fit that needs a negative compliance for every identifiable
    joint: the displacements are the wrong way round (unloaded minus loaded,
    or a sign-flipped measurement frame).  Returns warnings (one line each)
    for some, not all, joints negative."""
    ident = np.flatnonzero(fit.identifiable)
    neg = [j for j in ident if fit.compliance_rad_per_Nm[j] <= 0]
    if ident.size and len(neg) == ident.size:
        raise InputError(f"{campaign.path}: every identifiable joint needs a negative compliance: the displacements "
                         "dx,dy,dz look sign-flipped (they must be loaded minus unloaded, in the base frame, in the "
                         "direction the tool moved)")
    if neg and one_load_line(campaign.wrench):
        # one load direction cannot tell a joint's spring from the others' beyond it: a negative one is the
        # design's artefact (or the data's), never an identified stiffness
        ks = ", ".join(f"joint {j + 1} at {1.0 / fit.compliance_rad_per_Nm[j]:.3g} N*m/rad" for j in neg)
        raise InputError(f"{campaign.path}: every load (fx, fy, fz, and moments) is along one line and the fit "
                         f"needs a negative compliance for {ks}: a campaign with one load direction cannot separate "
                         "the joints; load in several directions (robstiff plan-poses)")
    return [f"joint {j + 1}: negative identified compliance (non-physical); the data or the model are wrong for this "
            "joint" for j in neg]


def _vif(A):
    """Variance inflation factor of each column of A (columns scaled to unit
    norm), from the SVD so that an exactly dependent set gives a huge value
    rather than round-off."""
    norms = np.linalg.norm(A, axis=0)
    An = A / np.where(norms > 0, norms, 1.0)
    _, s, vt = np.linalg.svd(An, full_matrices=False)
    s2 = np.maximum(s**2, 1e-300)
    return np.sum(vt.T**2 / s2, axis=1)


def _solve(A, b, robust):
    """Least squares (optionally Huber) -> x, covariance factor (A^T W A)^-1,
    residuals, residual variance, dof, IRLS weights."""
    n, p = A.shape
    x, *_ = np.linalg.lstsq(A, b, rcond=None)
    w = np.ones(n)
    if robust:
        r0 = A @ x - b
        scale = 1.4826 * np.median(np.abs(r0 - np.median(r0)))
        if scale > 0:
            f_scale = 1.345 * scale
            sol = optimize.least_squares(lambda z: A @ z - b, x, loss="huber", f_scale=f_scale, method="trf")
            x = sol.x
            r = A @ x - b
            w = np.minimum(1.0, f_scale / np.maximum(np.abs(r), 1e-300))
    r = A @ x - b
    dof = n - p
    s2 = float(np.sum(w * r * r) / dof) if dof > 0 else np.nan
    Aw = A * np.sqrt(w)[:, None]
    cov_factor = np.linalg.pinv(Aw.T @ Aw)
    return x, cov_factor, r, s2, dof, w


def identify(robot, campaign, *, tool_m=None, robust=False, use_rotations=True, J=None):
    """Identify the six joint stiffnesses from a StiffnessCampaign.  ``J``:
    the tool point's Jacobians (N, 6, 6) at the campaign's angles, when the
    caller has them (the diagnosis reads one file many ways)."""
    k_nom = robot.joint_stiffness_Nm_per_rad
    c_nom = 1.0 / k_nom
    q = robot.joint_rad(campaign.q_deg)
    W = campaign.wrench
    J = kin.jacobian(robot.dh, q, tool_m) if J is None else J
    A_d, A_r = regressor(robot.dh, q, W, tool_m, J=J)
    pred_nom_mm = (A_d @ c_nom) * 1e3
    mix = unit_mix_warning(campaign, pred_nom_mm)
    if mix is None:  # (a mix moves the median: the test of one unit would blame the displacements)
        check_displacement_units(campaign, pred_nom_mm)

    n = len(campaign)
    b_d = campaign.disp_mm.reshape(-1) * 1e-3  # m
    Ad = (A_d * c_nom).reshape(-1, 6)  # columns: nominal contribution (m)
    have_rot = use_rotations and campaign.rot_mrad is not None
    if have_rot:
        b_r = campaign.rot_mrad.reshape(-1) * 1e-3  # rad
        Ar = (A_r * c_nom).reshape(-1, 6)

    identifiable = np.ones(6, dtype=bool)
    reasons = [""] * 6

    def stacked(weights):
        if not have_rot:
            return Ad, b_d
        wd, wr = weights
        return np.vstack([Ad / wd, Ar / wr]), np.concatenate([b_d / wd, b_r / wr])

    # Weights: with rotations, each block by its own noise level, estimated
    # from a first fit (two blocks of different units cannot share one sigma).
    weights = (1.0, 1.0)
    colnorm = np.linalg.norm(stacked(weights)[0], axis=0)
    carries = carrying_joints(np.einsum("nrj,nr->nj", J, W))
    for j in range(6):
        if colnorm[j] <= ZERO_COLUMN_REL * colnorm.max() or not carries[j]:
            identifiable[j] = False
            reasons[j] = "the loads give this joint no torque (force on its axis)"

    for _ in range(2 * 6 + 1):  # each pass removes one joint or sets the weights
        A, b = stacked(weights)
        free = np.flatnonzero(identifiable)
        if free.size == 0:
            raise InputError(f"{campaign.path}: no joint can be identified from this campaign (too few poses or "
                             "load directions: every joint's column is uninformative or dependent on the others)")
        vif = _vif(A[:, free])
        worst = int(np.argmax(vif))
        if vif[worst] > MAX_VIF:
            j = free[worst]
            identifiable[j] = False
            reasons[j] = f"its column is nearly a combination of the others' (variance inflation {vif[worst]:.3g})"
            continue
        fixed = np.flatnonzero(~identifiable)
        b_free = b - A[:, fixed] @ np.ones(fixed.size)  # fixed joints at their nominal (x = 1)
        x, cov_factor, r, s2, dof, w = _solve(A[:, free], b_free, robust)
        if have_rot and weights == (1.0, 1.0):
            rd, rr = r[: 3 * n], r[3 * n:]
            weights = (max(np.sqrt(np.mean(rd**2)), 1e-12), max(np.sqrt(np.mean(rr**2)), 1e-12))
            continue
        std_x = np.sqrt(np.maximum(np.diag(cov_factor) * s2, 0.0)) if dof > 0 else np.full(free.size, np.nan)
        rel = np.where(x != 0, std_x / np.abs(x), np.inf)
        bad = [(rel[i], free[i]) for i in range(free.size) if rel[i] > MAX_REL_STD]
        if bad:
            relmax, j = max(bad)
            identifiable[j] = False
            reasons[j] = f"the data pin its compliance down only to +-{100 * relmax:.0f} % (1 sigma)"
            continue
        break
    else:
        raise InputError(f"{campaign.path}: identification did not settle")

    x_all = np.ones(6)
    x_all[free] = x
    std_all = np.full(6, np.nan)
    std_all[free] = std_x
    c = x_all * c_nom
    c_std = std_all * c_nom
    t = stats.t.ppf(0.975, dof) if dof > 0 else np.nan
    stiffness = np.where(identifiable, 1.0 / c, k_nom)
    k_std = np.where(identifiable, c_std / c**2, np.nan)
    ci = np.full((6, 2), np.nan)
    for j in np.flatnonzero(identifiable):
        lo_c, hi_c = c[j] - t * c_std[j], c[j] + t * c_std[j]
        ci[j] = [1.0 / hi_c if hi_c > 0 else -np.inf, 1.0 / lo_c if lo_c > 0 else np.inf]
    non_physical = [int(j) + 1 for j in np.flatnonzero(identifiable & (c <= 0))]

    predicted = (A_d @ c) * 1e3
    res_d = campaign.disp_mm - predicted
    res_r = (campaign.rot_mrad - (A_r @ c) * 1e3) if have_rot else None
    Afree = stacked(weights)[0][:, free]
    norms = np.linalg.norm(Afree, axis=0)
    cond = float(np.linalg.cond(Afree / norms)) if free.size else np.inf
    sigma_mm = float(np.sqrt(s2) * (weights[0] if have_rot else 1.0) * 1e3)
    outliers = []
    if robust:
        robust_sigma = 1.4826 * np.median(np.abs(res_d))
        outliers = [int(i) for i in np.flatnonzero(np.max(np.abs(res_d), axis=1) > 4 * robust_sigma)]
    return StiffnessFit(
        stiffness_Nm_per_rad=stiffness,
        stiffness_std_Nm_per_rad=k_std,
        stiffness_ci95_Nm_per_rad=ci,
        compliance_rad_per_Nm=c,
        compliance_std_rad_per_Nm=c_std,
        identifiable=identifiable,
        reasons=reasons,
        non_physical=non_physical,
        condition_number=cond,
        rms_residual_mm=float(np.sqrt(np.mean(res_d**2))),
        residuals_mm=res_d,
        residuals_rot_mrad=res_r,
        n_measurements=n,
        dof=int(dof),
        sigma_mm=sigma_mm,
        sigma_rot_mrad=float(np.sqrt(s2) * weights[1] * 1e3) if have_rot else None,
        robust=robust,
        outlier_rows=outliers,
        predicted_mm=predicted,
        input_warnings=[mix] if mix else [],
    )
