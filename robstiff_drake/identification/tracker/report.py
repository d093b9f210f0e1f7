"""The report of identification/tracker/diagnosis.py: the noise floor, the
gross-error screen, each kept effect in words with its intervals, the
verdict, confounded effects, and the test on a second campaign
(``validate``).  Plain numpy + scipy.
"""

import numpy as np
from scipy import stats

from robstiff_drake.identification.diagnosis import noise_floor as nf
from robstiff_drake.identification.tracker import periodic as tpd
from robstiff_drake.identification.diagnosis.confounding import confounded_pairs
from robstiff_drake.identification.tracker.campaign import position_scale
from robstiff_drake.identification.tracker.fit import Fit, LinearCV, Problem
from robstiff_drake.identification.tracker.model import GEOM
from robstiff_drake.identification.tracker.search import _checks
from robstiff_drake.model import kinematics as kin

OUTLIER_SIGMAS = 6.0


def stats3d(e):
    """{mean, rms, max} of 3D error lengths (mm) of e (n, 3) mm."""
    L = np.linalg.norm(e, axis=1)
    return {"mean": float(L.mean()), "rms": float(np.sqrt(np.mean(L**2))), "max": float(L.max())}


def _floor(problem, groups, rows, noise_mm):
    """The floor: stated, or the pooled scatter of rows measured at one pose."""
    g = groups[rows]
    _, inv, counts = np.unique(g, return_inverse=True, return_counts=True)
    rep = None
    dof = int(np.sum(counts[counts > 1] - 1))
    if dof >= nf.MIN_REPLICATE_DOF:
        means = np.zeros((len(counts), 3))
        np.add.at(means, inv, problem.m[rows])
        means /= counts[:, None]
        dev = problem.m[rows] - means[inv]
        rep = float(np.sqrt(np.sum(dev**2) / (3 * dof))) * 1e3
    if noise_mm is not None:
        return nf.Floor(float(noise_mm), "stated", float(noise_mm), rep, dof, int(np.sum(counts > 1)))
    if rep is not None:
        return nf.Floor(rep, "replicates", None, rep, dof, int(np.sum(counts > 1)))
    return nf.Floor(None, None, None, None, dof, 0)


def _screen(problem, fit, rows, floor_m):
    """Rows whose 3D residual is gross (chi-square(3) at 0.01 / N and
    OUTLIER_SIGMAS robust sigma, never below the floor)."""
    from robstiff_drake.identification.diagnosis.robust_fit import robust_scale, threshold

    e = problem.m[rows] - problem.predict(fit, rows)
    L = np.linalg.norm(e, axis=1)
    s = robust_scale(L)
    if floor_m is not None:
        s = max(s, floor_m)
    if s == 0:
        return np.array([], dtype=int)
    return rows[L**2 / s**2 > max(threshold(len(L)), OUTLIER_SIGMAS**2)]


def _term_reports(problem, fit, kept_blocks, rows, groups):
    """Each kept effect in words, with its parameters, 95 % intervals
    (pose-clustered) and plausibility, at the final fit."""
    X, slices, ev = problem.columns(fit, kept_blocks, rows)
    r = (problem.m[rows] - problem.predict(fit, rows, ev)).reshape(-1)
    cv = LinearCV(X, r, [np.arange(len(r))], np.repeat(groups[rows], 3))
    _, cov, G = cv.fit(np.arange(X.shape[1]))
    half = stats.t.ppf(0.975, max(G - 1, 1)) * np.sqrt(np.maximum(np.diag(cov), 0))
    info = {"ev": ev, "c_nom": problem.c_nom}
    out = []
    for b in kept_blocks:
        sl = slices[b.name]
        v = np.array([fit.geo[k, GEOM.index(kind)] for k, kind in b.geo]) if b.frame == "geometry" \
            else fit.coef[b.name]
        ok, why, physical = _checks(b, v, half[sl], problem, info)
        out.append({"name": b.name, "kind": b.kind, "description": b.describe(v, info),
                    "params": {f"{lab} ({u})": float(x * s) for (lab, u, s), x in zip(b.params, v)},
                    "ci95": {f"{lab} ({u})": [float((x - h) * s), float((x + h) * s)]
                             for (lab, u, s), x, h in zip(b.params, v, half[sl])},
                    "plausible": bool(ok and physical), "plausibility": why})
    return out, X, slices


def periodic_report(fit, kept_blocks, reports):
    """[{joint (1-based), period_deg, period_ci95_deg, amplitude_mrad, amplitude_ci95_mrad, sin_mrad, cos_mrad,
    harmonic_of_deg, false_alarm, beyond_typical, text}] of the kept periodic errors, largest first."""
    out = []
    for b in kept_blocks:
        if not b.periodic:
            continue
        v = fit.coef[b.name]
        ci = next(r for r in reports if r["name"] == b.name)["ci95"]
        for i, t in enumerate(b.periodic):
            s, c = v[2 * i], v[2 * i + 1]
            amp = float(np.hypot(s, c))
            keys = list(ci)[2 * i:2 * i + 2]
            half = max((hi - lo) / 2 for lo, hi in (ci[k] for k in keys)) * 1e-3  # rad, the wider of the two
            out.append({"joint": int(t["joint"]) + 1, "period_deg": float(t["period_deg"]),
                        "period_ci95_deg": t.get("period_ci95_deg"),
                        "amplitude_mrad": amp * 1e3,
                        "amplitude_ci95_mrad": [max(amp - half, 0.0) * 1e3, (amp + half) * 1e3],
                        "sin_mrad": float(s * 1e3), "cos_mrad": float(c * 1e3),
                        "harmonic_of_deg": t.get("harmonic_of"), "false_alarm": t.get("false_alarm"),
                        "beyond_typical": bool(amp > tpd.TYPICAL_MAX_RAD),
                        "text": (f"joint {int(t['joint']) + 1}: an angle error periodic every {t['period_deg']:.4g} deg"
                                 + (f" (95 %: {t['period_ci95_deg'][0]:.4g}-{t['period_ci95_deg'][1]:.4g})"
                                    if t.get("period_ci95_deg") else "")
                                 + f", {amp * 1e3:.2g} mrad: "
                                 + (f"harmonic of {t['harmonic_of']:.4g} deg" if t.get("harmonic_of")
                                    else "reducer or encoder"))})
    return sorted(out, key=lambda e: -e["amplitude_mrad"])


def _verdict(floor, lof, rms_after_mm, trends, leads, unexplained):
    if floor.sigma_mm is None:
        return None, ("no verdict: no noise floor is known (state the instrument's noise per component with "
                      "--noise-mm, or measure some poses twice); the accuracy figures above stand")
    text = (f"held-out RMS {rms_after_mm:.4f} mm per component against a floor of {floor.sigma_mm:.4f} mm "
            f"({floor.source}); lack-of-fit p = {lof.p_value:.2g}")
    if lof.p_value < nf.ALPHA_LACK_OF_FIT:
        lead = ""
        if leads:
            lead = (f"; {leads[0]['name']} would fit more of it (held-out {leads[0]['rms_mm']:.4f} mm) but was not "
                    f"added: {leads[0]['plausibility']}")
        trend = (f"; {', '.join(trends)} (a trend along the file's order, no t_s or seq) was taken out, not as a "
                 "cause" if trends else "")
        return False, (f"the final model does NOT explain the data: {text}; {unexplained:.4f} mm unexplained" + lead
                       + trend)
    if trends:
        return False, (f"not established: {text}, reached only with {', '.join(trends)}: the file has neither t_s nor "
                       "seq, so its order is not known to be the order of measurement; add the time of each row")
    return True, f"the final model explains the data as far as the noise allows: {text}"


def _confounded(X, kept_blocks, problem, fit, rows):
    i, blocks = 9, {"registration": np.arange(0, 6), "measured_point": np.arange(6, 9)}
    for b in kept_blocks:
        n = len(b.params) if b.frame != "geometry" else len(b.geo)
        blocks[b.name] = np.arange(i, i + n)
        i += n
    names = list(blocks)
    geometry = {b.name for b in kept_blocks if b.frame == "geometry"}
    kept = {b.name for b in kept_blocks}
    # the geometry's blocks are one calibration: their parameters correlate as kinematic calibration's do
    pairs = [(a, b) for j, a in enumerate(names) for b in names[j + 1:]
             if (a in kept or b in kept) and not (a in geometry and b in geometry)]
    return confounded_pairs(X, blocks, pairs)


def validate(d, other):
    """3D errors (mm) of another campaign of the same arm under the fitted
    model and registration, and with the registration (6 parameters)
    refitted to it, before (declared model) and after."""
    problem, fit, robot = d.problem, d.fit, d.robot
    q = robot.joint_rad(other.q_deg)
    nominal_mm = kin.tool_position(robot.dh, q, fit.u) * 1e3
    unit = position_scale(other, nominal_mm)
    p2 = Problem(robot, other.q_deg, other.pos * unit / 1e3, force_N=other.force_N, t_s=other.t_s,
                 temp_c=other.temp_c, seq=other.seq, tool_guess_m=fit.u)
    p2.set_gravity(problem.g_base)
    rows = np.arange(p2.n)
    # drift and thermal terms are centred on the fitted campaign's mean time and temperature: the
    # validation file is predicted without them (their origin in another session is not known)
    arm = [b for b in fit.blocks if b.frame != "instrument" and b.name != "thermal_expansion"]
    f_same = fit.copy()
    f_same.blocks = arm
    e_same = (p2.m - p2.predict(f_same, rows)) * 1e3
    base = Fit(fit.R.copy(), fit.t.copy(), fit.u.copy(), np.zeros((6, 5)))
    e_decl = (p2.m - p2.predict(base, rows)) * 1e3

    def reregistered(f0, blocks=None):
        f = f0.copy()
        if blocks is not None:
            f.blocks = list(blocks)
        keep = (f.blocks, f.coef, f.geo)
        for _ in range(6):
            X, sl, ev = p2.columns(f, [], rows)
            r = (p2.m - p2.predict(f, rows, ev)).reshape(-1)
            step, *_ = np.linalg.lstsq(X[:, :6], r, rcond=None)
            full = np.zeros(X.shape[1])
            full[:6] = step
            f = p2.apply(f, [], full, sl)
            f.blocks, f.coef, f.geo = keep
        return (p2.m - p2.predict(f, rows)) * 1e3, f

    e_rereg_before, _ = reregistered(base)
    e_rereg, f_rereg = reregistered(f_same)
    transfer = _transfer(f_same, arm, stats3d(e_rereg)["mean"], reregistered)
    dR = f_rereg.R @ fit.R.T
    moved_deg = float(np.rad2deg(np.arccos(np.clip((np.trace(dR) - 1) / 2, -1.0, 1.0))))
    moved_mm = float(np.linalg.norm(f_rereg.t - fit.t) * 1e3)
    session = [b.name for b in fit.blocks if b not in arm]
    transfer.append({"what": "registration", "carries_over": moved_mm < REGISTRATION_SAME_MM,
                     "text": f"the instrument's frame moved by {moved_mm:.4g} mm and {moved_deg:.3g} deg against the "
                             "fitted campaign's: " + ("it carries over (the same set-up)" if moved_mm <
                                                      REGISTRATION_SAME_MM else "refitted (another set-up)")})
    if session:
        transfer.append({"what": "session", "carries_over": False,
                         "text": ", ".join(session) + ": centred on the fitted campaign's own time and temperature; "
                                 "not carried over"})
    return {"data": other.path, "n_measurements": p2.n,
            "error_3d_mm": {"before": stats3d(e_decl), "after": stats3d(e_same)},
            "error_3d_mm_reregistered": {"before": stats3d(e_rereg_before), "after": stats3d(e_rereg)},
            "transfer": transfer,
            "note": "after: the fitted arm, measured point and registration; reregistered: the instrument's 6 "
                    "registration parameters refitted to this file (another session, the tracker moved); drift and "
                    "thermal terms are not carried over; transfer: each group of the fitted model left out in turn "
                    "(registration refitted)"}


# The instrument's frame within this of the fitted campaign's: the same set-up (a tracker re-levelled in place
# moves by tenths of a mm)
REGISTRATION_SAME_MM = 1.0
TRANSFER_MIN_GAIN = 0.02


def _transfer(f_same, arm, mean_all, reregistered):
    """What of the fitted arm model carries over to another campaign: each
    group (kinematics, sag, periodic errors, the rest) left out in turn, the
    registration refitted: it carries over when the other campaign's mean 3D
    error is TRANSFER_MIN_GAIN lower with it."""
    groups = {"kinematics": [b for b in arm if b.frame == "geometry"],
              "sag": [b for b in arm if b.frame == "joint"],
              "periodic errors": [b for b in arm if b.periodic]}
    groups["other arm effects"] = [b for b in arm if not any(b in g for g in groups.values())]
    out = []
    for name, members in groups.items():
        if not members:
            continue
        rest = [b for b in arm if b not in members]
        f = f_same.copy()
        if name == "kinematics":
            f.geo = np.zeros_like(f.geo)
        e, _ = reregistered(f, rest)
        without = stats3d(e)["mean"]
        carries = mean_all < (1 - TRANSFER_MIN_GAIN) * without
        hurts = mean_all > without
        out.append({"what": name, "blocks": [b.name for b in members], "mean_with_mm": mean_all,
                    "mean_without_mm": without, "carries_over": bool(carries),
                    "text": f"{name} ({', '.join(b.name for b in members)}): mean 3D error {without:.4f} mm without, "
                            f"{mean_all:.4f} mm with: "
                            + ("carries over" if carries else "makes it worse: does not carry over" if hurts
                               else "no measurable gain")})
    return out
