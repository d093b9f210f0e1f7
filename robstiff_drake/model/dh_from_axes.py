"""A robot file's kinematic table from a chain's joint axes (what a URDF
describes): standard Denavit-Hartenberg parameters of six revolute joints
given each joint's axis as a line in the base frame at the chain's zero
configuration, and the flange frame there.  Plain numpy.

Frame i-1's z axis is joint i's axis, pointing the way the joint turns
positively (so the joint angle is the chain's own), frame 0 the base.
For i = 1..5 the x axis of frame i runs along the common normal of the
axes of joints i and i+1: from the first to the second (a_i its length);
where the axes meet, along z_{i-1} x z_i (the sign that keeps it closer to
x_{i-1}); where they are parallel, through frame i-1's origin (d_i = 0).
Frame 6 is the flange: d_6 and a_6 place its origin, alpha_6 its z axis,
home_6 its x axis at the zero configuration.  home_i is the angle from
x_{i-1} to x_i about z_{i-1} at the zero configuration, so theta_i = q_i +
home_i with q the chain's joint angles.

Standard DH has no base transform: joint 1's axis must be the base's z
axis (either way).  Pointing down, or meeting the base x axis at right
angles away from the origin, the modified form's first row (alpha_0, a_0)
takes the base to it; any other base the robot file cannot describe
(ValueError, saying why).  Likewise a flange whose frame no DH row reaches
(its z axis neither along nor at a right angle through the axis of joint
6's common normal)."""

import numpy as np

TOL = 1e-9  # m and rad: what counts as on a line, parallel, perpendicular


def _unit(v):
    v = np.asarray(v, dtype=float)
    n = np.linalg.norm(v)
    if n < 1e-12:
        raise ValueError("a joint axis of zero length")
    return v / n


def _angle_about(a, b, axis):
    """The angle (rad) that turns unit vector a into b about ``axis``."""
    return float(np.arctan2(np.dot(np.cross(a, b), axis), np.dot(a, b)))


def _common_normal(p1, z1, p2, z2):
    """(foot on line 1, foot on line 2, kind): kind 'skew', 'meet' or 'parallel'."""
    n = np.cross(z1, z2)
    if np.linalg.norm(n) < TOL:  # parallel: through p1
        foot2 = p2 + np.dot(p1 - p2, z2) * z2
        return p1.copy(), foot2, "parallel"
    # closest points of two skew lines
    w = p1 - p2
    a, b, c, d, e = np.dot(z1, z1), np.dot(z1, z2), np.dot(z2, z2), np.dot(z1, w), np.dot(z2, w)
    den = a * c - b * b
    s = (b * e - c * d) / den
    t = (a * e - b * d) / den
    f1, f2 = p1 + s * z1, p2 + t * z2
    return f1, f2, ("meet" if np.linalg.norm(f2 - f1) < TOL else "skew")


def dh_from_axes(points, directions, flange_R, flange_o):
    """(convention, d (6,), a (6,), alpha (6,), home (6,), base (alpha_0, a_0))
    in m and rad from the joint axes at the zero configuration: ``points``
    (6, 3) a point on each axis and ``directions`` (6, 3) each axis, base
    frame, m; the flange frame ``flange_R`` (3, 3), ``flange_o`` (3,).
    convention is "standard_dh" (base (0, 0)) or "modified_dh"."""
    P = np.asarray(points, dtype=float)
    Z = np.array([_unit(v) for v in directions])
    # frame 0
    z0, p0 = Z[0], P[0]
    ex = np.array([1.0, 0.0, 0.0])
    alpha0, a0 = 0.0, 0.0
    if abs(abs(z0[2]) - 1.0) < TOL and np.hypot(*(p0 - z0 * np.dot(p0, z0))[:2]) < TOL:
        if z0[2] < 0:
            alpha0 = np.pi  # the base's z turned over about x
    elif abs(np.dot(z0, ex)) < TOL:
        # the axis must meet the base x axis: the point of it at y = z = 0
        k = -p0[1] / z0[1] if abs(z0[1]) > TOL else -p0[2] / z0[2]
        hit = p0 + k * z0
        if abs(hit[1]) > TOL or abs(hit[2]) > TOL:
            raise ValueError("joint 1's axis is neither the base's z axis nor meets its x axis: no DH base row "
                             "reaches it (move the URDF's base frame onto joint 1's axis)")
        a0 = float(hit[0])
        alpha0 = _angle_about(np.array([0.0, 0.0, 1.0]), z0, ex)
    else:
        raise ValueError("joint 1's axis is at an angle to the base's x-y plane that no DH base row reaches "
                         f"(direction {np.round(z0, 6).tolist()}): move the URDF's base frame onto it")
    R = np.eye(3)
    if alpha0 or a0:
        c, s = np.cos(alpha0), np.sin(alpha0)
        R = np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])
    x_prev, o_prev = R[:, 0], np.array([a0, 0.0, 0.0])
    d, a, alpha, home = np.zeros(6), np.zeros(6), np.zeros(6), np.zeros(6)
    if np.linalg.norm(np.cross(o_prev - P[0], Z[0])) > 1e-6:
        raise ValueError("joint 1's axis does not pass through the DH base frame's origin")
    for i in range(6):
        zc = Z[i]  # z_{i}, frame i's z before the joint turns (axis of joint i+1, 0-based i)
        if i < 5:
            f1, f2, kind = _common_normal(o_prev, zc, P[i + 1], Z[i + 1])
            if kind == "skew":
                x = _unit(f2 - f1)
            elif kind == "meet":
                x = _unit(np.cross(zc, Z[i + 1]))
                if np.dot(x, x_prev) < 0:
                    x = -x
            else:  # parallel
                x = _unit(f2 - f1) if np.linalg.norm(f2 - f1) > TOL else x_prev
            z_next, o_next = Z[i + 1], f2
        else:  # the flange
            zf, of = flange_R[:, 2], np.asarray(flange_o, dtype=float)
            foot = o_prev + np.dot(of - o_prev, zc) * zc
            off = of - foot
            if np.linalg.norm(off) > TOL:
                x = _unit(off)
            else:
                x = flange_R[:, 0] - np.dot(flange_R[:, 0], zc) * zc
                if np.linalg.norm(x) < TOL:
                    raise ValueError("the flange's x axis lies along joint 6's axis: no DH row reaches the flange")
                x = _unit(x)
            f1, z_next, o_next = foot, zf, of
        d[i] = float(np.dot(f1 - o_prev, zc))
        a[i] = float(np.dot(o_next - f1, x))
        alpha[i] = _angle_about(zc, z_next, x)
        home[i] = _angle_about(x_prev, x, zc)
        if abs(np.dot(x, zc)) > 1e-6 or abs(np.dot(x, z_next)) > 1e-6:
            which = "the flange's z axis" if i == 5 else f"joint {i + 2}'s axis"
            raise ValueError(f"{which} is not at a right angle to the common normal from joint {i + 1}'s: "
                             "no DH row reaches it")
        x_prev, o_prev = x, o_next
    # the flange's x axis must be the DH frame 6's (home_6 turned it there when its origin is on the axis)
    c6 = np.cos(alpha[5])
    if abs(np.dot(flange_R[:, 0], x_prev) - 1.0) > 1e-6 or abs(np.dot(flange_R[:, 2], Z[5]) - c6) > 1e-6:
        raise ValueError("the flange frame is turned about its own z axis against the DH frame its origin gives "
                         "(its x axis off the common normal of joint 6's axis): no DH row reaches it")
    convention = "standard_dh" if not (alpha0 or a0) else "modified_dh"
    if convention == "modified_dh" and (abs(a[5]) > TOL or abs(alpha[5]) > TOL):
        raise ValueError("a chain that needs a DH base row (joint 1's axis off the base's z axis) must end on a "
                         "flange along joint 6's axis: the robot file's modified form has no last a or alpha")
    return convention, d, a, alpha, home, (float(alpha0), float(a0))
