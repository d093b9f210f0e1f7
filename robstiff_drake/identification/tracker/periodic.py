"""Joint errors periodic in a joint's angle, of unknown period: reducer
stages and output encoders turn each joint's angle by an error that repeats
every P degrees of the controller's angle (a full turn for an eccentric
output bearing, 360/ratio for an input stage, 360/poles for an encoder), of
a few urad to a few mrad.  Plain numpy + scipy; no Drake.

    dJ(J) = s sin(2 pi J / P) + c cos(2 pi J / P)        (rad)

seen at the measured point through the arm's Jacobian (d = J_v G[:, J] dJ).

The search (``search``), on what the model leaves (base frame):
1. A periodogram per joint: for each period P on a grid from MIN_PERIOD_DEG
   to a full turn (uniform in cycles per turn, OVERSAMPLE points per peak
   width 360 / the joint's span), the least-squares reduction of the residual
   sum of squares by the two columns above (a Lomb-Scargle periodogram
   weighted by each pose's lever |J_v G[:, J]|^2, O(N) per period).
2. The highest peak over all joints, its period refined by a bounded
   scalar search between the grid's neighbours, its 95 % interval from the curvature of
   the sum of squares there (Delta SSE = chi2_1(0.95) sigma^2, sigma^2 from
   the residual); its false-alarm probability over the independent periods
   scanned (1 - (1 - p)^M, p the F test of the two columns).
3. It is kept when the false alarm is below ALPHA and, refitted with the
   terms found before and the model's own columns, it lowers the held-out
   (pose-grouped folds) RMS by MIN_STEP_GAIN; then its harmonics (P/2, P/3)
   are tried the same way (one period each: no search penalty).  Repeated
   until no peak passes or MAX_TERMS are found.
4. Each period is polished by the profile of the sum of squares with every
   other column refitted, its interval from that profile (``_polish``).

The terms found become one block per joint (``periodic_block``): the
diagnosis's search then judges them as a set with the rest of the model.
"""

import numpy as np
from scipy import stats

MIN_PERIOD_DEG = 3.0  # the finest reducer-stage or encoder period a tracker campaign resolves
OVERSAMPLE = 5
MIN_SPAN_DEG = 10.0
ALPHA = 1e-3  # false-alarm probability of a peak over all periods and joints scanned
MIN_STEP_GAIN = 0.005  # held-out RMS must drop by 0.5 % for a term to be kept
MAX_TERMS = 36
HARMONICS = (2, 3)
CHUNK = 64
# A typical size, not a bound: strain-wave and cycloidal reducers catalogue 0.3-1.5 mrad of angular
# transmission error, encoder eccentricity a few tenths; beyond 5 mrad the report says it is beyond typical
TYPICAL_MAX_RAD = 5e-3


def lever(Jv, G, J):
    """(N, 3): the measured point's motion per radian of controller angle J."""
    return np.einsum("nrj,j->nr", Jv, G[:, J])


MAX_BIN_RAD = 5e-4  # angles are binned this finely for the FFT (a phase error below 0.03 rad at the finest period)


def _layout(span_rad):
    """(K, L): the grid is f / K cycles per turn (OVERSAMPLE points per peak width 360 / span), the FFT's
    length L (a power of two) with bins of 2 pi K / L <= MAX_BIN_RAD rad."""
    K = max(int(np.ceil(OVERSAMPLE * span_rad / (2 * np.pi))), 1)
    L = 1 << int(np.ceil(np.log2(2 * np.pi * K / MAX_BIN_RAD)))
    return K, L


def periodogram(ang, L_, r, span_rad=None):
    """(cycles per turn (k,), Delta SSE (k,)): for each period from a full
    turn to MIN_PERIOD_DEG, the reduction of the residual's sum of squares by
    fitting s sin + c cos of ``ang`` (rad, (N,)) through the levers L_ (N, 3)
    to r (N, 3).  The sums over poses by one FFT of the angles binned
    (Delta SSE does not depend on the angle's origin)."""
    span = float(np.ptp(ang)) if span_rad is None else span_rad
    K, L = _layout(span)
    step = 2 * np.pi * K / L
    k = np.rint((ang - ang.min()) / step).astype(int)
    a = np.sum(L_ * r, axis=1)
    b = np.sum(L_ * L_, axis=1)
    f = np.arange(K, int(360.0 / MIN_PERIOD_DEG * K) + 1)
    FA = np.fft.rfft(np.bincount(k, a, L))[f]
    FB = np.fft.rfft(np.bincount(k, b, L))[2 * f]
    ca, sa = FA.real, -FA.imag
    sb = b.sum()
    cc, ss, cs = (sb + FB.real) / 2, (sb - FB.real) / 2, -FB.imag / 2
    det = cc * ss - cs * cs
    det = np.where(det > 1e-30 * sb * sb, det, np.inf)
    return f / K, (ss * ca * ca - 2 * cs * ca * sa + cc * sa * sa) / det


def reduction(ang, L_, r, nu):
    """Delta SSE at given cycles per turn ``nu`` (k,), by direct sums."""
    a = np.sum(L_ * r, axis=1)
    b = np.sum(L_ * L_, axis=1)
    out = []
    for v in np.atleast_1d(nu):
        c, s = np.cos(v * ang), np.sin(v * ang)
        ca, sa, cc, cs, ss = c @ a, s @ a, (c * c) @ b, (c * s) @ b, (s * s) @ b
        det = cc * ss - cs * cs
        out.append((ss * ca * ca - 2 * cs * ca * sa + cc * sa * sa) / det if det > 0 else 0.0)
    return np.array(out)


def columns(ang, L_, period_deg):
    """(N, 3, 2): the sin and cos columns of a period (rad of error)."""
    nu = 360.0 / period_deg
    return np.stack([L_ * np.sin(nu * ang)[:, None], L_ * np.cos(nu * ang)[:, None]], -1)


def _refine(ang, L_, r, nu, power, i):
    """The peak's cycles per turn (bounded scalar search of the exact Delta
    SSE between the grid's neighbours of point i) and the curvature of
    Delta SSE there (central difference), or None at the grid's ends."""
    from scipy.optimize import minimize_scalar

    if i == 0 or i == len(nu) - 1:
        return nu[i], None
    h = nu[1] - nu[0]
    res = minimize_scalar(lambda v: -reduction(ang, L_, r, [v])[0], bounds=(nu[i - 1], nu[i + 1]), method="bounded",
                          options={"xatol": 1e-4 * h})
    c = float(res.x)
    dh = h / 8
    y0, y1, y2 = reduction(ang, L_, r, [c - dh, c, c + dh])
    curv = (y0 - 2 * y1 + y2) / dh**2  # d2 (Delta SSE) / d nu2, negative at a peak
    return c, (-curv if curv < 0 else None)


class _Folds:
    """Pose-grouped K-fold held-out RMS of linear fits on the model's columns
    and those added (columns unit-normed; fold Gram matrices, so a candidate
    costs O(N P) whatever was added before)."""

    def __init__(self, X, r, tests):
        self.tests, self.r = tests, r
        self.Xf = [self._unit(X)[te] for te in tests]
        self.rf = [r[te] for te in tests]
        self.Gh = [x.T @ x for x in self.Xf]
        self.bh = [x.T @ y for x, y in zip(self.Xf, self.rf)]
        self.rr = [float(y @ y) for y in self.rf]
        self.n = sum(len(te) for te in tests)

    @staticmethod
    def _unit(Z):
        s = np.linalg.norm(Z, axis=0)
        return Z / np.where(s > 0, s, 1.0)

    def _extended(self, Z):
        if Z is None:
            return self.Gh, self.bh, self.Xf
        Zu = self._unit(Z)
        Gh, bh, Xf = [], [], []
        for x, G, b, te, y in zip(self.Xf, self.Gh, self.bh, self.tests, self.rf):
            z = Zu[te]
            C = x.T @ z
            Gh.append(np.block([[G, C], [C.T, z.T @ z]]))
            bh.append(np.r_[b, z.T @ y])
            Xf.append(np.hstack([x, z]))
        return Gh, bh, Xf

    def rms(self, Z=None):
        Gh, bh, _ = self._extended(Z)
        Gt, bt = sum(Gh), sum(bh)
        sse = 0.0
        for G, b, rr in zip(Gh, bh, self.rr):
            A = Gt - G
            A[np.diag_indices_from(A)] += 1e-12 * np.trace(A) / len(A)
            d = np.linalg.solve(A, bt - b)
            sse += rr - 2 * d @ b + d @ G @ d
        return float(np.sqrt(max(sse, 0.0) / self.n))

    def add(self, Z):
        self.Gh, self.bh, self.Xf = self._extended(Z)

    def residual(self):
        """(3N,) the residual of the fit on every row."""
        Gt, bt = sum(self.Gh), sum(self.bh)
        Gt = Gt + 1e-12 * np.trace(Gt) / len(Gt) * np.eye(len(Gt))
        d = np.linalg.solve(Gt, bt)
        out = np.empty_like(self.r)
        for te, x, y in zip(self.tests, self.Xf, self.rf):
            out[te] = y - x @ d
        return out


def _polish(found, q_ctrl_rad, levers, r, X_model, steps):
    """Each term's period re-estimated by the profile of the sum of squares
    with every other column (the model's and the other terms') refitted,
    within one grid step of its estimate, and its 95 % interval from the
    profile's curvature there (Delta SSE = chi2_1(0.95) sigma^2).  The scan
    found each period in what the terms before it left, which the others'
    parameters had partly taken; the profile frees it of that.  Updates
    ``found`` in place."""
    from scipy.optimize import minimize_scalar

    N = len(r) // 3
    before = [t["period_deg"] for t in found]
    cols = [columns(q_ctrl_rad[:, t["joint"]], levers[t["joint"]], t["period_deg"]).reshape(3 * N, 2) for t in found]
    for k, t in enumerate(found):
        J = t["joint"]
        X = np.hstack([X_model] + [c for i, c in enumerate(cols) if i != k])
        s = np.linalg.norm(X, axis=0)
        X = X / np.where(s > 0, s, 1.0)
        A = X.T @ X
        A[np.diag_indices_from(A)] += 1e-12 * np.trace(A) / len(A)
        Ainv = np.linalg.inv(A)
        e = r - X @ (Ainv @ (X.T @ r))
        sse_rest = float(e @ e)

        def sse(nu, J=J, X=X, Ainv=Ainv, e=e, sse_rest=sse_rest):
            z = columns(q_ctrl_rad[:, J], levers[J], 360.0 / nu).reshape(3 * N, 2)
            C = X.T @ z
            S = z.T @ z - C.T @ Ainv @ C
            g = z.T @ e
            try:
                return sse_rest - float(g @ np.linalg.solve(S, g))
            except np.linalg.LinAlgError:
                return sse_rest

        nu0, h = 360.0 / t["period_deg"], steps[J]
        res = minimize_scalar(sse, bounds=(nu0 - h, nu0 + h), method="bounded", options={"xatol": 1e-3 * h})
        nu = float(res.x)
        dh = h / 8
        y0, y1, y2 = sse(nu - dh), sse(nu), sse(nu + dh)
        curv = (y0 - 2 * y1 + y2) / dh**2
        sigma2 = y1 / max(len(r) - X.shape[1] - 2, 1)
        t["period_deg"] = 360.0 / nu
        t["period_ci95_deg"] = None
        if curv > 0:
            half = np.sqrt(2 * stats.chi2.ppf(0.95, 1) * sigma2 / curv)
            t["period_ci95_deg"] = [360.0 / (nu + half), 360.0 / max(nu - half, 1e-9)]
        cols[k] = columns(q_ctrl_rad[:, J], levers[J], t["period_deg"]).reshape(3 * N, 2)
    polished = dict(zip(before, [t["period_deg"] for t in found]))
    for t in found:  # a harmonic names its fundamental's polished period
        if t.get("harmonic_of") is not None:
            t["harmonic_of"] = polished.get(t["harmonic_of"], t["harmonic_of"])


def search(q_ctrl_rad, Jv, G, resid_base, X_model, tests, joints=range(6)):
    """Periodic joint errors in what the model leaves (see the module
    docstring).  ``resid_base`` (N, 3) m, base frame; ``X_model`` (3N, P)
    the model's own columns in the base frame (refitted with each term);
    ``tests`` the folds' equation indices.  Returns ([term], [scan]) with
    term = {joint (0-based), period_deg, period_ci95_deg, false_alarm,
    harmonic_of}, scan = {joint, period_deg (k,), reduction (k,)}."""
    N = len(resid_base)
    r = resid_base.reshape(-1)
    ho = _Folds(X_model, r, tests)
    current = ho.rms()
    levers = {J: lever(Jv, G, J) for J in joints}
    spans = {J: float(np.ptp(q_ctrl_rad[:, J])) for J in joints}
    use = [J for J in joints if np.rad2deg(spans[J]) >= MIN_SPAN_DEG and np.any(levers[J])]
    # independent periods: the grid's points over the oversampling, over every joint scanned
    M = max(sum((360.0 / MIN_PERIOD_DEG - 1) * _layout(spans[J])[0] for J in use) / OVERSAMPLE, 1.0)
    found, Z, scans = [], np.zeros((3 * N, 0)), []
    tried_h = set()

    def residual(Zc):
        return ho.residual().reshape(N, 3), X_model.shape[1] + Zc.shape[1]

    def consider(J, nu_c, curv, e, p_cols, harmonic_of, penalty, ci=None):
        nonlocal Z, current
        P = 360.0 / nu_c
        Zj = columns(q_ctrl_rad[:, J], levers[J], P).reshape(3 * N, 2)
        dsse = float(reduction(q_ctrl_rad[:, J], levers[J], e, [nu_c])[0])
        dof = max(3 * N - p_cols - 2, 1)
        sse = float(np.sum(e * e))
        F = (dsse / 2) / max((sse - dsse) / dof, 1e-300)
        p1 = float(stats.f.sf(F, 2, dof))
        fap = float(-np.expm1(penalty * np.log1p(-min(p1, 1 - 1e-16)))) if p1 > 0 else 0.0
        if fap >= ALPHA:
            return False
        rms = ho.rms(Zj)
        if rms > (1 - MIN_STEP_GAIN) * current:
            return False
        sigma2 = (sse - dsse) / dof
        if curv is not None:
            half_nu = np.sqrt(2 * stats.chi2.ppf(0.95, 1) * sigma2 / curv)
            ci = [360.0 / (nu_c + half_nu), 360.0 / max(nu_c - half_nu, 1e-9)]
        found.append({"joint": J, "period_deg": P, "period_ci95_deg": ci, "false_alarm": fap,
                      "harmonic_of": harmonic_of, "held_out_rms_m": rms})
        Z = np.hstack([Z, Zj])
        ho.add(Zj)
        current = rms
        return True

    while len(found) < MAX_TERMS:
        e, p_cols = residual(Z)
        best = None
        for J in use:
            nu, pw = periodogram(q_ctrl_rad[:, J], levers[J], e, spans[J])
            if not found:
                scans.append({"joint": J, "period_deg": 360.0 / nu, "reduction": pw})
            i = int(np.argmax(pw))
            if best is None or pw[i] > best[2]:
                best = (J, i, pw[i], nu, pw)
        if best is None:
            break
        J, i, _, nu, pw = best
        nu_c, curv = _refine(q_ctrl_rad[:, J], levers[J], e, nu, pw, i)
        if not consider(J, nu_c, curv, e, p_cols, None, M):
            break
        ci = found[-1]["period_ci95_deg"]
        for h in HARMONICS:  # the harmonics of what was just found
            if len(found) >= MAX_TERMS or 360.0 / (nu_c * h) < MIN_PERIOD_DEG or (J, h, round(nu_c, 3)) in tried_h:
                continue
            tried_h.add((J, h, round(nu_c, 3)))
            e, p_cols = residual(Z)
            consider(J, nu_c * h, None, e, p_cols, 360.0 / nu_c, 1.0, None if ci is None else [c / h for c in ci])
    if found:
        # one grid step (cycles per turn) either side
        _polish(found, q_ctrl_rad, levers, r, X_model, {J: 1.0 / _layout(spans[J])[0] for J in use})
    return found, scans
