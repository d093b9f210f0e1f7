"""The causes of a machining run's residual and how they are fitted and
tested (identification/runs/diagnosis.py, whose docstring describes the
method): the candidates' columns, the face's envelope, the nested fits,
forward selection, the noise floor and the damping's profile.  Plain numpy
and scipy."""

from dataclasses import dataclass, replace

import numpy as np
from scipy.optimize import least_squares

from robstiff_drake.errors import InputError
from robstiff_drake.identification.runs import tables as rt
from robstiff_drake.identification.runs import scan_statistics as ss
from robstiff_drake.identification.runs.signals import (
    GRID_HZ, gear_law_deviation, play_crossing_deviation, play_relay_deviation,
)
from robstiff_drake.model.transmission import fallback_take_up_Nm, gap_friction_Nm


ALPHA = 1e-3  # per test; about 10 causes are tried per round
SIZE_FACTOR = 1.0  # a named cause changes the surface by at least this many noise floors (RMS)
MAX_CAUSES = 2
MIN_FLOOR_MM = 5e-4  # below half a micrometre a machining question is not decided
EXPLAIN_ALPHA = 0.01  # the residual is consistent with the floor unless chi2 says otherwise at this level
NO_DATA = 0.1  # of the floor: what a parameter must move the surface by over its range to be kept
LOOP = "loop_lag"  # the loop's tracking error: always in the model, its fix offered when it matters
NOISE_DISAGREE = 2.0  # warn when the stated and the estimated noise differ by more than this factor
# ASSUMPTION: a constant error of the sensor's force reading after gravity removal is within 20 N per axis: a
# strain-gauge sensor's zero drift is about 0.05 % of its rated force per 10 K (HBM), 2.5 N for a 2,500 N sensor
# warmed 20 K; a payload calibrated 1 kg off reads 10 N off; beyond that a user would have re-zeroed the sensor
FORCE_BIAS_N = 20.0
# ASSUMPTION: a direction of the force bias that moves the face less than a tenth as much as the one that moves it
# most is confounded with it on this pass (its estimate would be the noise's): it is not fitted
BIAS_DIRECTION_TOL = 0.1
# ASSUMPTION: the lost motion a fit may name is bounded by a physical limit, not by the catalogue: 2 mrad (7
# arcmin), a worn-out reducer (the plant's own limit, diagrams/scenario_schema.MAX_PLAY_RAD; RV gears are
# catalogued at <= 1 arcmin, robot reducers at 0.1-0.3 mrad).  A gap that wide moves the tool of an arm reaching
# 1.5 m by up to 6 mm (2 b L) at a reversal, which a cell sees without a scan.  A size beyond the catalogue is
# reported as a finding (LOST_MOTION_CATALOGUE_RAD: diagnosis.py's warning), not refused
LOST_MOTION_LIMIT_RAD = 2e-3
LOST_MOTION_CATALOGUE_RAD = 2.91e-4  # 1 arcmin: the RV gears' catalogued lost motion (Nabtesco RV-E: <= 1 arcmin)
REBUILDS = 4  # refits of a cause not linear in its parameters (lost motion: the crossing), each at the last's
REBUILD_RTOL = 0.01  # ... until its parameters move by less than 1 %
ALIKE = 1.0  # causes whose mean-square residuals differ by less than ALIKE x floor^2 are alike


@dataclass
class Param:
    name: str
    unit: str
    scale: float  # SI -> unit
    lo: float  # bounds, SI
    hi: float
    lo_is_limit: bool = False  # lo is a physical limit (b >= 0), not a plausibility bound
    nominal: float = 0.0  # SI: the value with nothing amiss (the loop's a: 1, as predicted)


@dataclass
class Candidate:
    name: str
    columns: np.ndarray  # (n, k): dz (m) per unit parameter (SI)
    params: list
    what: str
    # where the fitted parameters are combinations of physical ones (only those the run can see): the physical
    # parameters = basis @ the fitted ones, named basis_names (SI), as reported
    basis: np.ndarray = None
    basis_names: tuple = ()
    # where the cause is not linear in its parameters: a callable of the parameters (SI, all of them) giving
    # the columns per unit parameter there (try_cause refits with them, REBUILDS times)
    rebuild: object = None


def loop_lag_ms(sig):
    """How far (ms) the correction lags the model's deflection where it acts,
    at the motor: the compensator's own lag (the shift, 0-500 ms, that best
    cancels the correction's vertical effect and the deflection's) plus the
    servo's (the interpolator's dead time and the position loop's 1 / Kp)."""
    corr_z = np.einsum("nj,nj->n", sig.Jz, sig.correction_rad)
    defl_z = np.einsum("nj,nj->n", sig.Jz, sig.model_dq_rad)
    if not np.any(defl_z):
        return sig.servo.low_frequency_lag_s * 1e3
    shifts = np.arange(0.0, 0.5, 1.0 / GRID_HZ)
    cost = [np.sum((corr_z + np.interp(sig.t_s - d, sig.t_s, defl_z)) ** 2) for d in shifts]
    return float((shifts[int(np.argmin(cost))] + sig.servo.low_frequency_lag_s) * 1e3)


def _along(sig, dq):
    """The tool's vertical deviation (m, (n,)) of joint deviations dq (n, 6) rad."""
    return np.einsum("nj,nj->n", sig.Jz, dq)


def candidates(sig):
    """The candidate causes' columns and parameters (see the module docstring)."""
    Jz, c = sig.Jz, sig.compliance
    # ASSUMPTION: a <= 1.5.  The prediction has the servo and the arm's modes; a tracking error that fits
    # only when scaled beyond 1.5 is not this one
    out = [Candidate(LOOP, sig.dz_loop_m[:, None], [Param("a", "x predicted", 1.0, 0.0, 1.5, True, 1.0)],
                     "the loop's tracking error (the correction's lag behind the load, through the compensator, "
                     "the interpolator and the servo), as the logs predict it")]
    # what a joint's gear carries beyond the weight: the process load (a generalized force on the links,
    # which the gear holds back) and the arm's inertia.  ASSUMPTION (as diagrams/station.py): the
    # controller's gravity model is calibrated on the arm, so a stiffness error leaves the weight's part
    # to it; lost motion and coupling are not in it (the touch-off takes their static part at the first
    # path point only)
    moved = sig.tau_Nm - sig.tau_inertia_Nm
    for j in range(6):
        # a joint softer (r > 0) or stiffer than the model; ASSUMPTION: -50 %..+100 % of the compliance
        # bounds what an identified model can be off by
        out.append(Candidate(f"stiffness_error_j{j + 1}", (Jz[:, j] * c[j] * moved[:, j])[:, None],
                             [Param(f"r{j + 1}", "%", 100.0, -0.5, 1.0)],
                             f"joint {j + 1}'s compliance differs from the model's"))
    law = (sig.tau_static_Nm, sig.tau_touch_off_Nm, sig.tau_inertia_Nm, sig.tau_Nm)
    take_up = fallback_take_up_Nm(c)  # each joint's, as the compensator's (signals.gear_law_deviation)
    # the compensator's hysteretic law (its default, model/play_hysteresis.py; the plant's too): a relay per
    # gear switching where the total torque passes its friction, the compensator's fallback (the settings
    # carry no identified one: 1.5 % of the rated torque of the model's stiffness, model/compensator.py)
    friction = gap_friction_Nm(1.0 / np.asarray(c, dtype=float))
    relay = play_relay_deviation(*law, friction)
    cross = _crossing_columns(sig, law, friction, relay) if sig.twist_inertia_kgm2 is not None else None
    out.append(Candidate("lost_motion", np.column_stack([_along(sig, relay * np.eye(6)[j]) for j in range(6)]),
                         [Param(f"b{j + 1}", "urad", 1e6, 0.0, LOST_MOTION_LIMIT_RAD, True) for j in range(6)],
                         "lost motion (backlash) in the gears beyond the model's: each gear stays on the flank "
                         "it last pressed until the total torque it carries (weight, inertia and cut) passes "
                         "the friction in its play the other way, and its link then crosses the gap with its "
                         "inertia (the compensator's hysteretic law)", rebuild=cross))
    # ASSUMPTION: |c23| <= 0.3 sqrt(c2 c3); a positive-definite compliance needs < 1
    c23 = 0.3 * np.sqrt(c[1] * c[2])
    out.append(Candidate("joint_coupling", _along(sig, gear_law_deviation(*law, None, 1.0, take_up))[:, None],
                         [Param("c23", "rad/(N*m)", 1.0, -c23, c23)],
                         "a joint 2-3 coupling beyond the model's (of the total torque)"))
    if sig.tau_per_sensor_force is not None:
        out.append(_force_bias(Jz, c, sig.tau_per_sensor_force))
    out.append(Candidate("setup_offset", -np.ones((len(sig.t_s), 1)), [Param("offset", "mm", 1e3, -1e-3, 1e-3)],
                         "a constant: tool length or workpiece height (+ = cut more)"))
    return out


def _crossing_columns(sig, law, friction_Nm, relay):
    """The lost_motion cause's columns per unit b at b (a callable of the six
    b, rad): the links crossing their gaps with their twist inertia (a wider
    gap takes longer: signals.play_crossing_deviation), the relay where b = 0."""
    def columns(b):
        b = np.maximum(np.asarray(b, dtype=float), 0.0)
        dev = play_crossing_deviation(*law, b, friction_Nm, sig.twist_inertia_kgm2, sig.t_s)
        per = np.where(b > 0, dev / np.where(b > 0, b, 1.0), relay)
        return np.column_stack([_along(sig, per * np.eye(6)[j]) for j in range(6)])
    return columns


def _force_bias(Jz, c, tau_per_force):
    """The force_bias candidate: the compensator corrected for a force the
    cut did not exert, so the arm sits off by what the model's compliance
    makes of it.  On a pass whose orientation hardly changes, the sensor's
    three axes move the face almost alike: only the directions of the bias
    the run can see (singular values of the three columns within
    BIAS_DIRECTION_TOL of the largest) are fitted, each along its unit
    direction; the bias reported is their sum (the smallest bias that
    explains the face)."""
    X = -np.einsum("nj,nja->na", Jz * c, tau_per_force)
    _, S, Vt = np.linalg.svd(X, full_matrices=False)
    seen = S >= BIAS_DIRECTION_TOL * S[0] if S[0] > 0 else np.zeros(3, bool)
    basis = Vt[seen].T if seen.any() else np.eye(3)
    where = "; ".join("(" + ", ".join(f"{v:+.2f}" for v in basis[:, i]) + ")" for i in range(basis.shape[1]))
    return Candidate("force_bias", X @ basis,
                     [Param(f"F{i + 1}", "N", 1.0, -FORCE_BIAS_N, FORCE_BIAS_N) for i in range(basis.shape[1])],
                     "a constant error of the sensor's force reading after gravity removal (its bias drifted since "
                     "it was calibrated, or the payload's weight is off); this run sees it along the sensor-frame "
                     f"direction(s) {where}", basis, ("Fx", "Fy", "Fz"))


def _physical(c, k, theta):
    """{name: SI value} of a cause's fitted parameters (kept indices k)."""
    if c.basis is None:
        return {c.params[i].name: float(v) for i, v in zip(k, theta)}
    full = np.zeros(len(c.params))
    full[list(k)] = theta
    return dict(zip(c.basis_names, (c.basis @ full).tolist()))


class Envelope:
    """The face a deviation dz(t) leaves along the scan: each point is the
    lowest the cutter's face (radius R, centred on the program's tool point,
    moved by the arm's own motion error ``sig.dz_motion_m``) went while
    covering it."""

    def __init__(self, scan, sig, cutter_diameter_mm):
        x, y = scan.x_mm / 1e3, scan.y_mm / 1e3
        p = sig.p_nominal_m
        R = cutter_diameter_mm / 2e3
        cover = (x[:, None] - p[None, :, 0]) ** 2 + (y[:, None] - p[None, :, 1]) ** 2 <= R * R
        self.covered = cover.any(axis=1)  # scan points the pass went over
        cover = cover[self.covered]
        self.samples = np.flatnonzero(cover.any(axis=0))  # samples that cover a scan point
        cover = cover[:, self.samples]
        # the covering (point, sample) pairs, point by point: the envelope is a minimum over each point's run
        rows, cols = np.nonzero(cover)
        self._pair_samples = self.samples[cols]
        self._starts = np.flatnonzero(np.r_[True, np.diff(rows) > 0])
        z = p[self._pair_samples, 2]
        self.base = np.minimum.reduceat(z, self._starts)  # the programmed face
        self._Z = z + sig.dz_motion_m[self._pair_samples]

    def surface(self, dz):
        """Surface error (m, + = cut more) at the covered scan points."""
        return self.base - np.minimum.reduceat(self._Z + dz[self._pair_samples], self._starts)


@dataclass
class Fit:
    causes: list  # Candidate
    keep: list  # per cause: indices of its parameters kept
    theta: np.ndarray  # SI, concatenated
    rss: float
    residual: np.ndarray  # m

    def columns(self):
        return np.hstack([c.columns[:, k] for c, k in zip(self.causes, self.keep)]) if self.causes else None

    def params(self):
        return [p for c, k in zip(self.causes, self.keep) for p in (c.params[i] for i in k)]

    def slices(self):
        out, i = [], 0
        for k in self.keep:
            out.append(slice(i, i + len(k)))
            i += len(k)
        return out


def _solve(env, cols, params, y, starts):
    """Bounded least squares of surface(cols @ theta) = y from each start;
    (theta SI, rss m^2) of the best.  Solved for each parameter's fraction
    of its range and residuals in mm, so that the solver's tolerances (made
    for numbers of order one) stop it at the optimum, not at the start."""
    lo = np.array([p.lo for p in params])
    span = np.array([p.hi for p in params]) - lo

    def resid(u):
        return (env.surface(cols @ (lo + span * u)) - y) * 1e3

    best = None
    for start in starts:
        u0 = np.clip((np.asarray(start, dtype=float) - lo) / span, 0.0, 1.0)
        sol = least_squares(resid, u0, bounds=(0.0, 1.0), method="trf", x_scale="jac")
        if best is None or sol.cost < best.cost:
            best = sol
    return lo + span * best.x, float(2.0 * best.cost) * 1e-6


def fit_model(env, causes, keep, y, base=None):
    """Fit the causes (their kept parameters) to y.  ``base``: the fit of
    the model this one extends (its causes first): its solution, with the
    new parameters at zero, is the first start, so the extension is never
    worse; the new parameters also start at a quarter and three quarters of
    their range, and all parameters start once more at their nominal
    values (a fit through the face's envelope has local minima: an old
    parameter that absorbed what the new one explains may not come back
    from where the smaller model left it)."""
    fit = Fit(list(causes), [list(k) for k in keep], np.zeros(0), float(y @ y), -y)
    params = fit.params()
    if not params:
        return fit
    n_old = len(base.theta) if base is not None else 0
    head = base.theta if base is not None else np.zeros(0)
    new = params[n_old:]
    starts = [np.r_[head, [p.nominal for p in new]]]
    for frac in (0.25, 0.75):
        starts.append(np.r_[head, [p.lo + frac * (p.hi - p.lo) for p in new]])
    if n_old:
        starts.append(np.array([p.nominal for p in params]))
    fit.theta, fit.rss = _solve(env, fit.columns(), params, y, starts)
    fit.residual = env.surface(fit.columns() @ fit.theta) - y
    return fit


def without(fit, i, value=None):
    """fit.theta with cause i's parameters set to zero (or parameter ``i``, a flat index, to ``value``)."""
    th = fit.theta.copy()
    if value is None:
        th[fit.slices()[i]] = 0.0
    else:
        th[i] = value
    return th


def rms(v):
    return float(np.sqrt(np.mean(np.square(v)))) if np.size(v) else 0.0


def _no_data(env, fit, floor_m, first_new):
    """Flat indices (>= first_new) of parameters that cannot move the surface
    by NO_DATA x the floor over their whole range."""
    cols, params = fit.columns(), fit.params()
    out = []
    for i in range(first_new, len(params)):
        s_lo = env.surface(cols @ without(fit, i, params[i].lo))
        s_hi = env.surface(cols @ without(fit, i, params[i].hi))
        if rms(s_hi - s_lo) < NO_DATA * floor_m:
            out.append(i)
    return out


def _identifiable(env, cols):
    X = cols[env.samples]
    norms = np.linalg.norm(X, axis=0)
    if np.any(norms == 0):
        return False
    return np.linalg.matrix_rank(X / norms, tol=1e-8) == X.shape[1]


def try_cause(env, base, cand, y, floor_m, stats_ctx):
    """Extend ``base`` by ``cand``: the fit, its test and whether it is named."""
    row = {"name": cand.name, "what": cand.what}
    keep = list(range(len(cand.params)))
    # a parameter whose column is zero over the covered samples cannot act here
    norms = np.linalg.norm(cand.columns[env.samples], axis=0)
    keep = [i for i in keep if norms[i] > 1e-9 * max(norms.max(), 1e-300)]
    n_old = len(base.theta)
    while True:
        if not keep:
            row["status"] = "no data in this run (the cause cannot change the surface here)"
            return row, None
        causes, keeps = base.causes + [cand], base.keep + [keep]
        trial = Fit(causes, keeps, np.zeros(0), 0.0, None)
        if not _identifiable(env, trial.columns()):
            row["status"] = "not identifiable from this run (its deviation is a combination of the model's)"
            return row, None
        fit = fit_model(env, causes, keeps, y, base)
        dropped = _no_data(env, fit, floor_m, n_old)
        if not dropped:
            break
        keep = [k for j, k in enumerate(keep) if n_old + j not in dropped]
    if cand.rebuild is not None:  # a cause not linear in its parameters: its columns where the fit put them
        for _ in range(REBUILDS):
            full = np.zeros(len(cand.params))
            full[keep] = fit.theta[n_old:]
            cand = replace(cand, columns=cand.rebuild(full))
            prev = fit.theta[n_old:].copy()
            fit = fit_model(env, base.causes + [cand], base.keep + [keep], y, base)
            if np.allclose(fit.theta[n_old:], prev, rtol=REBUILD_RTOL, atol=0.0):
                break
    n = y.size
    n_eff, tau = ss.effective_points(fit.residual * 1e3, stats_ctx["segs"], stats_ctx["length_mm"],
                                     stats_ctx["cutter_mm"])
    F, p = ss.f_test(base.rss, fit.rss, len(keep), len(fit.theta), n, n_eff)
    # what the cause adds: how far the face it fits moves from the smaller model's own fit (a cause that
    # only trades places with one already in the model, as an offset and a stiffness error on a steady
    # cut, moves it little however large its parameter)
    before = env.surface(base.columns() @ base.theta) if base.causes else np.zeros(n)
    size = rms(env.surface(fit.columns() @ fit.theta) - before)
    mine = fit.theta[fit.slices()[-1]]
    ps = [cand.params[i] for i in keep]
    at_bound = [q.name for q, v in zip(ps, mine)
                if (abs(v - q.hi) <= 1e-6 * (q.hi - q.lo)) or (not q.lo_is_limit and abs(v - q.lo) <= 1e-6 * (q.hi - q.lo))]
    row.update(status="ok", rms_mm=rms(fit.residual) * 1e3, f_stat=F, p_value=p, n_effective=n_eff,
               size_mm=size * 1e3, params={f"{q.name} ({q.unit})": float(v * q.scale) for q, v in zip(ps, mine)},
               dropped_no_data=[cand.params[i].name for i in range(len(cand.params)) if i not in keep],
               at_bound=at_bound)
    reasons = []
    if p >= ALPHA:
        reasons.append(f"p = {p:.2g} >= {ALPHA:g}")
    if size < SIZE_FACTOR * floor_m:
        reasons.append(f"changes the surface by {size * 1e3:.4f} mm, below the noise floor")
    if at_bound:
        reasons.append(f"needs {', '.join(at_bound)} at its plausibility bound")
    row["named"] = not reasons
    row["why_not"] = "; ".join(reasons)
    return row, fit


def noise_floor(scan, segs, stated_mm, warnings):
    """(floor mm, source, stated mm or None, estimated mm or None)."""
    estimated = ss.noise_from_scan(scan.error_mm, segs)
    stated, source = stated_mm, "stated (--noise-mm)"
    if stated is None and scan.noise_mm is not None:
        stated, source = scan.noise_mm, f"stated ({rt.SCAN} noise_mm)"
    if stated is None:
        if estimated is None:
            raise InputError(f"{scan.path}: too few neighbouring points to estimate the scan's noise; "
                             "state it with --noise-mm SIGMA")
        floor, source = estimated, "estimated from the scan (second differences)"
    else:
        floor = stated
        if estimated is not None and stated > 0 and not 1 / NOISE_DISAGREE <= estimated / stated <= NOISE_DISAGREE:
            warnings.append(f"the scan's own noise ({estimated:.4f} mm, from its second differences) differs from "
                            f"the stated {stated:.4f} mm by more than {NOISE_DISAGREE:g}x")
    if floor < MIN_FLOOR_MM:
        warnings.append(f"noise floor {floor:.5f} mm raised to {MIN_FLOOR_MM} mm (nothing finer is decided)")
        floor = MIN_FLOOR_MM
    return floor, source, stated, estimated


def trace(env, cands, y, floor_m, stats_ctx, base):
    """Forward selection of causes on top of ``base`` (the loop's tracking
    error: always in the model); returns (rounds, final Fit)."""
    fit = base
    rounds = []
    while len(fit.causes) - len(base.causes) < MAX_CAUSES:
        results, fits = [], {}
        for cand in cands:
            if any(c.name == cand.name for c in fit.causes):
                continue
            row, f = try_cause(env, fit, cand, y, floor_m, stats_ctx)
            results.append(row)
            if f is not None:
                fits[cand.name] = f
        rounds.append(results)
        named = [r for r in results if r.get("named")]
        if not named:
            break
        fit = fits[min(named, key=lambda r: fits[r["name"]].rss)["name"]]
    return rounds, fit


def alternatives(env, cands, y, floor_m, stats_ctx, final):
    """Models as good as the final one with one named cause swapped for
    another candidate: its fit's mean square within ALIKE x floor^2 of the
    final's, changing the surface by at least the floor, no parameter at a
    plausibility bound.  [(row, Fit)], the row naming the cause replaced."""
    out = []
    names = [c.name for c in final.causes]
    for i, c in enumerate(final.causes):
        if c.name == LOOP:
            continue  # always in the model
        rest = Fit([], [], np.zeros(0), float(y @ y), -y)
        others = [(cc, k) for j, (cc, k) in enumerate(zip(final.causes, final.keep)) if j != i]
        if others:
            rest = fit_model(env, [o[0] for o in others], [o[1] for o in others], y)
        for cand in cands:
            if cand.name in names:
                continue
            row, f = try_cause(env, rest, cand, y, floor_m, stats_ctx)
            if f is None or row["at_bound"] or row["size_mm"] < SIZE_FACTOR * floor_m * 1e3:
                continue
            if (f.rss - final.rss) / y.size <= ALIKE * floor_m**2:
                row["instead_of"] = c.name
                out.append((row, f))
    return out


def cause_params(fit):
    """{cause name: {param (unit): value}} of a fit."""
    out = {}
    for c, k, sl in zip(fit.causes, fit.keep, fit.slices()):
        if c.basis is not None:  # physical parameters, in the unit of the fitted ones
            out[c.name] = {f"{n} ({c.params[0].unit})": v * c.params[0].scale
                           for n, v in _physical(c, k, fit.theta[sl]).items()}
            continue
        out[c.name] = {f"{c.params[i].name} ({c.params[i].unit})": float(v * c.params[i].scale)
                       for i, v in zip(k, fit.theta[sl])}
    return out


def si_params(fit):
    out = {}
    for c, k, sl in zip(fit.causes, fit.keep, fit.slices()):
        out[c.name] = _physical(c, k, fit.theta[sl])
    return out
