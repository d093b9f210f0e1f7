"""The model of an absolute-position (tracker) campaign: the arm's
kinematics with small geometric errors, the instrument's registration, the
measured point on the flange, and displacements added to the rigid arm's
(sag under gravity, transmission error, base tilt, thermal and time drift).
Plain numpy; no Drake.

    m_i = R (p(q_i; geometry, u) + dp_i) + t + dm_i

R, t: the registration (base frame to instrument frame); u: the measured
point on the flange (flange frame, m); geometry: deltas of the canonical
chain's (theta, d, a, alpha, beta) per link (model/robot.py's DH, with
Hayati's beta where consecutive axes are nearly parallel); dp_i: the
base-frame displacement of the linear effects (columns times coefficients);
dm_i: instrument-frame ones (the tracker or the floor moving).

Derivatives are analytic: a joint angle turns the tool point about z_i
through o_i, d moves it along z_i, a along the link's x axis before its
twist (u_i), alpha turns it about u_i and beta about y_{i+1}, both through
o_{i+1}; R by small rotations, t and u linearly.  Gravity torques come from
the robot file's masses (links and payload), with gravity along the
instrument's -z seen in the base frame when the registration says the two
vertical axes are within LEVEL_DEG (ASSUMPTION: a tracker is levelled to
gravity, as its users do; a base set 0.3 deg off level turns a 3 mm sag's
gravity by 0.5 %, 15 um), else along the base frame's -z (ASSUMPTION: the
robot stands on the floor; a wall- or ceiling-mounted arm needs its base
frame turned).
"""

from dataclasses import replace

import numpy as np

from robstiff_drake.model.robot import GRAVITY_BASE_M_PER_S2

GEOM = ("theta", "d", "a", "alpha", "beta")
GEOM_UNITS = {"theta": ("deg", np.rad2deg(1.0)), "d": ("mm", 1e3), "a": ("mm", 1e3),
              "alpha": ("deg", np.rad2deg(1.0)), "beta": ("deg", np.rad2deg(1.0))}
PARALLEL_SIN = np.sin(np.deg2rad(10.0))
LEVEL_DEG = 5.0


def cross(a, b):
    """a x b along the last axis (broadcast): np.cross's products and
    differences, without its general-shape handling and copies (the fit
    makes hundreds of them over every row)."""
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    return np.stack(np.broadcast_arrays(a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0), axis=-1)


def gravity_in_base(R):
    """Gravity (m/s^2) in the base frame of a registration R (base to
    instrument): the instrument's -z when it is within LEVEL_DEG of the
    base's (a levelled tracker), else the base's -z."""
    down = R.T @ np.array([0.0, 0.0, -1.0])
    if np.degrees(np.arccos(np.clip(-down[2], -1.0, 1.0))) <= LEVEL_DEG:
        return down * np.linalg.norm(GRAVITY_BASE_M_PER_S2)
    return np.array(GRAVITY_BASE_M_PER_S2, dtype=float)  # consecutive axes this close to parallel get Hayati's beta


def geometry_params(robot):
    """[(link, kind)] of the canonical chain's parameters the search may
    correct (and a robot file can hold): every theta, d, a, alpha; beta
    where the link's axes are nearly parallel; for a modified-DH file not
    the last link's a, alpha, beta (the table has no row for them; the
    measured point absorbs them)."""
    out = []
    modified = robot.convention == "modified_dh"
    for k in range(6):
        for kind in GEOM:
            if kind == "beta" and abs(np.sin(robot.dh.alpha_rad[k])) > PARALLEL_SIN:
                continue
            if modified and k == 5 and kind in ("a", "alpha", "beta"):
                continue
            out.append((k, kind))
    return out


def perturbed_dh(dh, delta):
    """The chain with geometric deltas (6, 5) added, SI (GEOM order)."""
    delta = np.asarray(delta, dtype=float)
    beta0 = np.zeros(6) if dh.beta_rad is None else dh.beta_rad
    beta = beta0 + delta[:, 4]
    return replace(dh, home_rad=dh.home_rad + delta[:, 0], d_m=dh.d_m + delta[:, 1], a_m=dh.a_m + delta[:, 2],
                   alpha_rad=dh.alpha_rad + delta[:, 3], beta_rad=beta if np.any(beta) else None)


def tool_points(T, u):
    """(N, 3) the point u (flange frame) in the base frame, from frames T (N, 7, 3 or 4, 4)."""
    return T[:, 6, :3, 3] + T[:, 6, :3, :3] @ u


def jacobian_v(T, p):
    """(N, 3, 6) linear Jacobian of the point p (N, 3) from frames T."""
    z = T[:, :6, :3, 2]
    o = T[:, :6, :3, 3]
    return np.swapaxes(cross(z, p[:, None, :] - o), 1, 2)


def geometry_jacobian(T, p, dh):
    """(N, 3, 6, 5): d p / d (link, GEOM kind) at frames T (a view of an
    (N, 6, 5, 3) array: each derivative is written as whole rows)."""
    N = len(p)
    out = np.empty((N, 6, 5, 3))
    beta = np.zeros(6) if dh.beta_rad is None else dh.beta_rad
    for k in range(6):
        z, o = T[:, k, :3, 2], T[:, k, :3, 3]
        R1, o1 = T[:, k + 1, :3, :3], T[:, k + 1, :3, 3]
        u = R1 @ np.array([np.cos(beta[k]), 0.0, np.sin(beta[k])])  # x after Rz(theta), before Ry(beta)
        y1 = R1[:, :, 1]
        out[:, k, 0] = cross(z, p - o)
        out[:, k, 1] = z
        out[:, k, 2] = u
        out[:, k, 3] = cross(u, p - o1)
        out[:, k, 4] = cross(y1, p - o1)
    return out.transpose(0, 3, 1, 2)


def gravity(robot, T, q, applied_force_N=None, tool_m=None, g_base=None):
    """Joint torques (N, 6) N*m of the arm's own weight (links and payload,
    robot file) on the model's joints, as generalized forces (the load's
    torque, dq = C tau), and the moment (N, 3) N*m of that weight about the
    base origin; with ``applied_force_N`` (N, 3) at ``tool_m`` (flange), its
    torques and moment are added.  ``g_base``: gravity in the base frame
    (m/s^2; default straight down the base's -z)."""
    g = GRAVITY_BASE_M_PER_S2 if g_base is None else np.asarray(g_base, dtype=float)
    theta = q + robot.dh.home_rad
    bodies_c, bodies_m = [], []
    for i in range(1, 7):
        link = robot.links[i]
        c, s = np.cos(theta[:, i - 1]), np.sin(theta[:, i - 1])
        com = link.com_m
        local = np.column_stack([c * com[0] - s * com[1], s * com[0] + c * com[1], np.full_like(c, com[2])])
        bodies_c.append(T[:, i - 1, :3, 3] + np.einsum("nij,nj->ni", T[:, i - 1, :3, :3], local))
        bodies_m.append(link.mass_kg)
    bodies_c.append(T[:, 6, :3, 3] + T[:, 6, :3, :3] @ robot.payload.com_m)
    bodies_m.append(robot.payload.mass_kg)
    forces = [(c, np.broadcast_to(m * g, c.shape)) for c, m in zip(bodies_c, bodies_m)]
    if applied_force_N is not None:
        forces.append((tool_points(T, np.zeros(3) if tool_m is None else tool_m), np.asarray(applied_force_N)))
    # each body's force and moment about the base origin, summed from the hand back: joint j carries the
    # bodies beyond it, tau_j = z_j . (sum c x f - o_j x sum f)
    body_of = [min(k, 5) for k in range(len(forces))]  # the payload and an applied force act beyond joint 6
    S_M = np.zeros((len(q), 3))
    S_F = np.zeros((len(q), 3))
    tau = np.zeros((len(q), 6))
    k = len(forces) - 1
    for j in range(5, -1, -1):
        while k >= 0 and body_of[k] >= j:
            c, f = forces[k]
            S_M += cross(c, f)
            S_F += f
            k -= 1
        z, o = T[:, j, :3, 2], T[:, j, :3, 3]
        tau[:, j] = np.sum(z * (S_M - cross(o, S_F)), axis=1)
    return tau, S_M.copy()
