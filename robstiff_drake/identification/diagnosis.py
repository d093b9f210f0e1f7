"""Residual diagnosis of a stiffness campaign: which effect that the six-spring
model lacks explains what it gets wrong.  Plain numpy + scipy; no Drake.

The base model is the identification's (joint compliances, linear).  Each
candidate in CANDIDATES adds parametric columns to the regressor: linear in
its parameters, or linearised at the base fit where it multiplies the
compliance.  For each candidate:

  * held-out error: k-fold cross-validation, grouped by pose when the file
    has a ``pose`` column (a pose's rows are never split between fitting and
    testing), RMS of all displacement components (mm);
  * a nested F-test against the current model (all data), and the change in
    BIC.

Forward selection adds the best candidate only when it is significant
(p < ALPHA, a strict level because ten candidates are tried each round) and
lowers the held-out RMS by at least MIN_GAIN; it repeats until nothing
qualifies.  A candidate whose columns the data cannot separate from the
model's (rank) is reported as not identifiable and never selected; one with
more parameters than the data support is skipped, with the reason.
"""

from dataclasses import dataclass, field

import numpy as np
from scipy import stats

from robstiff_drake.identification.joint_stiffness import identify, regressor
from robstiff_drake.model import kinematics as kin

ALPHA = 1e-4
MIN_GAIN = 0.10  # held-out RMS must fall by at least 10 % of the current value
K_FOLDS = 5
MAX_EFFECTS = 3
TAU_REF_NM = 1000.0


@dataclass
class Columns:
    """A candidate's regressor columns (3N, p), in metres per parameter, with
    the parameters' names and units for the report."""

    name: str
    X: np.ndarray
    params: list  # [(name, unit, scale to the unit)]


@dataclass
class CandidateResult:
    name: str
    status: str  # "ok", "not identifiable", "skipped"
    reason: str = ""
    rms_mm: float = float("nan")  # held out, with the candidate added to the current model
    f_stat: float = float("nan")
    p_value: float = float("nan")
    delta_bic: float = float("nan")
    params: dict = field(default_factory=dict)


@dataclass
class Diagnosis:
    rms_before_mm: float
    rms_after_mm: float
    rms_fit_before_mm: float
    selected: list
    rounds: list  # per round, the list of CandidateResult
    joint_stiffness_Nm_per_rad: np.ndarray
    identifiable: np.ndarray
    final_params: dict
    residual_before_mm: np.ndarray  # (N, 3) base model, all data
    residual_after_mm: np.ndarray
    columns: dict  # name -> Columns (for the residual views)
    base_X: np.ndarray = None  # the six-spring model's columns (free joints), (3N, p)


class CampaignContext:
    """What the candidates need, computed once."""

    def __init__(self, robot, campaign, tool_m, base_fit, compliance=None):
        self.robot = robot
        self.campaign = campaign
        self.tool = np.zeros(3) if tool_m is None else np.asarray(tool_m, dtype=float)
        self.q = robot.joint_rad(campaign.q_deg)
        self.W = campaign.wrench
        self.J = kin.jacobian(robot.dh, self.q, self.tool)
        self.Jv = self.J[:, :3, :]
        self.tau = np.einsum("nrj,nr->nj", self.J, self.W)
        # the base fit's compliances (nominal where not identifiable), unless given
        self.c = base_fit.compliance_rad_per_Nm if compliance is None else compliance
        self.n = len(campaign)

    def disp_of_wrench(self, W, tool=None, c=None):
        """Conventional-model displacement (N, 3) in m of wrenches W (N, 6)."""
        J = self.J if tool is None else kin.jacobian(self.robot.dh, self.q, tool)
        tau = np.einsum("nrj,nr->nj", J, W)
        return np.einsum("nrj,nj->nr", J[:, :3, :], tau * (self.c if c is None else c))

    def from_dq(self, dq):
        return np.einsum("nrj,nj->nr", self.Jv, dq)


def _stack(cols):
    """List of (N, 3) arrays -> (3N, p)."""
    return np.column_stack([c.reshape(-1) for c in cols])


def _lost_motion(ctx):
    cols = [ctx.from_dq(np.eye(6)[j] * np.sign(ctx.tau)) for j in range(3)]
    return Columns("lost_motion", _stack(cols), [(f"b{j + 1}", "urad", 1e6) for j in range(3)])


def _joint_coupling(ctx):
    dq = np.zeros_like(ctx.tau)
    dq[:, 1], dq[:, 2] = ctx.tau[:, 2], ctx.tau[:, 1]
    return Columns("joint_coupling", _stack([ctx.from_dq(dq)]), [("c23", "rad/(N*m)", 1.0)])


def _load_dependent(ctx):
    cols = []
    for j in range(3):
        dq = np.zeros_like(ctx.tau)
        dq[:, j] = np.abs(ctx.tau[:, j]) * ctx.tau[:, j] / TAU_REF_NM
        cols.append(ctx.from_dq(dq))
    return Columns("load_dependent_stiffness", _stack(cols),
                   [(f"dc{j + 1}_per_kNm", "rad/(N*m) per kN*m", 1.0) for j in range(3)])


def _posture_dependent(ctx):
    dq = np.zeros_like(ctx.tau)
    dq[:, 1] = (ctx.q[:, 1] - ctx.q[:, 1].mean()) * ctx.tau[:, 1]
    return Columns("posture_dependent_stiffness", _stack([ctx.from_dq(dq)]),
                   [("dc2_per_rad_q2", "rad/(N*m) per rad of q2", 1.0)])


def _geometric(ctx):
    Kg = kin.geometric_stiffness(ctx.robot.dh, ctx.q, ctx.W, ctx.tool)
    # (K - lambda Kg)^-1 tau ~ C tau + lambda C Kg C tau
    ctau = ctx.tau * ctx.c
    dq = ctx.c * np.einsum("nij,nj->ni", Kg, ctau)
    return Columns("geometric_stiffness", _stack([ctx.from_dq(dq)]), [("lambda", "-", 1.0)])


def _link(ctx):
    u = kin.frames(ctx.robot.dh, ctx.q)[:, 3, :3, 2]
    F = ctx.W[:, :3]
    F_perp = F - np.sum(F * u, axis=1, keepdims=True) * u
    return Columns("link_compliance", _stack([F_perp]), [("c_link", "um/N", 1e6)])


def _frame_rotation(ctx):
    cols = []
    for k in range(3):
        e = np.eye(3)[k]
        extra = np.hstack([np.cross(e, ctx.W[:, :3]), np.cross(e, ctx.W[:, 3:])])
        cols.append(ctx.disp_of_wrench(extra))
    return Columns("force_frame_rotation", _stack(cols), [(f"phi_{a}", "mrad", 1e3) for a in "xyz"])


def _force_bias(ctx):
    cols = []
    for k in range(3):
        extra = np.zeros_like(ctx.W)
        extra[:, k] = 1.0
        cols.append(ctx.disp_of_wrench(extra))
    return Columns("force_bias", _stack(cols), [(f"b_f{a}", "N", 1.0) for a in "xyz"])


def _tool_offset(ctx, h=1e-3):
    cols = []
    for k in range(3):
        e = np.eye(3)[k] * h
        cols.append((ctx.disp_of_wrench(ctx.W, ctx.tool + e) - ctx.disp_of_wrench(ctx.W, ctx.tool - e)) / (2 * h))
    return Columns("tool_offset", _stack(cols), [(f"d_{a}", "mm", 1e3) for a in "xyz"])


def _drift(ctx):
    seq = ctx.campaign.seq
    cols = []
    for k in range(3):
        c = np.zeros((ctx.n, 3))
        c[:, k] = seq  # offset = v * seq: zero at the start of the campaign
        cols.append(c)
    return Columns("drift", _stack(cols), [(f"v_{a}", "um per measurement", 1e6) for a in "xyz"])


CANDIDATES = {
    "lost_motion": _lost_motion,
    "joint_coupling": _joint_coupling,
    "load_dependent_stiffness": _load_dependent,
    "posture_dependent_stiffness": _posture_dependent,
    "geometric_stiffness": _geometric,
    "link_compliance": _link,
    "force_frame_rotation": _frame_rotation,
    "force_bias": _force_bias,
    "tool_offset": _tool_offset,
    "drift": _drift,
}


def folds(campaign, k=K_FOLDS, seed=0):
    """Row indices of k test folds; a pose's rows stay together."""
    groups = np.asarray(campaign.pose) if campaign.pose is not None else np.arange(len(campaign)).astype(str)
    uniq = np.unique(groups)
    rng = np.random.default_rng(seed)
    order = rng.permutation(len(uniq))
    k = min(k, len(uniq))
    out = []
    for f in range(k):
        members = set(uniq[order[f::k]])
        out.append(np.flatnonzero([g in members for g in groups]))
    return out


class Design:
    """The base regressor (free joints, nominal-scaled) and the target."""

    def __init__(self, robot, campaign, tool_m, base_fit):
        A_d, _ = regressor(robot.dh, robot.joint_rad(campaign.q_deg), campaign.wrench, tool_m)
        c_nom = 1.0 / robot.joint_stiffness_Nm_per_rad
        A = (A_d * c_nom).reshape(-1, 6)
        self.free = np.flatnonzero(base_fit.identifiable)
        fixed = np.flatnonzero(~base_fit.identifiable)
        self.b = campaign.disp_mm.reshape(-1) * 1e-3 - A[:, fixed].sum(axis=1)  # fixed joints at nominal
        self.A = A[:, self.free]
        self.c_nom = c_nom
        self.n_rows = len(campaign)

    def rows_to_eq(self, rows):
        return (3 * rows[:, None] + np.arange(3)).ravel()


def _lstsq(X, y):
    scale = np.linalg.norm(X, axis=0)
    scale[scale == 0] = 1.0
    theta, *_ = np.linalg.lstsq(X / scale, y, rcond=None)
    return theta / scale


def _rank_ok(X_base, X_new, tol=1e-8):
    """Do X_new's columns add rank to X_base's (nominal-scaled, unit columns)?"""
    Xb = X_base / np.maximum(np.linalg.norm(X_base, axis=0), 1e-300)
    Xn = X_new / np.maximum(np.linalg.norm(X_new, axis=0), 1e-300)
    s_b = np.linalg.svd(Xb, compute_uv=False)
    s = np.linalg.svd(np.hstack([Xb, Xn]), compute_uv=False)
    rank_b = int(np.sum(s_b > tol * s_b[0]))
    rank = int(np.sum(s > tol * s[0]))
    return rank - rank_b == Xn.shape[1], rank - rank_b


def _relinearise_tool(robot, campaign, ctx, base, X_selected, tool_m, iterations=6):
    """Gauss-Newton on the tool offset: rebuild the base columns and the
    offset's own at the offset found so far, until it stops moving.  Returns
    (X, target, design, Columns with ``total`` = the whole offset)."""
    tool0 = ctx.tool.copy()
    tool = tool0.copy()
    c = ctx.c.copy()
    for _ in range(iterations):
        d = Design(robot, campaign, tool, base)
        cx = CampaignContext(robot, campaign, tool, base, compliance=c)
        C = _tool_offset(cx)
        X = np.hstack([d.A, X_selected, C.X])
        theta = _lstsq(X, d.b)
        c = c.copy()
        c[d.free] = theta[: len(d.free)] * d.c_nom[d.free]
        step = theta[-3:]
        tool = tool + step
        if np.max(np.abs(step)) < 1e-7:
            break
    d = Design(robot, campaign, tool, base)
    C = _tool_offset(CampaignContext(robot, campaign, tool, base, compliance=c))
    C.total = tool - tool0
    return np.hstack([d.A, X_selected, C.X]), d.b, d, C


def _relinearise_geometric(ctx, design, X, iterations=8):
    """Gauss-Newton on lambda of the CCT term: e(lambda) = J [(K - lambda K_g)^-1 - C] tau
    is nonlinear in lambda; linearise it where the fit lands.  Returns (X,
    target with e(lambda) taken out, design with that target, Columns with
    ``total`` = lambda)."""
    import copy

    Kg = kin.geometric_stiffness(ctx.robot.dh, ctx.q, ctx.W, ctx.tool)
    K = np.array([np.diag(1.0 / ctx.c)] * ctx.n)
    lam = 0.0

    def effect_and_slope(lam):
        Minv = np.linalg.inv(K - lam * Kg)
        dq = np.einsum("nij,nj->ni", Minv, ctx.tau)
        e = ctx.from_dq(dq - ctx.c * ctx.tau).reshape(-1)
        g = ctx.from_dq(np.einsum("nij,njk,nk->ni", Minv, Kg, dq)).reshape(-1)
        return e, g

    for _ in range(iterations):
        e, g = effect_and_slope(lam)
        theta = _lstsq(np.column_stack([X, g]), design.b - e + lam * g)
        step = theta[-1] - lam
        lam = theta[-1]
        if abs(step) < 1e-9 * max(1.0, abs(lam)):
            break
    e, g = effect_and_slope(lam)
    d = copy.copy(design)
    d.b = design.b - e  # the effect at lambda taken out; g's coefficient is what is left of lambda
    C = Columns("geometric_stiffness", g[:, None], [("lambda", "-", 1.0)])
    C.total = np.array([lam])
    return np.column_stack([X, g]), d.b, d, C


def held_out_rms_mm(design, X, fold_rows):
    """Held-out RMS (mm) of all components for regressor X (3N, p)."""
    sq, count = 0.0, 0
    all_rows = np.arange(design.n_rows)
    for test in fold_rows:
        train = np.setdiff1d(all_rows, test)
        tr, te = design.rows_to_eq(train), design.rows_to_eq(test)
        theta = _lstsq(X[tr], design.b[tr])
        r = design.b[te] - X[te] @ theta
        sq += float(r @ r)
        count += len(te)
    return float(np.sqrt(sq / count)) * 1e3


def _fit_stats(X, y):
    theta = _lstsq(X, y)
    r = y - X @ theta
    return theta, float(r @ r), r


def diagnose(robot, campaign, *, tool_m=None, candidates=None):
    """Forward selection of effects that explain the residual (see module docstring)."""
    base = identify(robot, campaign, tool_m=tool_m)
    ctx = CampaignContext(robot, campaign, tool_m, base)
    design = Design(robot, campaign, tool_m, base)
    fold_rows = folds(campaign)
    n_eq = 3 * len(campaign)
    names = list(candidates or CANDIDATES)
    cols = {}
    unavailable = {}
    for name in names:
        if name == "drift" and campaign.seq is None:
            unavailable[name] = ("skipped", "the file has no seq column (measurement order)")
            continue
        cols[name] = CANDIDATES[name](ctx)

    X = design.A
    current_rms = held_out_rms_mm(design, X, fold_rows)
    rms_before = current_rms
    _, rss, r0 = _fit_stats(X, design.b)
    residual_before = r0.reshape(-1, 3) * 1e3
    selected, rounds, chosen = [], [], {}
    while len(selected) < MAX_EFFECTS:
        results = []
        p0 = X.shape[1]
        for name in names:
            if name in selected:
                continue
            if name in unavailable:
                results.append(CandidateResult(name, *unavailable[name]))
                continue
            C = cols[name]
            p_e = C.X.shape[1]
            if n_eq - p0 - p_e < 3 * (p0 + p_e):
                results.append(CandidateResult(name, "skipped", f"{p_e} more parameters need more than the "
                                               f"{len(campaign)} measurements (3 equations each)"))
                continue
            ok, added = _rank_ok(X, C.X)
            if not ok:
                results.append(CandidateResult(name, "not identifiable",
                                               f"its {p_e} columns add only {added} independent direction(s) "
                                               "to the model's: the campaign cannot separate it"))
                continue
            X1, target, cand_design = np.hstack([X, C.X]), design.b, design
            if name == "tool_offset":  # nonlinear in the offset: re-linearise where it lands
                X1, target, cand_design, C = _relinearise_tool(robot, campaign, ctx, base, X[:, len(design.free):],
                                                               tool_m)
            elif name == "geometric_stiffness":  # (K - lambda K_g)^-1 is nonlinear in lambda
                X1, target, cand_design, C = _relinearise_geometric(ctx, design, X)
            theta, rss1, _ = _fit_stats(X1, target)
            df2 = n_eq - X1.shape[1]
            F = ((rss - rss1) / p_e) / (rss1 / df2) if rss1 > 0 else np.inf
            p = float(stats.f.sf(F, p_e, df2)) if np.isfinite(F) else 0.0
            dbic = n_eq * np.log(rss1 / rss) + p_e * np.log(n_eq)
            values = C.total if name in ("tool_offset", "geometric_stiffness") else theta[p0:]
            params = {f"{pn} ({unit})": float(v * s) for (pn, unit, s), v in zip(C.params, values)}
            res = CandidateResult(name, "ok", "", held_out_rms_mm(cand_design, X1, fold_rows), float(F), p,
                                  float(dbic), params)
            res.model = (X1, cand_design, values)  # what selecting it makes the current model
            results.append(res)
        rounds.append(results)
        qualified = [r for r in results if r.status == "ok" and r.p_value < ALPHA
                     and r.rms_mm <= (1 - MIN_GAIN) * current_rms]
        if not qualified:
            break
        best = min(qualified, key=lambda r: r.rms_mm)
        selected.append(best.name)
        chosen[best.name] = best.model
        X, design, _ = best.model
        current_rms = best.rms_mm
        _, rss, _ = _fit_stats(X, design.b)

    theta, _, r1 = _fit_stats(X, design.b)
    k = np.array(robot.joint_stiffness_Nm_per_rad, dtype=float)
    x_free = theta[: len(design.free)]
    k[design.free] = 1.0 / (x_free * design.c_nom[design.free])
    final_params, i = {}, len(design.free)
    for name in selected:
        C = cols[name]
        values = theta[i:i + len(C.params)]
        if name in ("tool_offset", "geometric_stiffness"):  # the re-linearisation point plus what is left at it
            values = np.asarray(chosen[name][2]) + values
        for (pn, unit, s), v in zip(C.params, values):
            final_params.setdefault(name, {})[f"{pn} ({unit})"] = float(v * s)
        i += len(C.params)
    return Diagnosis(rms_before_mm=rms_before, rms_after_mm=current_rms,
                     rms_fit_before_mm=float(np.sqrt(np.mean(r0**2))) * 1e3, selected=selected, rounds=rounds,
                     joint_stiffness_Nm_per_rad=k, identifiable=base.identifiable, final_params=final_params,
                     residual_before_mm=residual_before, residual_after_mm=r1.reshape(-1, 3) * 1e3, columns=cols,
                     base_X=Design(robot, campaign, tool_m, base).A)
