"""Fitting the tracker model (identification/tracker/model.py) to an
absolute-position campaign: Gauss-Newton on the rows given, the linearised
cross-validation the search uses, and the rank test that decides which
parameters the campaign identifies.  Plain numpy; no Drake.

Memory is linear in the rows: the columns (3N x P) are the largest arrays,
and the search works on fold Gram matrices (P x P) once they are formed.
"""

from dataclasses import dataclass, field, replace

import numpy as np

from robstiff_drake.identification.tracker.model import (GEOM, cross, geometry_jacobian, gravity, jacobian_v,
                                                         perturbed_dh, tool_points)
from robstiff_drake.identification.tracker.terms import Eval
from robstiff_drake.model import kinematics as kin
from robstiff_drake.model.robot import GRAVITY_BASE_M_PER_S2

GN_ITER = 10
# fixed-point steps of the sag from the nominal pose's (the error shrinks by the sag's own relative size,
# about 3e-3, per step)
SAG_ITER = 1
GN_TOL = 1e-9  # relative step
POSE_CHUNK = 2000  # poses a step when LinearCV.fit sums each pose's scores (memory, not results)
RANK_TOL = 1e-3  # a column whose part outside the others' span is below this (unit norm) is not identifiable


def rodrigues(w):
    th = float(np.linalg.norm(w))
    if th < 1e-15:
        return np.eye(3)
    k = np.asarray(w) / th
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(th) * K + (1 - np.cos(th)) * K @ K


@dataclass
class Fit:
    """A fitted tracker model: registration (R, t m), measured point u (m,
    flange frame), geometric deltas (6, 5) SI and each block's coefficients."""

    R: np.ndarray
    t: np.ndarray
    u: np.ndarray
    geo: np.ndarray
    coef: dict = field(default_factory=dict)  # block name -> values (SI)
    blocks: list = field(default_factory=list)

    def copy(self):
        return replace(self, R=self.R.copy(), t=self.t.copy(), u=self.u.copy(), geo=self.geo.copy(),
                       coef={k: v.copy() for k, v in self.coef.items()}, blocks=list(self.blocks))


class Problem:
    """A campaign as the fit sees it: the model's angles, the weight's
    torques (robot file's masses, nominal chain), the clock and temperature,
    the measured points (m)."""

    def __init__(self, robot, q_deg, pos_m, *, force_N=None, t_s=None, temp_c=None, seq=None, tool_guess_m=None):
        self.robot = robot
        self.n = len(pos_m)
        self.m = np.asarray(pos_m, dtype=float)
        self.q = robot.joint_rad(q_deg)
        self.q_ctrl = np.deg2rad(np.asarray(q_deg, dtype=float))
        self.G = robot.joint_map.G
        self.c_nom = 1.0 / np.asarray(robot.joint_stiffness_Nm_per_rad, dtype=float)
        self.force, self.tool_guess = force_N, tool_guess_m
        self.sag = True  # the robot file's masses and stiffness are part of the declared model
        self.set_gravity(None)
        self.t_h = None if t_s is None else (np.asarray(t_s) - np.mean(t_s)) / 3600.0
        self.dtemp = None if temp_c is None else np.asarray(temp_c) - np.mean(temp_c)
        self.seq = None if seq is None else (np.asarray(seq, float) - np.mean(seq)) / 1000.0
        self.order = (np.arange(self.n) - (self.n - 1) / 2.0) / 1000.0
        self.geo_free = []

    def set_gravity(self, g_base):
        """Gravity in the base frame (None: the base's -z); the weight's torques at the nominal chain."""
        self.g_base = g_base
        # the nominal chain's frames (N x 7 x 4 x 4) are made here and freed, not kept (90 MB at 100,000 rows)
        self.tau, self.moment = gravity(self.robot, kin.frames(self.robot.dh, self.q, rows=3), self.q, self.force,
                                        self.tool_guess, g_base)

    def evaluate(self, fit, rows):
        """The Eval of rows ``rows`` at the fit's geometry and measured point,
        the joints sagged under the weight when the fit has compliances (a
        fixed point of dq = x c tau(q + dq), SAG_ITER steps)."""
        dh = perturbed_dh(self.robot.dh, fit.geo)
        q = self.q[rows]
        tau, moment = self.tau[rows], self.moment[rows]
        sag = next((b for b in fit.blocks if b.frame == "joint"), None)
        x = np.ones(6)  # the declared model sags with the robot file's compliances
        if sag is not None:
            x[sag.joints] = fit.coef[sag.name]
        if self.sag:
            dq = tau * (x * self.c_nom)
            for _ in range(SAG_ITER):
                T = kin.frames(dh, q + dq, rows=3)
                tau, moment = gravity(self.robot, T, q + dq, None if self.force is None else self.force[rows],
                                      self.tool_guess, self.g_base)
                dq = tau * (x * self.c_nom)
                T = None  # (freed before the next frames are made)
            q = q + dq
        T = kin.frames(dh, q, rows=3)  # (rotations and origins only: what the fit reads)
        p = tool_points(T, fit.u)

        def sub(x):
            return None if x is None else x[rows]

        return Eval(T=T, p=p, Jv=jacobian_v(T, p), tau=tau, moment=moment,
                    q_ctrl_rad=self.q_ctrl[rows], G=self.G, c_nom=self.c_nom, t_h=sub(self.t_h),
                    dtemp=sub(self.dtemp), seq=sub(self.seq), order=self.order[rows], geo_free=self.geo_free,
                    rows=np.asarray(rows), q_rad=q, robot=self.robot, c_sag=x * self.c_nom,
                    g_base=np.asarray(GRAVITY_BASE_M_PER_S2 if self.g_base is None else self.g_base, float)), dh

    def parts(self, fit, ev):
        """(R (p + dp), dm): the arm's point in the instrument's axes and the
        instrument-frame displacement, (n, 3) m each."""
        dp = np.zeros_like(ev.p)
        dm = np.zeros_like(ev.p)
        for b in fit.blocks:
            if b.frame in ("geometry", "joint"):
                continue
            d = np.einsum("nrk,k->nr", b.columns(ev), fit.coef[b.name])
            if b.frame == "base":
                dp += d
            else:
                dm += d
        return (ev.p + dp) @ fit.R.T, dm

    def predict(self, fit, rows, ev=None):
        """(n, 3) m: the model's measured points at rows."""
        if ev is None:
            ev, _ = self.evaluate(fit, rows)
        arm, dm = self.parts(fit, ev)
        return arm + fit.t + dm

    def columns(self, fit, blocks, rows, at=None, cache=None):
        """(3n, P) derivatives of the prediction at ``rows``: registration
        rotation (3), translation (3), measured point (3), then each block's
        parameters; and {name: slice}.  ``at``: ``evaluate(fit, rows)``'s
        result when the caller has it (the same fit and rows); ``cache``: a
        dict kept between calls with the same ``at`` (the geometry's
        Jacobian is computed once)."""
        ev, dh = self.evaluate(fit, rows) if at is None else at
        v, _ = self.parts(fit, ev)  # R (p + dp): what the registration's rotation turns
        R6 = ev.T[:, 6, :3, :3]
        slices, i = {"registration_rotation": slice(0, 3), "registration_translation": slice(3, 6),
                     "measured_point": slice(6, 9)}, 9
        Jg = None
        for b in blocks:
            if b.frame == "geometry":
                if Jg is None:
                    Jg = cache.get("Jg") if cache is not None else None
                    if Jg is None:
                        Jg = geometry_jacobian(ev.T, ev.p, dh)
                    if cache is not None:
                        cache["Jg"] = Jg
                width = len(b.geo)
            else:
                width = len(b.params)
            slices[b.name] = slice(i, i + width)
            i += width
        # one (n, 3, P) array written block by block (no list of blocks concatenated into a second copy)
        X = np.empty((len(v), 3, i))
        for k in range(3):
            X[:, :, k] = cross(np.eye(3)[k], v)
            X[:, :, 3 + k] = np.eye(3)[k]
            X[:, :, 6 + k] = R6[:, :, k] @ fit.R.T
        for b in blocks:  # each block's (n, 3, width) columns, made when written
            sl = slices[b.name]
            if b.frame == "geometry":
                Z = np.stack([Jg[:, :, k, GEOM.index(kind)] for k, kind in b.geo], axis=-1)
                X[:, :, sl] = np.einsum("ij,njp->nip", fit.R, Z)
            elif b.frame in ("base", "joint"):
                X[:, :, sl] = np.einsum("ij,njp->nip", fit.R, b.columns(ev))
            else:
                X[:, :, sl] = b.columns(ev)
        return X.reshape(-1, X.shape[-1]), slices, ev

    def apply(self, fit, blocks, delta, slices):
        """The fit moved by a Gauss-Newton step ``delta`` (SI)."""
        new = fit.copy()
        new.R = rodrigues(delta[slices["registration_rotation"]]) @ fit.R
        new.t = fit.t + delta[slices["registration_translation"]]
        new.u = fit.u + delta[slices["measured_point"]]
        for b in blocks:
            d = delta[slices[b.name]]
            if b.frame == "geometry":
                for (k, kind), x in zip(b.geo, d):
                    new.geo[k, GEOM.index(kind)] += x
            else:
                new.coef[b.name] = new.coef.get(b.name, np.full(len(b.params), b.start)) + d
        new.blocks = list(blocks)
        return new

    def gauss_newton(self, fit, blocks, rows, iterations=GN_ITER):
        """Fit ``blocks`` (and the registration and measured point) to rows,
        from ``fit``; blocks not in ``blocks`` are dropped (geometry zeroed)."""
        fit = fit.copy()
        keep_geo = {(k, kind) for b in blocks if b.frame == "geometry" for k, kind in b.geo}
        for k in range(6):
            for j, kind in enumerate(GEOM):
                if (k, kind) not in keep_geo:
                    fit.geo[k, j] = 0.0
        fit.coef = {b.name: fit.coef.get(b.name, np.full(len(b.params), b.start)) for b in blocks
                    if b.frame != "geometry"}
        fit.blocks = list(blocks)
        for _ in range(iterations):
            X, slices, ev = self.columns(fit, blocks, rows)
            r = (self.m[rows] - self.predict(fit, rows, ev)).reshape(-1)
            step = normal_solve(X, r)
            fit = self.apply(fit, blocks, step, slices)
            if np.linalg.norm(X @ step) < GN_TOL * max(np.linalg.norm(r), 1e-12):
                break
        return fit


def normal_solve(X, r):
    """Least squares of r on X's columns through the normal equations of the
    unit-normed columns (a P x P solve; X^T X costs O(N P^2) in BLAS, far
    less than an SVD of X), a tiny ridge against exact rank loss."""
    scale = np.linalg.norm(X, axis=0)
    scale[scale == 0] = 1.0
    # X^T X and X^T r of the unscaled columns, then scaled (no scaled copy of X)
    A = (X.T @ X) / np.outer(scale, scale)
    A[np.diag_indices_from(A)] += 1e-12 * len(A)
    try:
        step = np.linalg.solve(A, (X.T @ r) / scale)
    except np.linalg.LinAlgError:
        step = np.linalg.lstsq(X / scale, r, rcond=None)[0]
    return step / scale


def rows_to_eq(rows):
    rows = np.asarray(rows)
    return (3 * rows[:, None] + np.arange(3)).ravel()


def independent_columns(X, preferred):
    """Greedy rank test: of X's columns (unit-normed), in the order
    ``preferred`` (indices), those whose part outside the span of the ones
    kept before them is at least RANK_TOL.  Returns the kept indices."""
    Xs = X / np.maximum(np.linalg.norm(X, axis=0), 1e-300)
    Gm = Xs.T @ Xs
    kept = []
    L = np.zeros((0, 0))
    for c in preferred:
        g = Gm[kept, c] if kept else np.zeros(0)
        w = np.linalg.solve(L, g) if kept else g
        rest = Gm[c, c] - float(w @ w)
        if rest >= RANK_TOL**2:
            n = len(kept)
            L2 = np.zeros((n + 1, n + 1))
            L2[:n, :n] = L
            L2[n, :n] = w
            L2[n, n] = np.sqrt(rest)
            L, kept = L2, kept + [c]
    return kept


class LinearCV:
    """Held-out errors of linear models on columns X (3N, P) and target r,
    from fold Gram matrices: a subset of columns costs O(K P^3), whatever N.
    ``tests``: equation indices of each fold's test rows."""

    def __init__(self, X, r, tests, groups_eq, copy=True):
        """``copy=False``: X is the caller's to give away (scaled in place:
        no second 3N x P array)."""
        self.scale = np.linalg.norm(X, axis=0)
        self.scale[self.scale == 0] = 1.0
        if copy:
            self.Xs = X / self.scale
        else:
            self.Xs = X
            self.Xs /= self.scale
        self.r = r
        self.tests = tests
        self.Gh, self.bh = [], []
        for te in tests:  # each fold's rows copied once (all the rows in order: none)
            Xt = self.Xs if len(te) == len(r) and np.array_equal(te, np.arange(len(r))) else self.Xs[te]
            self.Gh.append(Xt.T @ Xt)
            self.bh.append(Xt.T @ r[te])
            Xt = None
        self.rrh = [float(r[te] @ r[te]) for te in tests]
        self.Gm, self.b = sum(self.Gh), sum(self.bh)
        self.n_eq = sum(len(te) for te in tests)
        self.order = np.argsort(groups_eq, kind="stable")
        g = groups_eq[self.order]
        self.starts = np.r_[0, np.flatnonzero(np.diff(g)) + 1]

    @staticmethod
    def _solve(A, y):
        try:
            return np.linalg.solve(A + 1e-12 * np.trace(A) / len(A) * np.eye(len(A)), y)
        except np.linalg.LinAlgError:
            return np.linalg.pinv(A) @ y

    def heldout_rms(self, cols):
        cols = np.asarray(cols)
        sse = 0.0
        for Gh, bh, rr in zip(self.Gh, self.bh, self.rrh):
            A = (self.Gm - Gh)[np.ix_(cols, cols)]
            d = self._solve(A, (self.b - bh)[cols])
            sse += rr - 2 * d @ bh[cols] + d @ Gh[np.ix_(cols, cols)] @ d
        return float(np.sqrt(max(sse, 0.0) / self.n_eq))

    def fit(self, cols):
        """(coefficients SI, clustered covariance SI, clusters) of the fit on all rows."""
        cols = np.asarray(cols)
        A = self.Gm[np.ix_(cols, cols)]
        d = self._solve(A, self.b[cols])
        Xc = self.Xs if np.array_equal(cols, np.arange(self.Xs.shape[1])) else self.Xs[:, cols]
        e = self.r - Xc @ d
        U = np.empty((len(self.starts), Xc.shape[1]))  # per pose: the sum of its rows times their residuals
        ends = np.r_[self.starts[1:], len(self.order)]
        for g0 in range(0, len(self.starts), POSE_CHUNK):  # a chunk of poses at a time (no n x p copy)
            g1 = min(g0 + POSE_CHUNK, len(self.starts))
            take = self.order[self.starts[g0]:ends[g1 - 1]]
            W = Xc[take]
            W *= e[take][:, None]
            U[g0:g1] = np.add.reduceat(W, self.starts[g0:g1] - self.starts[g0], axis=0)
        W = Xc = None
        G = len(U)
        bread = np.linalg.pinv(A)
        cov = bread @ (U.T @ U) @ bread * (G / max(G - 1, 1))
        s = self.scale[cols]
        return d / s, cov / np.outer(s, s), G
