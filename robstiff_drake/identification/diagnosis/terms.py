"""Terms that extend the six-spring model, and fitting a model made of them.
Plain numpy; no Drake.

The six-spring model predicts the tool-point displacement d = J_v diag(c) J^T W,
linear in the compliances c.  A term adds displacement columns to it:

  * LINEAR: columns that depend on the campaign only (e.g. b_j sign(tau_j));
  * GRID: linear once a nonlinear shape parameter is chosen from a short grid
    (e.g. the transition torque of a backlash); the choice is made on the
    fitting rows, so inside cross-validation it is made afresh in each fold;
  * BILINEAR: linear in the term's parameters at given compliances (e.g. a
    measuring frame turned by phi rotates the springs' displacement); the
    columns are rebuilt at the compliances fitted on the fitting rows, and
    the fit is iterated until they settle;
  * GAUSS_NEWTON: nonlinear in the parameters (the tool offset, the CCT
    factor): linearised where the fit lands and iterated (Gauss-Newton).

``fit_model(ctx, terms, rows)`` fits the springs and the terms to the rows
given; every nonlinear choice is made from those rows only, so held-out
rows never inform their own prediction.
"""

from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from robstiff_drake.identification.diagnosis.cross_validation import pose_groups, rows_to_eq
from robstiff_drake.identification.stiffness.joint_stiffness import carrying_joints, regressor
from robstiff_drake.model import kinematics as kin

LINEAR, GRID, BILINEAR, GAUSS_NEWTON = "linear", "grid", "bilinear", "gauss-newton"
MAX_ITER = 8  # Gauss-Newton / bilinear iterations (they settle in 2-4)
REL_TOL = 1e-7


@dataclass
class Term:
    """One hypothesis: an effect the six springs lack.

    ``params``: [(name, unit, scale from SI to the unit)].  ``columns``:
    LINEAR ctx -> (3N, p); GRID (ctx, g) -> (3N, p); BILINEAR (ctx, c) ->
    (3N, p).  ``effect``: GAUSS_NEWTON (ctx, c, theta) -> (3N,) m, with
    ``step`` the finite-difference step of each parameter (SI).
    ``describe(values_SI, info) -> str`` names it in physical words;
    ``plausible(values_SI, info) -> (bool, reason)`` checks its size (see
    identification/diagnosis/plausibility.py).  ``needs``: why the term cannot be
    tried on this campaign (None if it can): ctx -> str | None."""

    name: str
    source: str  # "library" (named, `robstiff synth --effect`) or "dictionary"
    kind: str
    params: list
    columns: Callable = None
    grid: Callable = None  # GRID: ctx -> list of values (SI)
    grid_param: tuple = None  # GRID: (name, unit, scale) of the grid's parameter
    effect: Callable = None
    step: tuple = ()
    describe: Callable = None
    plausible: Callable = None
    needs: Callable = None
    trend: bool = False  # a trend along the file's order (no seq/t_s): reported as unexplained, never as a cause


class Context:
    """A campaign as the terms see it (SI units, base frame), computed once."""

    def __init__(self, robot, campaign, tool_m, identifiable, J=None, frames=None):
        """``J``, ``frames``: kinematics.jacobian and kinematics.frames at the campaign's angles (and ``tool_m``),
        when the caller has them."""
        self.robot = robot
        self.campaign = campaign
        self.tool = np.zeros(3) if tool_m is None else np.asarray(tool_m, dtype=float)
        self.q = robot.joint_rad(campaign.q_deg)
        self.W = campaign.wrench
        self.n = len(campaign)
        self.frames = kin.frames(robot.dh, self.q) if frames is None else frames
        self.J = kin.jacobian(robot.dh, self.q, self.tool, T=self.frames) if J is None else J
        self.Jv, self.Jw = self.J[:, :3, :], self.J[:, 3:, :]
        self.tau = np.einsum("nrj,nr->nj", self.J, self.W)
        self.tau[:, ~carrying_joints(self.tau)] = 0.0  # round-off torques carry nothing (no term is built on them)
        self.c_nom = 1.0 / np.asarray(robot.joint_stiffness_Nm_per_rad, dtype=float)
        self.p_tool = self.frames[:, 6, :3, 3] + self.frames[:, 6, :3, :3] @ self.tool
        self._groups = None  # (the groups property)
        self.seq = None if campaign.seq is None else np.asarray(campaign.seq, dtype=float)
        t_s = getattr(campaign, "t_s", None)
        self.t_s = None if t_s is None else np.asarray(t_s, dtype=float)
        A_d, _ = regressor(robot.dh, self.q, self.W, self.tool, J=self.J)
        A = (A_d * self.c_nom).reshape(-1, 6)
        self.identifiable = np.asarray(identifiable, dtype=bool)
        self.free = np.flatnonzero(self.identifiable)
        fixed = np.flatnonzero(~self.identifiable)
        self.A = A[:, self.free]
        self.b = campaign.disp_mm.reshape(-1) * 1e-3 - A[:, fixed].sum(axis=1)  # fixed joints at nominal
        self._cache = {}

    @property
    def groups(self):
        """(N,) pose group of each row (cross_validation.pose_groups), made when first asked for: the
        misreadings screen's Context of each reading of the file never asks (a sort of the campaign's rows)."""
        if self._groups is None:
            self._groups = pose_groups(self.campaign)
        return self._groups

    # -- helpers for the terms
    def cached(self, key, make):
        if key not in self._cache:
            self._cache[key] = make()
        return self._cache[key]

    def c_from(self, x_free):
        c = self.c_nom.copy()
        c[self.free] = np.asarray(x_free) * self.c_nom[self.free]
        return c

    def from_dq(self, dq):
        """Tool-point displacement (N, 3) m of joint deflections dq (N, 6)."""
        return np.einsum("nrj,nj->nr", self.Jv, dq)

    def rot_from_dq(self, dq):
        """Flange rotation (N, 3) rad of joint deflections dq (N, 6)."""
        return np.einsum("nrj,nj->nr", self.Jw, dq)

    def jacobian_moved(self, delta_m):
        """The Jacobian (N, 6, 6) at the tool point moved by delta_m (flange frame):
        the linear rows gain z_i x (R_6 delta) = -[R_6 delta]x z_i, the angular
        rows stay.  The last few are kept (a Gauss-Newton step asks for the
        same offset several times)."""
        key = tuple(np.round(np.asarray(delta_m, dtype=float), 15))
        memo = self._cache.setdefault("jacobian_moved", {})
        if key not in memo:
            s = np.einsum("nij,j->ni", self.frames[:, 6, :3, :3], np.asarray(delta_m, dtype=float))
            S = np.zeros((self.n, 3, 3))
            S[:, 0, 1], S[:, 0, 2], S[:, 1, 2] = -s[:, 2], s[:, 1], -s[:, 0]
            S[:, 1, 0], S[:, 2, 0], S[:, 2, 1] = s[:, 2], -s[:, 1], s[:, 0]
            if len(memo) >= 16:
                memo.pop(next(iter(memo)))
            memo[key] = np.concatenate([self.Jv - S @ self.Jw, self.Jw], axis=1)
        return memo[key]

    def disp_of_wrench(self, W, c, delta_m=None):
        """Six-spring displacement (N, 3) m of wrenches W (N, 6) at the tool
        point (moved by delta_m, flange frame, when given)."""
        J = self.J if delta_m is None else self.jacobian_moved(delta_m)
        tau = np.einsum("nrj,nr->nj", J, W)
        return np.einsum("nrj,nj->nr", J[:, :3, :], tau * c)


def stack(cols):
    """List of (N, 3) arrays -> (3N, p)."""
    return np.column_stack([np.asarray(c).reshape(-1) for c in cols])


def lstsq(X, y):
    """Least squares with columns scaled to unit norm (they differ by decades)."""
    scale = np.linalg.norm(X, axis=0)
    scale[scale == 0] = 1.0
    theta, *_ = np.linalg.lstsq(X / scale, y, rcond=None)
    return theta / scale


@dataclass
class ModelFit:
    """The springs plus terms fitted to some rows; columns and offset cover
    all rows, linearised where the fit landed, so ``predict`` works for any."""

    terms: list
    rows: np.ndarray
    X: np.ndarray  # (3N, p)
    offset: np.ndarray  # (3N,)
    coef: np.ndarray  # (p,)
    c: np.ndarray  # (6,) compliances, rad/(N*m)
    slices: dict  # term name -> slice of coef
    values: dict  # term name -> parameter values, SI
    grid: dict = field(default_factory=dict)  # GRID term name -> chosen value (SI)

    def predict(self, rows=None):
        if rows is None:
            return self.X @ self.coef + self.offset
        eq = rows_to_eq(rows)
        return self.X[eq] @ self.coef + self.offset[eq]


def term_columns(ctx, t, c, theta=None, g=None):
    """(Z, offset) of term t at compliances c (and GN parameters theta)."""
    if t.kind == LINEAR:
        return ctx.cached(("lin", t.name), lambda: np.asarray(t.columns(ctx), dtype=float)), 0.0
    if t.kind == GRID:
        return ctx.cached(("grid", t.name, float(g)), lambda: np.asarray(t.columns(ctx, g), dtype=float)), 0.0
    if t.kind == BILINEAR:
        return np.asarray(t.columns(ctx, c), dtype=float), 0.0
    G, f0, _ = gauss_newton_columns(ctx, t, c, theta)
    return G, f0 - G @ (np.zeros(len(t.params)) if theta is None else theta)


def gauss_newton_columns(ctx, t, c, theta):
    """Linearisation of a GAUSS_NEWTON term at (c, theta): (G = d effect / d theta,
    f0 = effect, Jc = d effect / d x), x the free joints' nominal-scaled
    compliances (the six springs' coefficients)."""
    theta = np.zeros(len(t.params)) if theta is None else np.asarray(theta, dtype=float)
    f0 = t.effect(ctx, c, theta)
    G = np.empty((f0.size, theta.size))
    for k, h in enumerate(t.step):
        e = np.zeros_like(theta)
        e[k] = h
        G[:, k] = (t.effect(ctx, c, theta + e) - t.effect(ctx, c, theta - e)) / (2 * h)
    Jc = np.empty((f0.size, len(ctx.free)))
    for i, j in enumerate(ctx.free):
        dc = np.zeros(6)
        dc[j] = 1e-3 * ctx.c_nom[j]
        Jc[:, i] = (t.effect(ctx, c + dc, theta) - f0) / 1e-3
    return G, f0, Jc


def _fit_fixed_grid(ctx, terms, rows, grid, max_iter=MAX_ITER):
    eq = rows_to_eq(rows)
    x = lstsq(ctx.A[eq], ctx.b[eq])
    c = ctx.c_from(x)
    if not terms:  # the six springs alone: the pass below would solve the same system again (X = A, no offset)
        return ModelFit([], np.asarray(rows), ctx.A, np.zeros(3 * ctx.n), x, c, {}, {}, dict(grid))
    theta = {t.name: np.zeros(len(t.params)) for t in terms if t.kind == GAUSS_NEWTON}
    iterative = any(t.kind in (BILINEAR, GAUSS_NEWTON) for t in terms)
    nf = len(ctx.free)
    for _ in range(max_iter if iterative else 1):
        base, blocks, offset, slices, i = ctx.A, [], np.zeros(3 * ctx.n), {}, nf
        for t in terms:
            if t.kind == GAUSS_NEWTON:  # full Gauss-Newton: the springs' columns move with it too
                Z, f0, Jc = gauss_newton_columns(ctx, t, c, theta[t.name])
                base = base + Jc
                off = f0 - Z @ theta[t.name] - Jc @ x
            else:
                Z, off = term_columns(ctx, t, c, None, grid.get(t.name))
            blocks.append(Z)
            offset = offset + off
            slices[t.name] = slice(i, i + Z.shape[1])
            i += Z.shape[1]
        X = np.hstack([base] + blocks)
        coef = lstsq(X[eq], ctx.b[eq] - offset[eq])
        x = coef[:nf]
        c_new = ctx.c_from(x)
        moved = np.max(np.abs(c_new - c) / np.abs(ctx.c_nom))
        for name in theta:
            new = coef[slices[name]]
            moved = max(moved, float(np.max(np.abs(new - theta[name]) / np.maximum(np.abs(new), 1e-6))))
            theta[name] = new
        c = c_new
        if moved < REL_TOL:
            break
    values = {t.name: coef[slices[t.name]] for t in terms}
    return ModelFit(list(terms), np.asarray(rows), X, offset, coef, c, slices, values, dict(grid))


def fit_model(ctx, terms, rows, grid=None, max_iter=MAX_ITER):
    """Fit the springs plus ``terms`` to ``rows`` (see module docstring).  A
    GRID term's value is taken from ``grid`` or chosen by the fit error on
    these rows (one coordinate pass, in the terms' order)."""
    grid = dict(grid or {})
    for t in terms:
        if t.kind == GRID and t.name not in grid:
            best = None
            for g in t.grid(ctx):
                trial = {**{u.name: u.grid(ctx)[0] for u in terms if u.kind == GRID}, **grid, t.name: g}
                f = _fit_fixed_grid(ctx, terms, rows, trial, max_iter)
                r = ctx.b[rows_to_eq(rows)] - f.predict(rows)
                sse = float(r @ r)
                if best is None or sse < best[0]:
                    best = (sse, g)
            grid[t.name] = best[1]
    return _fit_fixed_grid(ctx, terms, rows, grid, max_iter)


def held_out(ctx, terms, folds):
    """Held-out residual (3N,) m of the model over the folds' test rows (zero
    elsewhere), each fold fitted on its training rows only; and the fold fits.
    ``folds``: [(train rows, test rows)]."""
    resid = np.zeros(3 * ctx.n)
    fits = []
    for train, test in folds:
        f = fit_model(ctx, terms, train)
        eq = rows_to_eq(test)
        resid[eq] = ctx.b[eq] - f.predict(test)
        fits.append(f)
    return resid, fits


def rms_mm(resid):
    return float(np.sqrt(np.mean(resid**2))) * 1e3
