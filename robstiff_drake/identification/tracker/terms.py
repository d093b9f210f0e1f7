"""The effects a tracker campaign is searched for (identification/
tracker_diagnosis.py), each a block of parameters with its columns, its
physical range and its words.  Plain numpy; no Drake.

Geometry (the arm's kinematic errors; only the identifiable parameters,
tracker_diagnosis decides which from the rank of the identification
Jacobian):
  joint_offsets   theta_i: the joints' zero offsets
  link_lengths    d_i, a_i
  link_twists     alpha_i, and Hayati's beta_i between nearly parallel axes
Displacements of the arm (base frame):
  joint_compliance        sag under the arm's own weight (and applied loads), which the
                          declared model has with the robot file's compliances (x = 1):
                          dq_j = x_j c_j tau_j(q + dq), c_j the robot file's compliance,
                          tau_j the robot file's masses' torque (tracker_model.gravity)
                          at the sagged pose (a fixed point, applied in the kinematics:
                          a large arm sags by 1-4 mrad, whose square is not negligible);
                          x_j a parameter for the joints that carry SAG_TORQUE_SHARE of
                          the largest torque, 1 (the file's compliance) for the others
  periodic_jJ             joint J's angle errors periodic in its angle, of
                          periods found by tracker_periodic.py's search:
                          dJ = sum_P s_P sin(2 pi J / P) + c_P cos(2 pi J / P)
  base_tilt               the base tilts on its foundation under the weight's
                          moment: theta = c (M_x, M_y, 0), d = theta x p
  thermal_expansion       the arm grows with temperature: d = kappa (T - mean) p
The instrument (its frame moves against the base):
  thermal_drift           v (T - mean)
  time_drift              v (t - mean), and time_drift_quadratic in (t - mean)^2
  seq_drift               v (seq - mean) (measurement order without a clock)
  order_trend             v (row - mean) along the file's order: with neither
                          t_s nor seq the order of the rows is not known to be
                          the order of measurement, so a trend found this way is
                          reported as unexplained, not as a cause
Every range below is an engineering bound; the comment gives its reasoning.
"""

from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from robstiff_drake.identification.diagnosis import plausibility as pl
from robstiff_drake.identification.tracker import periodic as tpd
from robstiff_drake.identification.tracker.model import GEOM, GEOM_UNITS

# Joint zero offsets: a robot mastered to its marks is within 0.01-0.1 deg
# (calibration literature); a joint mastered at the wrong mark or after a
# motor change can be off by about a degree.  Beyond 2 deg someone would see it.
JOINT_OFFSET_MAX_RAD = np.deg2rad(2.0)
# Link lengths: machining and assembly tolerances of a large arm's castings,
# 0.1-1 mm in the literature; 5 mm is a wrong drawing, not a tolerance.
LINK_LENGTH_MAX_M = 5e-3
# Link twists and Hayati tilts: 0.01-0.1 deg; 1 deg is a bent or misassembled link.
LINK_TWIST_MAX_RAD = np.deg2rad(1.0)
# A joint's compliance against the robot file's: the file's values are often
# assumptions (the library's are); a factor 10 either way is the bound.
COMPLIANCE_FACTOR_MAX = 10.0
# A joint's periodic angle error (reducer, encoder): catalogues give 0.3-1.5 mrad
# (tracker_periodic.TYPICAL_MAX_RAD is the typical size the report names); an
# error of 20 mrad (1.1 deg) would be seen by anyone watching the arm: beyond it
# the term stands for another effect and is a lead.
PERIODIC_ERROR_MAX_RAD = 20e-3
# Thermal expansion of the arm: steel 12 ppm/K, aluminium 23 ppm/K; 50 ppm/K bound.
THERMAL_EXPANSION_MAX_PER_K = 50e-6
# The instrument against the base with temperature: a 1 m steel stand grows
# 12 um/K, a tracker's own drift is of that order; bound 0.1 mm/K.
THERMAL_DRIFT_MAX_M_PER_K = 1e-4
# Drift in time: warm-up of a large arm moves the tool 0.1-0.5 mm over
# hours (plausibility.py); bound 1 mm/h, and 0.5 mm over a campaign.
TIME_DRIFT_MAX_M_PER_H = 1e-3
DRIFT_TOTAL_MAX_M = pl.DRIFT_TOTAL_MAX_M
# A joint whose largest torque (gravity and loads) is below this fraction of
# the campaign's largest carries none: its compliance has no column (round-off).
TORQUE_REL_MIN = 1e-6


@dataclass
class Eval:
    """The campaign at the current model, what every block's columns need."""

    T: np.ndarray  # (N, 7, 3, 4) frames of the current chain (rotations and origins)
    p: np.ndarray  # (N, 3) m, the measured point in the base frame
    Jv: np.ndarray  # (N, 3, 6)
    tau: np.ndarray  # (N, 6) N*m: the weight's (and loads') torques
    moment: np.ndarray  # (N, 3) N*m about the base origin
    q_ctrl_rad: np.ndarray  # (N, 6) the controller's angles
    G: np.ndarray  # (6, 6) d model angle / d controller angle
    c_nom: np.ndarray  # (6,) the robot file's compliances
    t_h: np.ndarray | None  # (N,) hours from the campaign's mean time
    dtemp: np.ndarray | None  # (N,) K from the mean temperature
    seq: np.ndarray | None  # (N,) measurement order, centred
    order: np.ndarray  # (N,) the rows' order in the file, centred, per 1000 rows
    geo_free: list = field(default_factory=list)  # [(link, kind)] identifiable geometry
    rows: np.ndarray = None  # the campaign's rows these are
    q_rad: np.ndarray = None  # (N, 6) the model's angles the frames T are at (sagged)
    g_base: np.ndarray = None  # (3,) m/s^2 gravity in the base frame the sag was computed with
    robot: object = None  # the robot file's RobotModel (masses, payload)
    c_sag: np.ndarray = None  # (6,) rad/(N*m) the compliances the sag uses (the fit's factors times c_nom)


@dataclass
class Block:
    name: str
    frame: str  # "geometry", "joint" (deflects the joints: applied in the kinematics), "base" or "instrument"
    params: list  # [(label, unit, scale from SI)]
    columns: Callable  # Eval -> (N, 3, p) (geometry: indices into the geometry Jacobian, see geo)
    describe: Callable  # (values SI, info) -> str
    plausible: Callable  # (values SI, info) -> (ok, reason)
    needs: Callable = None  # Eval -> reason it cannot be tried, or None
    kind: str = "cause"  # "cause", or "trend" (reported as unexplained, never as a cause)
    geo: list = field(default_factory=list)  # geometry blocks: [(link, kind)]
    joints: list = field(default_factory=list)  # "joint" blocks: the joints whose compliance is a parameter
    start: float = 0.0  # the parameters' value in the declared model (the sag's: 1, the robot file's compliance)
    periodic: list = field(default_factory=list)  # periodic blocks: the terms found [{joint, period_deg, ...}]


def _fmt(values, params):
    return ", ".join(f"{lab} = {v * s:.3g} {u}" for (lab, u, s), v in zip(params, values))


def _bound(values, bound, what, unit, scale):
    return pl.within(values, bound, what, unit, scale)


def geometry_block(name, kinds, free, text):
    geo = [(k, kind) for k, kind in free if kind in kinds]
    params = [(f"{kind}{k + 1}", *GEOM_UNITS[kind]) for k, kind in geo]
    bounds = {"theta": JOINT_OFFSET_MAX_RAD, "d": LINK_LENGTH_MAX_M, "a": LINK_LENGTH_MAX_M,
              "alpha": LINK_TWIST_MAX_RAD, "beta": LINK_TWIST_MAX_RAD}

    def plausible(v, info):
        worst = max(range(len(geo)), key=lambda i: abs(v[i]) / bounds[geo[i][1]]) if geo else None
        if worst is None:
            return True, ""
        k, kind = geo[worst]
        unit, s = GEOM_UNITS[kind]
        return pl.within([v[worst]], bounds[kind], f"{kind}{k + 1} correction", unit, s)

    return Block(name, "geometry", params, None, lambda v, info: f"{text}: {_fmt(v, params)}", plausible,
                 needs=(lambda ev: None if geo else "no parameter of this kind is identifiable"), geo=geo)


# The sag's compliances are parameters only for joints whose weight torque
# is at least this share of the most loaded joint's (RMS over the campaign):
# below it (joint 1 of an arm whose base is a fraction of a degree off level)
# the torque is too small to tell the joint's compliance from the others'.
SAG_TORQUE_SHARE = 0.02


def _torque_joints(ev):
    rms = np.sqrt(np.mean(ev.tau**2, axis=0))
    tmax = np.max(np.abs(ev.tau), axis=0)
    keep = (tmax > TORQUE_REL_MIN * max(float(tmax.max()), 1e-300)) & (rms >= SAG_TORQUE_SHARE * rms.max())
    return np.flatnonzero(keep)


def joint_compliance_block(ev):
    joints = _torque_joints(ev)
    params = [(f"k{j + 1}", "x the robot file's compliance", 1.0) for j in joints]

    def columns(e):
        return np.stack([e.Jv[:, :, j] * (e.c_nom[j] * e.tau[:, j])[:, None] for j in joints], axis=-1)

    def describe(v, info):
        k = [f"k{j + 1} = {1.0 / (x * info['c_nom'][j]):.3g}" if x > 0 else f"k{j + 1} negative"
             for j, x in zip(joints, v)]
        return ("the joints deflect under the arm's weight (robot file's masses) and the applied loads: stiffness "
                + ", ".join(k) + " N*m/rad")

    def plausible(v, info):
        bad = [f"joint {j + 1}: {x:.3g}x the robot file's compliance" for j, x in zip(joints, v)
               if not 0 < x <= COMPLIANCE_FACTOR_MAX]
        if bad:
            return False, "; ".join(bad) + f" (physical: positive, at most {COMPLIANCE_FACTOR_MAX:g}x)"
        return True, f"compliances {np.round(v, 3).tolist()} x the robot file's (within 0-{COMPLIANCE_FACTOR_MAX:g}x)"

    return Block("joint_compliance", "joint", params, columns, describe, plausible,
                 needs=lambda e: None if len(joints) else "no joint carries a torque", joints=list(joints),
                 start=1.0), joints


def periodic_block(J, terms):
    """Joint J's errors periodic in its controller angle (tracker_periodic.py
    found the periods ``terms``, [{period_deg, period_ci95_deg, ...}]): a sin
    and a cos amplitude (rad) per period."""
    periods = [t["period_deg"] for t in terms]
    params = [(f"{ab}@{P:.4g}deg", "mrad", 1e3) for P in periods for ab in ("sin", "cos")]

    def columns(ev):
        L = tpd.lever(ev.Jv, ev.G, J)
        return np.concatenate([tpd.columns(ev.q_ctrl_rad[:, J], L, P) for P in periods], axis=-1)

    def amplitudes(v):
        return [float(np.hypot(v[2 * i], v[2 * i + 1])) for i in range(len(periods))]

    def plausible(v, info):
        amp = amplitudes(v)
        if max(amp) > PERIODIC_ERROR_MAX_RAD:
            return False, (f"an angle error of {max(amp) * 1e3:.3g} mrad periodic in joint {J + 1}'s angle: a joint "
                           f"that wobbles by {np.rad2deg(max(amp)):.2g} deg would be seen; more likely another effect")
        beyond = [f"{a * 1e3:.3g} mrad every {P:.4g} deg" for a, P in zip(amp, periods) if a > tpd.TYPICAL_MAX_RAD]
        if beyond:
            return True, ("beyond the typical few tenths of a mrad of a reducer or encoder (" + ", ".join(beyond)
                          + "): check the joint's reducer and encoder")
        return True, f"amplitudes within a reducer's or encoder's typical {tpd.TYPICAL_MAX_RAD * 1e3:g} mrad"

    def describe(v, info):
        parts = []
        for t, a in zip(terms, amplitudes(v)):
            ci = t.get("period_ci95_deg")
            rng = f" (95 %: {ci[0]:.4g}-{ci[1]:.4g})" if ci else ""
            what = (f"harmonic of {t['harmonic_of']:.4g} deg" if t.get("harmonic_of") else "reducer or encoder")
            parts.append(f"joint {J + 1}: an angle error periodic every {t['period_deg']:.4g} deg{rng}, "
                         f"{a * 1e3:.3g} mrad: {what}")
        return "; ".join(parts)

    return Block(f"periodic_j{J + 1}", "base", params, columns, describe, plausible,
                 periodic=[dict(t, joint=J) for t in terms])


def base_tilt_block():
    params = [("c", "rad/(N*m)", 1.0)]

    def columns(ev):
        theta = np.column_stack([ev.moment[:, 0], ev.moment[:, 1], np.zeros(len(ev.p))])
        return np.cross(theta, ev.p)[:, :, None]

    def plausible(v, info):
        if v[0] < 0:
            return False, "needs a negative compliance (non-physical)"
        return pl.within(v, pl.BASE_TILT_COMPLIANCE_MAX, "base tilt compliance", "rad/(N*m)", 1.0)

    return Block("base_tilt", "base", params, columns,
                 lambda v, info: f"the base tilts under the arm's weight: compliance {v[0]:.3g} rad/(N*m)", plausible)


def _vector_block(name, frame, unit, scale, text, variable, bound, needs, kind="cause", total=None):
    params = [(f"v_{a}", unit, scale) for a in "xyz"]

    def columns(ev):
        x = variable(ev)
        return np.stack([np.outer(x, np.eye(3)[k]) for k in range(3)], axis=-1)

    def plausible(v, info):
        size = np.linalg.norm(v) * (total(info["ev"]) if total else 1.0)
        return pl.within([size], bound, text if total is None else "total over the campaign",
                         "mm" if total else unit, 1e3 if total else scale)

    return Block(name, frame, params, columns, lambda v, info: f"{text}: {_fmt(v, params)}", plausible, needs, kind)


def thermal_expansion_block():
    params = [("kappa", "ppm/K", 1e6)]
    return Block("thermal_expansion", "base", params, lambda ev: (ev.dtemp[:, None] * ev.p)[:, :, None],
                 lambda v, info: f"the arm grows with temperature: {v[0] * 1e6:.3g} ppm/K",
                 lambda v, info: pl.within(v, THERMAL_EXPANSION_MAX_PER_K, "thermal expansion", "ppm/K", 1e6),
                 needs=lambda ev: None if ev.dtemp is not None and np.ptp(ev.dtemp) >= 0.2
                 else "no temp_c column, or the temperature varies less than 0.2 K")


def blocks(ev, free):
    """Every block the campaign can be searched for, in a fixed order."""
    comp, _ = joint_compliance_block(ev)
    temp_needs = (lambda e: None if e.dtemp is not None and np.ptp(e.dtemp) >= 0.2
                  else "no temp_c column, or the temperature varies less than 0.2 K")
    time_needs = lambda e: None if e.t_h is not None and np.ptp(e.t_h) > 0 else "no t_s column"  # noqa: E731
    out = [geometry_block("joint_offsets", ("theta",), free, "the joints' zero offsets"),
           geometry_block("link_lengths", ("d", "a"), free, "link length errors"),
           geometry_block("link_twists", ("alpha", "beta"), free, "link twist errors (alpha; beta between "
                          "nearly parallel axes)"),
           comp]
    out += [base_tilt_block(), thermal_expansion_block(),
            _vector_block("thermal_drift", "instrument", "mm/K", 1e3, "the instrument moves against the base with "
                          "temperature", lambda e: e.dtemp, THERMAL_DRIFT_MAX_M_PER_K, temp_needs),
            _vector_block("time_drift", "instrument", "mm/h", 1e3, "drift in time", lambda e: e.t_h,
                          TIME_DRIFT_MAX_M_PER_H, time_needs),
            _vector_block("time_drift_quadratic", "instrument", "mm/h^2", 1e3, "drift growing with the square of "
                          "time", lambda e: e.t_h**2 - np.mean(e.t_h**2), DRIFT_TOTAL_MAX_M, time_needs,
                          total=lambda e: float(np.ptp(e.t_h**2))),
            _vector_block("seq_drift", "instrument", "mm per 1000 measurements", 1e3, "drift with measurement order",
                          lambda e: e.seq, DRIFT_TOTAL_MAX_M,
                          lambda e: None if e.seq is not None and e.t_h is None else
                          ("no seq column" if e.seq is None else "the file has t_s (time_drift)"),
                          total=lambda e: float(np.ptp(e.seq))),
            _vector_block("order_trend", "instrument", "mm per 1000 rows", 1e3, "a trend along the file's order "
                          "(no t_s or seq: not known to be the order of measurement)", lambda e: e.order,
                          DRIFT_TOTAL_MAX_M, lambda e: None if e.seq is None and e.t_h is None else
                          "the file has t_s or seq", kind="trend", total=lambda e: float(np.ptp(e.order)))]
    return out


def geometry_values(block, values):
    """{(link, kind): value SI} of a geometry block's parameters."""
    return dict(zip(block.geo, values))


__all__ = ["Block", "Eval", "blocks", "geometry_values", "GEOM"]
