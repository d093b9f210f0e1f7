"""Effects that the conventional six-spring model lacks, as parametric
extensions of it.  ``robstiff synth`` switches them on to make campaigns
that carry an effect nobody declared; the residual diagnosis fits them.

Plain numpy.  Every effect is a function

    extra_displacement(ctx, params) -> (N, 3) m

that returns what the effect adds to the conventional model's tool-point
displacement for a campaign described by ``ctx`` (an EffectContext).
``default_shape(name, rng)`` gives a unit parameter set of the physically
expected form, which synth scales to a chosen RMS size.
"""

from dataclasses import dataclass

import numpy as np

from robstiff_drake.model import kinematics as kin

TAU_REF_NM = 1000.0  # torque scale of load_dependent_stiffness (N*m)


@dataclass
class EffectContext:
    """A campaign as the effects see it (SI units, base frame)."""

    dh: object
    joint_stiffness_Nm_per_rad: np.ndarray  # (6,)
    q_rad: np.ndarray  # (N, 6)
    wrench: np.ndarray  # (N, 6) as reported (N, N*m at the model tool point)
    seq: np.ndarray  # (N,) measurement order
    tool_m: np.ndarray  # (3,) the model's tool point, flange frame

    def __post_init__(self):
        self.J = kin.jacobian(self.dh, self.q_rad, self.tool_m)
        self.tau = np.einsum("nrj,nr->nj", self.J, self.wrench)
        self.c = 1.0 / np.asarray(self.joint_stiffness_Nm_per_rad, dtype=float)

    def disp_from_dq(self, dq):
        """Tool-point displacement (m) of joint deflections dq (N, 6)."""
        return np.einsum("nrj,nj->nr", self.J[:, :3, :], dq)

    def disp_from_wrench(self, wrench):
        """Conventional-model displacement (m) of a wrench (N, 6) at the tool."""
        tau = np.einsum("nrj,nr->nj", self.J, wrench)
        return self.disp_from_dq(tau * self.c)


def lost_motion(ctx, p):
    """Backlash / hysteresis: dq_i += b_i sign(tau_i).  p['b_rad'] (6,)."""
    return ctx.disp_from_dq(np.asarray(p["b_rad"]) * np.sign(ctx.tau))


def joint_coupling(ctx, p):
    """Off-diagonal joint compliance c_23 (rad/(N*m)): dq2 += c23 tau3, dq3 += c23 tau2."""
    dq = np.zeros_like(ctx.tau)
    dq[:, 1] = p["c23_rad_per_Nm"] * ctx.tau[:, 2]
    dq[:, 2] = p["c23_rad_per_Nm"] * ctx.tau[:, 1]
    return ctx.disp_from_dq(dq)


def load_dependent_stiffness(ctx, p):
    """c_i(tau) = c_i (1 + beta_i |tau_i| / 1000 N*m); beta < 0 stiffens."""
    beta = np.asarray(p["beta"])
    return ctx.disp_from_dq(ctx.c * beta * np.abs(ctx.tau) / TAU_REF_NM * ctx.tau)


def posture_dependent_stiffness(ctx, p):
    """c_2(q) = c_2 (1 + gamma * q2[rad]) (the axis-2 balancing unit)."""
    dq = np.zeros_like(ctx.tau)
    dq[:, 1] = ctx.c[1] * p["gamma_per_rad"] * ctx.q_rad[:, 1] * ctx.tau[:, 1]
    return ctx.disp_from_dq(dq)


def geometric_stiffness(ctx, p):
    """The CCT term: dq = (K_q - lambda K_g)^-1 J^T F instead of C_q J^T F
    (lambda = 1 is the physical term for the campaign's loads)."""
    lam = p["lambda"]
    out = np.empty((len(ctx.q_rad), 3))
    K = np.diag(1.0 / ctx.c)
    for n, (q, W) in enumerate(zip(ctx.q_rad, ctx.wrench)):
        K_g = kin.geometric_stiffness(ctx.dh, q, W, ctx.tool_m)
        dq = np.linalg.solve(K - lam * K_g, ctx.tau[n]) - ctx.c * ctx.tau[n]
        out[n] = ctx.J[n, :3, :] @ dq
    return out


def forearm_axis(ctx):
    """Unit vector along the forearm (z axis of DH frame 3), (N, 3)."""
    return kin.frames(ctx.dh, ctx.q_rad)[:, 3, :3, 2]


def link_compliance(ctx, p):
    """Forearm bending: the tool moves by c_L times the force across the
    forearm, c_L in m/N (a cantilever's L^3 / 3EI)."""
    u = forearm_axis(ctx)
    F = ctx.wrench[:, :3]
    F_perp = F - np.sum(F * u, axis=1, keepdims=True) * u
    return p["c_link_m_per_N"] * F_perp


def force_frame_rotation(ctx, p):
    """The reported wrench is in a frame turned by the small rotation phi
    (rad) from the base: true W = W + phi x W (force and moment)."""
    phi = np.asarray(p["phi_rad"])
    W = ctx.wrench
    extra = np.hstack([np.cross(phi, W[:, :3]), np.cross(phi, W[:, 3:])])
    return ctx.disp_from_wrench(extra)


def force_bias(ctx, p):
    """A constant offset b (N) in the reported force: true F = F + b."""
    extra = np.zeros_like(ctx.wrench)
    extra[:, :3] = np.asarray(p["bias_N"])
    return ctx.disp_from_wrench(extra)


def tool_offset(ctx, p):
    """The loaded (and measured) point is the model's tool point plus
    delta (m, flange frame)."""
    tool = ctx.tool_m + np.asarray(p["delta_m"])
    J = kin.jacobian(ctx.dh, ctx.q_rad, tool)
    tau = np.einsum("nrj,nr->nj", J, ctx.wrench)
    d_true = np.einsum("nrj,nj->nr", J[:, :3, :], tau * ctx.c)
    return d_true - ctx.disp_from_wrench(ctx.wrench)


def drift(ctx, p):
    """A displacement offset growing with measurement order: v * seq (m)."""
    return np.asarray(ctx.seq, dtype=float)[:, None] * np.asarray(p["v_m_per_step"])[None, :]


EFFECTS = {
    "lost_motion": lost_motion,
    "joint_coupling": joint_coupling,
    "load_dependent_stiffness": load_dependent_stiffness,
    "posture_dependent_stiffness": posture_dependent_stiffness,
    "geometric_stiffness": geometric_stiffness,
    "link_compliance": link_compliance,
    "force_frame_rotation": force_frame_rotation,
    "force_bias": force_bias,
    "tool_offset": tool_offset,
    "drift": drift,
}


def _unit(rng):
    v = rng.normal(size=3)
    return v / np.linalg.norm(v)


def default_shape(name, rng):
    """A unit parameter set of the expected physical form for effect ``name``
    (scaled by synth to the requested size)."""
    if name == "lost_motion":
        return {"b_rad": np.array([1.0, 1.0, 1.0, 0.0, 0.0, 0.0]) * rng.uniform(0.5, 1.5, 6) * 1e-5}
    if name == "joint_coupling":
        return {"c23_rad_per_Nm": 1e-7}
    if name == "load_dependent_stiffness":
        return {"beta": -np.array([1.0, 1.0, 1.0, 0.0, 0.0, 0.0]) * rng.uniform(0.5, 1.5, 6) * 0.1}
    if name == "posture_dependent_stiffness":
        return {"gamma_per_rad": 1.0}
    if name == "geometric_stiffness":
        return {"lambda": 10.0}
    if name == "link_compliance":
        return {"c_link_m_per_N": 1e-7}
    if name == "force_frame_rotation":
        return {"phi_rad": _unit(rng) * 0.01}
    if name == "force_bias":
        return {"bias_N": _unit(rng) * 10.0}
    if name == "tool_offset":
        return {"delta_m": _unit(rng) * 0.01}
    if name == "drift":
        return {"v_m_per_step": _unit(rng) * 1e-7}
    raise KeyError(name)


def scale_params(params, s):
    return {k: np.asarray(v) * s for k, v in params.items()}


def base_regressor(ctx):
    """The conventional model's columns for this campaign (3N, 6): the
    displacement per unit change of each joint compliance."""
    A = ctx.J[:, :3, :] * ctx.tau[:, None, :]
    return A.reshape(-1, 6)


def unexplained(extra, A):
    """The part of a displacement set (N, 3) that no change of the joint
    compliances can explain (its residual after the least-squares fit of A)."""
    y = extra.reshape(-1)
    norms = np.linalg.norm(A, axis=0)
    keep = norms > 1e-12 * max(norms.max(), 1e-300)
    An = A[:, keep] / norms[keep]
    coef, *_ = np.linalg.lstsq(An, y, rcond=None)
    return (y - An @ coef).reshape(extra.shape)


def sized_effect(name, ctx, rms_m, rng, visible=True):
    """Parameters of effect ``name`` scaled so that its displacement has the
    RMS ``rms_m`` (m) over the campaign's components; with ``visible`` the
    RMS of the part the six-spring model cannot absorb by refitting its
    compliances (what a residual diagnosis can see at all).  Returns
    (params, extra displacement, (raw RMS, unexplained RMS) in m)."""
    fn = EFFECTS[name]
    params = default_shape(name, rng)
    A = base_regressor(ctx)

    def size(extra):
        part = unexplained(extra, A) if visible else extra
        return float(np.sqrt(np.mean(part**2)))

    s = 1.0
    for _ in range(4):  # linear effects converge at once; the others in a few steps
        extra = fn(ctx, scale_params(params, s))
        rms = size(extra)
        if rms <= 1e-9 * max(float(np.sqrt(np.mean(extra**2))), 1e-300):
            raise ValueError(f"effect {name} cannot show in this campaign: the six joint springs absorb all of it "
                             "(too few poses or load directions)")
        s *= rms_m / rms
    params = scale_params(params, s)
    extra = fn(ctx, params)
    return params, extra, (float(np.sqrt(np.mean(extra**2))), size(extra) if visible else
                           float(np.sqrt(np.mean(unexplained(extra, A)**2))))
