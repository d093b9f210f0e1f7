"""The open dictionary of the residual diagnosis: physically meaningful terms
beyond the named library, searched when the named candidates leave a
structured residual.  Plain numpy; no Drake.

For each of the six joints j:
  * backlash_jJ          lost motion: dq_j += b tanh(tau_j / tau0), tau0 from a grid
  * nonlinear_stiffness_jJ  odd cubic law: dq_j += a c_j (tau_j / tau_max)^2 tau_j
                          (a > 0 softening, a < 0 hardening)
  * angle_compliance_jJ  compliance varying smoothly with its own angle:
                          dq_j += c_j tau_j (a1 P1(x_j) + a2 P2(x_j) + a3 P3(x_j)),
                          x_j = q_j scaled to [-1, 1] over the campaign, P Legendre
  * angle_compliance_jJ_qK  ... and linearly with another joint's angle q_k
  * hysteresis_jJ        dependence on the previous loads (a play held by friction):
                          dq_j += h_load s_after + h_reference s_pose, s_after the side
                          (sign of tau_j) of the last load so far above a friction
                          torque tau_f (from a grid), s_pose that side when the row's
                          pose began (its unloaded reading); one play gives
                          h_reference = -h_load
and for every pair j < k (2-3 is the named joint_coupling):
  * coupling_jJK         dq_j += c tau_k, dq_k += c tau_j
Outside the joints:
  * base_tilt            the base tilts on its foundation about horizontal
                          axes through the base origin: theta = c (M_x, M_y, 0)
  * base_shear           the base slides: d += c F
  * turret_bending, lower_arm_bending, upper_arm_bending, forearm_bending,
    lower_arm_torsion    a link bends (or twists) as a virtual joint a third of
                          the way along it
The measurement:
  * measurement_frame_rotation  displacements measured in a frame turned by phi
  * measured_point_offset       the measured point is delta (flange frame) from
                                the loaded point: it also moves with the flange's
                                rotation
  * displacement_offset  a constant offset of the displacements
  * drift_quadratic      drift that grows with the square of measurement order
A translation of the measuring frame against the base cancels in loaded-minus-
unloaded displacements, so it has no term; a constant displacement offset does.
The loads' history, the force sensor's crosstalk, the load's size, periodic
drift and trends along the file's order are in dictionary_loads.py.

Every term carries its plausibility check (identification/diagnosis/plausibility.py).
"""

import numpy as np

from robstiff_drake.identification.diagnosis import plausibility as pl
from robstiff_drake.identification.diagnosis.terms import BILINEAR, GAUSS_NEWTON, GRID, LINEAR, Term, stack

BACKLASH_TAU0_FRACTIONS = (0.01, 0.02, 0.05, 0.1, 0.2, 0.4)  # transition torque / largest |tau_j| of the campaign
HYSTERESIS_FRICTION_FRACTIONS = (0.0, 0.01, 0.02, 0.05, 0.1, 0.2)  # torque that moves a held joint / largest |tau_j|
MIN_ANGLE_RANGE_DEG = 1.0  # an angle that varies less than this cannot carry a dependence


def _tau_max(ctx, j):
    return float(np.max(np.abs(ctx.tau[:, j])))


def _scaled_angle(ctx, j):
    """The model's angle of joint j scaled to [-1, 1] over the campaign, and
    the range of the controller's angle q_j in the file (deg)."""
    q = ctx.q[:, j]
    lo, hi = float(q.min()), float(q.max())
    half = 0.5 * (hi - lo)
    q_file = np.asarray(ctx.campaign.q_deg)[:, j]
    return (q - 0.5 * (lo + hi)) / max(half, 1e-12), (float(q_file.min()), float(q_file.max()))


def _dq_col(ctx, j, values):
    dq = np.zeros_like(ctx.tau)
    dq[:, j] = values
    return ctx.from_dq(dq)


def _needs_torque(j):
    return lambda ctx: None if _tau_max(ctx, j) > 0 else f"the loads give joint {j + 1} no torque"


def _needs_angle(j, k=None):
    def needs(ctx):
        if _tau_max(ctx, j) == 0:
            return f"the loads give joint {j + 1} no torque"
        span = np.ptp(np.rad2deg(ctx.q[:, j if k is None else k]))
        if span < MIN_ANGLE_RANGE_DEG:
            return f"q{(j if k is None else k) + 1} varies only {span:.2g} deg in this campaign"
        return None
    return needs


def _needs_seq(ctx):
    return None if ctx.seq is not None else "the file has no seq column (measurement order)"


# -------------------------------------------------------------- joints


def _backlash(j):
    def grid(ctx):
        return [f * _tau_max(ctx, j) for f in BACKLASH_TAU0_FRACTIONS]

    def columns(ctx, g):
        return stack([_dq_col(ctx, j, np.tanh(ctx.tau[:, j] / g))])

    def describe(v, info):
        return (f"joint {j + 1} lost motion (backlash): b = {v[0] * 1e6:.3g} urad, taken up over "
                f"{info['g']:.3g} N*m of torque")

    return Term(f"backlash_j{j + 1}", "dictionary", GRID, [("b", "urad", 1e6)], columns=columns, grid=grid,
                grid_param=("tau0", "N*m", 1.0), describe=describe,
                plausible=lambda v, info: pl.within(v, pl.LOST_MOTION_MAX_RAD, "lost motion", "urad", 1e6),
                needs=_needs_torque(j))


def _nonlinear(j):
    def shape(ctx):
        tm = _tau_max(ctx, j)
        return (ctx.tau[:, j] / tm) ** 2

    def columns(ctx):
        return stack([_dq_col(ctx, j, ctx.c_nom[j] * shape(ctx) * ctx.tau[:, j])])

    def describe(v, info):
        rel = v[0] * info["ctx"].c_nom[j] / info["c"][j]
        word = "softens" if rel > 0 else "hardens"
        return (f"joint {j + 1}'s stiffness {word} with torque (cubic law): compliance {100 * rel:+.3g} % at "
                f"{_tau_max(info['ctx'], j):.3g} N*m")

    def plausible(v, info):
        return pl.compliance_ratio(info["c"][j], v[0] * info["ctx"].c_nom[j] * shape(info["ctx"]))

    return Term(f"nonlinear_stiffness_j{j + 1}", "dictionary", LINEAR, [("a", "x nominal compliance", 1.0)],
                columns=columns, describe=describe, plausible=plausible, needs=_needs_torque(j))


def _angle(j, k=None):
    own = k is None
    kk = j if own else k

    def basis(ctx):
        x, _ = _scaled_angle(ctx, kk)
        return [x, 1.5 * x**2 - 0.5, 2.5 * x**3 - 1.5 * x] if own else [x]

    def columns(ctx):
        return stack([_dq_col(ctx, j, ctx.c_nom[j] * ctx.tau[:, j] * b) for b in basis(ctx)])

    def variation(v, info):
        return info["ctx"].c_nom[j] * sum(a * b for a, b in zip(v, basis(info["ctx"])))

    def describe(v, info):
        dc = variation(v, info)
        _, (lo, hi) = _scaled_angle(info["ctx"], kk)
        c = info["c"][j]
        return (f"joint {j + 1}'s compliance varies with q{kk + 1}: {100 * dc.min() / c:+.3g} to "
                f"{100 * dc.max() / c:+.3g} % over q{kk + 1} = {lo:.0f}..{hi:.0f} deg")

    name = f"angle_compliance_j{j + 1}" + ("" if own else f"_q{k + 1}")
    params = [(f"a{i}", "x nominal compliance", 1.0) for i in (1, 2, 3)] if own else \
        [("a", "x nominal compliance per half range", 1.0)]
    return Term(name, "dictionary", LINEAR, params, columns=columns, describe=describe,
                plausible=lambda v, info: pl.compliance_ratio(info["c"][j], variation(v, info)),
                needs=_needs_angle(j, k))


def _held_sides(ctx, j, tau_f):
    """Per row (in seq order): the side of joint j's play after the row's load
    (the sign of the last load so far whose |tau_j| exceeded tau_f: friction
    holds the link where a load put it), and the side when the row's pose
    began (what its unloaded reading saw)."""
    order = np.argsort(ctx.seq, kind="stable")
    after, at_pose = np.zeros(ctx.n), np.zeros(ctx.n)
    side, pose_side = 0.0, {}
    for row in order:
        g = ctx.groups[row]
        if g not in pose_side:
            pose_side[g] = side
        if abs(ctx.tau[row, j]) > tau_f:
            side = np.sign(ctx.tau[row, j])
        after[row], at_pose[row] = side, pose_side[g]
    return after, at_pose


def _hysteresis(j):
    def grid(ctx):
        return [f * _tau_max(ctx, j) for f in HYSTERESIS_FRICTION_FRACTIONS]

    def columns(ctx, g):
        after, at_pose = _held_sides(ctx, j, g)
        return stack([_dq_col(ctx, j, after), _dq_col(ctx, j, at_pose)])

    def describe(v, info):
        held = f"loads above {info['g']:.3g} N*m move it" if info["g"] > 0 else "every load moves it"
        return (f"joint {j + 1} play held by friction ({held}): the link sits {v[0] * 1e6:+.3g} urad toward the "
                f"side the last load left it on, each pose's unloaded reading {v[1] * 1e6:+.3g} urad")

    def needs(ctx):
        if ctx.seq is None:
            return "the file has no seq column (measurement order)"
        return _needs_torque(j)(ctx)

    return Term(f"hysteresis_j{j + 1}", "dictionary", GRID, [("h_load", "urad", 1e6), ("h_reference", "urad", 1e6)],
                columns=columns, grid=grid, grid_param=("tau_friction", "N*m", 1.0), describe=describe,
                plausible=lambda v, info: pl.within(v, pl.LOST_MOTION_MAX_RAD, "play", "urad", 1e6), needs=needs)


def _coupling(j, k):
    def columns(ctx):
        dq = np.zeros_like(ctx.tau)
        dq[:, j], dq[:, k] = ctx.tau[:, k], ctx.tau[:, j]
        return stack([ctx.from_dq(dq * np.sqrt(ctx.c_nom[j] * ctx.c_nom[k]))])

    def rho(v, info):
        prod = info["c"][j] * info["c"][k]
        if prod <= 0:
            return float("inf")
        return float(v[0]) * np.sqrt(info["ctx"].c_nom[j] * info["ctx"].c_nom[k] / prod)

    def describe(v, info):
        c = float(v[0]) * np.sqrt(info["ctx"].c_nom[j] * info["ctx"].c_nom[k])
        return (f"joints {j + 1} and {k + 1} coupled: c{j + 1}{k + 1} = {c:.3g} rad/(N*m), "
                f"{rho(v, info):+.2f} of sqrt(c{j + 1} c{k + 1})")

    def plausible(v, info):
        r = abs(rho(v, info))
        ok = r <= pl.COUPLING_MAX
        pd = f"; {pl.NON_PHYSICAL}: the compliance matrix is not positive definite" if r >= 1 else ""
        return ok, f"coupling {r:.2f} of sqrt(cj ck) ({'within' if ok else 'beyond'} {pl.COUPLING_MAX:g}{pd})"

    return Term(f"coupling_j{j + 1}{k + 1}", "dictionary", LINEAR, [("rho", "x sqrt(cj ck) nominal", 1.0)],
                columns=columns, describe=describe, plausible=plausible,
                needs=lambda ctx: _needs_torque(j)(ctx) or _needs_torque(k)(ctx))


# -------------------------------------------------------------- structure


def _base_moment(ctx):
    """Moment of the applied wrench about the base origin (N*m), (N, 3)."""
    return np.cross(ctx.p_tool, ctx.W[:, :3]) + ctx.W[:, 3:]


def _base_tilt(ctx):
    M = _base_moment(ctx)
    theta = np.column_stack([M[:, 0], M[:, 1], np.zeros(ctx.n)])
    return stack([np.cross(theta, ctx.p_tool)])


def _base_shear(ctx):
    return stack([ctx.W[:, :3]])


# Each link as the segment between DH frame origins i and i + 1: the turret
# (base to the axis-2 point), the lower arm (axis 2 to axis 3), the upper arm
# (axis 3 to the forearm's root) and the forearm (along z3 to the wrist centre).
LINKS = {"turret": 0, "lower_arm": 1, "upper_arm": 2, "forearm": 3}


def _link_segment(ctx, which):
    """(pivot, unit axis) of a link, (N, 3) each: the pivot a third of the way
    from its root (a cantilever's tip moves as if it turned about that point)."""
    T = ctx.frames
    a, b = T[:, LINKS[which], :3, 3], T[:, LINKS[which] + 1, :3, 3]
    u = (b - a) / np.linalg.norm(b - a, axis=1, keepdims=True)
    return a + (b - a) / 3.0, u


def _link_moment(ctx, which):
    pivot, u = _link_segment(ctx, which)
    r = ctx.p_tool - pivot
    M = np.cross(r, ctx.W[:, :3]) + ctx.W[:, 3:]
    return M, u, r


def _bending(which):
    def columns(ctx):
        M, u, r = _link_moment(ctx, which)
        M_perp = M - np.sum(M * u, axis=1, keepdims=True) * u
        return stack([np.cross(M_perp, r)])
    return columns


def _torsion(ctx):
    M, u, r = _link_moment(ctx, "lower_arm")
    return stack([np.cross(np.sum(M * u, axis=1, keepdims=True) * u, r)])


def _compliance_term(name, text, columns, upper, unit="rad/(N*m)"):
    def describe(v, info):
        k = 1.0 / v[0] if v[0] > 0 else float("inf")
        return f"{text}: compliance {v[0]:.3g} {unit} (stiffness {k:.3g} {unit.replace('rad/(N*m)', 'N*m/rad')})" \
            if unit == "rad/(N*m)" else f"{text}: compliance {v[0] * 1e6:.3g} um/N"

    def plausible(v, info):
        if v[0] < 0:
            return False, "needs a negative compliance (non-physical)"
        return pl.within(v, upper, "compliance", unit if unit == "rad/(N*m)" else "um/N",
                         1.0 if unit == "rad/(N*m)" else 1e6)

    return Term(name, "dictionary", LINEAR, [("c", unit, 1.0)], columns=columns, describe=describe,
                plausible=plausible)


# -------------------------------------------------------------- measurement


def _rotation(phi):
    """Rotation matrix of the rotation vector phi (rad), Rodrigues."""
    a = float(np.linalg.norm(phi))
    if a < 1e-15:
        return np.eye(3)
    k = np.asarray(phi, dtype=float) / a
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(a) * K + (1 - np.cos(a)) * K @ K


def _frame_rotation(ctx, c, phi):
    """The springs' displacements read in a frame turned by phi: R(phi) d - d,
    exact in the angle (a frame from the cell drawings can be off by
    degrees, where the small-angle form phi x d leaves a residual)."""
    d = ctx.from_dq(c * ctx.tau)
    return (d @ _rotation(phi).T - d).reshape(-1)


def _point_offset(ctx, c):
    rot = ctx.rot_from_dq(c * ctx.tau)
    R6 = ctx.frames[:, 6, :3, :3]
    return stack([np.cross(rot, R6[:, :, k]) for k in range(3)])


def _offset(ctx):
    return stack([np.tile(np.eye(3)[k], (ctx.n, 1)) for k in range(3)])


def _drift2(ctx):
    s = ctx.seq - ctx.seq.min()
    return stack([np.outer(s**2, np.eye(3)[k]) for k in range(3)])


def _vec_term(name, kind, params, text, columns, bound, scale, unit, needs=None, total=None, **kw):
    def describe(v, info):
        return f"{text}: " + ", ".join(f"{n} = {x * s:.3g} {u}" for (n, u, s), x in zip(params, v))

    def plausible(v, info):
        size = np.linalg.norm(v) * (total(info["ctx"]) if total else 1.0)
        return pl.within([size], bound, text if not total else "total over the campaign", unit, scale)

    return Term(name, "dictionary", kind, params, columns=columns, describe=describe, plausible=plausible,
                needs=needs, **kw)


def build_dictionary():
    """The dictionary's terms, in a fixed order (name -> Term)."""
    terms = []
    for j in range(6):
        terms += [_backlash(j), _nonlinear(j), _angle(j)]
        terms += [_angle(j, k) for k in range(6) if k != j]
        terms.append(_hysteresis(j))
    terms += [_coupling(j, k) for j in range(6) for k in range(j + 1, 6) if (j, k) != (1, 2)]
    terms += [
        _compliance_term("base_tilt", "the base tilts on its foundation", _base_tilt, pl.BASE_TILT_COMPLIANCE_MAX),
        _compliance_term("base_shear", "the base slides on its foundation", _base_shear, pl.BASE_SHEAR_COMPLIANCE_MAX,
                         unit="m/N"),
        *[_compliance_term(f"{link}_bending", f"the {link.replace('_', ' ')} bends", _bending(link),
                           pl.LINK_BENDING_COMPLIANCE_MAX) for link in LINKS],
        _compliance_term("lower_arm_torsion", "the lower arm twists", _torsion, pl.LINK_BENDING_COMPLIANCE_MAX),
        _vec_term("measurement_frame_rotation", GAUSS_NEWTON, [(f"phi_{a}", "mrad", 1e3) for a in "xyz"],
                  "displacements measured in a frame turned against the base", None,
                  pl.FRAME_ROTATION_MAX_RAD, 1e3, "mrad", effect=_frame_rotation, step=(1e-3, 1e-3, 1e-3)),
        _vec_term("measured_point_offset", BILINEAR, [(f"delta_{a}", "mm", 1e3) for a in "xyz"],
                  "the measured point is off the loaded point (flange frame)", _point_offset,
                  pl.POINT_OFFSET_MAX_M, 1e3, "mm"),
        _vec_term("displacement_offset", LINEAR, [(f"o_{a}", "mm", 1e3) for a in "xyz"],
                  "a constant offset of the measured displacements", _offset, pl.DISPLACEMENT_OFFSET_MAX_M, 1e3,
                  "mm"),
        _vec_term("drift_quadratic", LINEAR, [(f"a_{a}", "um per measurement^2", 1e6) for a in "xyz"],
                  "drift growing with the square of measurement order", _drift2, pl.DRIFT_TOTAL_MAX_M, 1e3, "mm",
                  needs=_needs_seq, total=lambda ctx: float(np.ptp(ctx.seq)) ** 2),
    ]
    from robstiff_drake.identification.diagnosis.dictionary_loads import terms as load_terms

    terms += load_terms()
    return {t.name: t for t in terms}


DICTIONARY = build_dictionary()
