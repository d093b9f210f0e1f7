"""The named candidate library of the residual diagnosis: the effects that
``robstiff synth --effect`` can switch on (their generator is
model/effects.py), each as a Term (identification/diagnosis/terms.py) with its
physical plausibility check.  Plain numpy; no Drake.
"""

import numpy as np

from robstiff_drake.identification.diagnosis import plausibility as pl
from robstiff_drake.identification.diagnosis.terms import BILINEAR, GAUSS_NEWTON, LINEAR, Term, stack
from robstiff_drake.model import kinematics as kin

TAU_REF_NM = 1000.0  # torque scale of load_dependent_stiffness (N*m)


def _needs_seq(ctx):
    return None if ctx.seq is not None else "the file has no seq column (measurement order)"


# -- lost motion of joints 1-3: dq_j += b_j sign(tau_j)
def _lost_motion(ctx):
    return stack([ctx.from_dq(np.eye(6)[j] * np.sign(ctx.tau)) for j in range(3)])


def _lost_motion_ok(v, info):
    return pl.within(v, pl.LOST_MOTION_MAX_RAD, "lost motion", "urad", 1e6)


# -- joint 2-3 coupling: dq2 += c23 tau3, dq3 += c23 tau2
def _coupling(ctx):
    dq = np.zeros_like(ctx.tau)
    dq[:, 1], dq[:, 2] = ctx.tau[:, 2], ctx.tau[:, 1]
    return stack([ctx.from_dq(dq)])


def _coupling_ok(v, info):
    prod = info["c"][1] * info["c"][2]
    rho = abs(float(v[0])) / np.sqrt(prod) if prod > 0 else float("inf")
    ok = rho <= pl.COUPLING_23_MAX
    pd = f"; {pl.NON_PHYSICAL}: the compliance matrix is not positive definite" if rho >= 1 else ""
    return ok, f"c23 is {rho:.2f} of sqrt(c2 c3) ({'within' if ok else 'beyond'} {pl.COUPLING_23_MAX:g}{pd})"


# -- load-dependent stiffness of joints 1-3: dq_j += a_j |tau_j| tau_j / 1 kN*m
def _load_dependent(ctx):
    cols = []
    for j in range(3):
        dq = np.zeros_like(ctx.tau)
        dq[:, j] = np.abs(ctx.tau[:, j]) * ctx.tau[:, j] / TAU_REF_NM
        cols.append(ctx.from_dq(dq))
    return stack(cols)


def _load_dependent_ok(v, info):
    ctx, c = info["ctx"], info["c"]
    checks = [pl.compliance_ratio(c[j], v[j] * np.abs(ctx.tau[:, j]) / TAU_REF_NM) for j in range(3)]
    bad = [f"joint {j + 1}: {why}" for j, (ok, why) in enumerate(checks) if not ok]
    if bad:
        return False, "; ".join(bad)
    return True, "; ".join(f"joint {j + 1}: {why}" for j, (_, why) in enumerate(checks))


# -- posture-dependent stiffness of joint 2 (balancer): dq2 += g (q2 - mean q2) tau2
def _posture(ctx):
    dq = np.zeros_like(ctx.tau)
    dq[:, 1] = (ctx.q[:, 1] - ctx.q[:, 1].mean()) * ctx.tau[:, 1]
    return stack([ctx.from_dq(dq)])


def _posture_ok(v, info):
    ctx = info["ctx"]
    return pl.compliance_ratio(info["c"][1], v[0] * (ctx.q[:, 1] - ctx.q[:, 1].mean()))


# -- geometric stiffness (CCT): dq = (K - lambda K_g)^-1 tau instead of C tau
def _Kg(ctx):
    return ctx.cached("Kg", lambda: kin.geometric_stiffness(ctx.robot.dh, ctx.q, ctx.W, ctx.tool))


def _geometric_effect(ctx, c, theta):
    K = np.zeros((ctx.n, 6, 6))
    K[:, np.arange(6), np.arange(6)] = 1.0 / c
    dq = np.linalg.solve(K - theta[0] * _Kg(ctx), ctx.tau[..., None])[..., 0]
    return ctx.from_dq(dq - c * ctx.tau).reshape(-1)


def _geometric_ok(v, info):
    lo, hi = pl.GEOMETRIC_FACTOR_RANGE
    return pl.within(v, hi, "CCT factor lambda", "(1 = physics)", 1.0, lower=lo)


# -- forearm bending: the tool moves by c_L times the force across the forearm
def _link(ctx):
    u = ctx.frames[:, 3, :3, 2]
    F = ctx.W[:, :3]
    return stack([F - np.sum(F * u, axis=1, keepdims=True) * u])


def _link_ok(v, info):
    return pl.within(v, pl.LINK_COMPLIANCE_MAX_M_PER_N, "forearm compliance", "um/N", 1e6, lower=0.0)


# -- the reported wrench is in a frame turned by phi (force and moment)
def _frame_rotation(ctx, c):
    cols = []
    for k in range(3):
        e = np.eye(3)[k]
        extra = np.hstack([np.cross(e, ctx.W[:, :3]), np.cross(e, ctx.W[:, 3:])])
        cols.append(ctx.disp_of_wrench(extra, c))
    return stack(cols)


def _frame_rotation_ok(v, info):
    return pl.within([np.linalg.norm(v)], pl.FORCE_FRAME_MAX_RAD, "force frame rotation", "mrad", 1e3)


# -- a constant bias of the reported force
def _force_bias(ctx, c):
    cols = []
    for k in range(3):
        extra = np.zeros_like(ctx.W)
        extra[:, k] = 1.0
        cols.append(ctx.disp_of_wrench(extra, c))
    return stack(cols)


def _force_bias_ok(v, info):
    return pl.within([np.linalg.norm(v)], pl.FORCE_BIAS_MAX_N, "force bias", "N", 1.0)


# -- the loaded (and measured) point is the model's tool point plus delta (flange frame)
def _tool_offset_effect(ctx, c, theta):
    return (ctx.disp_of_wrench(ctx.W, c, theta) - ctx.disp_of_wrench(ctx.W, c)).reshape(-1)


def _tool_offset_ok(v, info):
    return pl.within([np.linalg.norm(v)], pl.TOOL_OFFSET_MAX_M, "tool point offset", "mm", 1e3)


# -- drift: offset v * seq
def _drift(ctx):
    cols = []
    for k in range(3):
        col = np.zeros((ctx.n, 3))
        col[:, k] = ctx.seq
        cols.append(col)
    return stack(cols)


def _drift_ok(v, info):
    return pl.within([np.linalg.norm(v)], pl.DRIFT_MAX_M_PER_MEASUREMENT, "drift", "um per measurement", 1e6)


def _fmt(values, params):
    return ", ".join(f"{n} = {v * s:.3g} {u}" for (n, u, s), v in zip(params, values))


def _named(name, kind, params, text, plausible, **kw):
    return Term(name, "library", kind, params, describe=lambda v, info: f"{text}: {_fmt(v, params)}",
                plausible=plausible, **kw)


CANDIDATES = {t.name: t for t in [
    _named("lost_motion", LINEAR, [(f"b{j + 1}", "urad", 1e6) for j in range(3)],
           "lost motion (backlash) in joints 1-3", _lost_motion_ok, columns=_lost_motion),
    _named("joint_coupling", LINEAR, [("c23", "rad/(N*m)", 1.0)], "joints 2 and 3 coupled", _coupling_ok,
           columns=_coupling),
    _named("load_dependent_stiffness", LINEAR, [(f"dc{j + 1}_per_kNm", "rad/(N*m) per kN*m", 1.0) for j in range(3)],
           "compliance of joints 1-3 grows with |torque|", _load_dependent_ok, columns=_load_dependent),
    _named("posture_dependent_stiffness", LINEAR, [("dc2_per_rad_q2", "rad/(N*m) per rad of q2", 1.0)],
           "joint 2's compliance varies with q2 (balancer)", _posture_ok, columns=_posture),
    _named("geometric_stiffness", GAUSS_NEWTON, [("lambda", "-", 1.0)], "geometric stiffness (CCT term)",
           _geometric_ok, effect=_geometric_effect, step=(1.0,)),
    _named("link_compliance", LINEAR, [("c_link", "um/N", 1e6)], "forearm bending", _link_ok, columns=_link),
    _named("force_frame_rotation", BILINEAR, [(f"phi_{a}", "mrad", 1e3) for a in "xyz"],
           "forces reported in a turned frame", _frame_rotation_ok, columns=_frame_rotation),
    _named("force_bias", BILINEAR, [(f"b_f{a}", "N", 1.0) for a in "xyz"], "constant bias of the reported force",
           _force_bias_ok, columns=_force_bias),
    _named("tool_offset", GAUSS_NEWTON, [(f"d_{a}", "mm", 1e3) for a in "xyz"],
           "loaded point off the model's tool point (flange frame)", _tool_offset_ok, effect=_tool_offset_effect,
           step=(1e-3, 1e-3, 1e-3)),
    _named("drift", LINEAR, [(f"v_{a}", "um per measurement", 1e6) for a in "xyz"], "drift with measurement order",
           _drift_ok, columns=_drift, needs=_needs_seq),
]}
