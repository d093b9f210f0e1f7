"""The candidate causes of a machining run's residual (identification/runs/
diagnosis.py's docstring lists them): each a deviation of the tool's
height along the run per unit parameter, with its parameters' units and
bounds (identification/runs/causes.py fits and tests them).  Plain numpy."""

from dataclasses import dataclass

import numpy as np

from robstiff_drake.identification.runs.signals import (
    GRID_HZ, gear_law_deviation, play_crossing_deviation, play_relay_deviation,
)
from robstiff_drake.model.transmission import fallback_take_up_Nm, gap_friction_Nm

LOOP = "loop_lag"  # the loop's tracking error: always in the model, its fix offered when it matters
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
