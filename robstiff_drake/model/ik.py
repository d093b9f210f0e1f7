"""Inverse kinematics for any 6R arm of the canonical chain (model/robot.py):
closed form where the arm has the industrial layout (spherical wrist, axes
2 and 3 parallel), a numerical solver otherwise; both polished by Newton
steps and checked against the working ranges.

Plain numpy.  Angles in radians, the model's joint angles (theta = q + home).

Closed form.  The wrist centre c (where axes 4, 5 and 6 meet) follows from
the tool pose.  Axis 1: in frame 1 the wrist centre must sit at the height
e = d2 + d3 + cos(alpha3) d4 along axis 2 (the shoulder's lateral offset),
which gives theta1 in front of axis 1 (and behind it).  Axes 2 and 3 are
parallel, so in frame 1 the wrist centre moves in a plane:
    c_xy = Rz(theta2) [(a2, 0) + Rz(theta3) w],   w = (a3, -sin(alpha3) d4)
a two-link problem with link lengths a2 and |w| (elbow up and down).  The
wrist: axis 5 is perpendicular to axes 4 and 6 (alpha4, alpha5 = +-90 deg),
so it lies along +-(z4-axis x z6-axis); theta4, theta5 and theta6 follow from
the directions of the axes (two wrist branches; at q5 = 0, axes 4 and 6
aligned, theta4 stays at its reference).

The arm branch is always the machining configuration, in front of axis 1
(the shoulder between axis 1 and the wrist centre) with the elbow up (the
elbow above the line from the shoulder to the wrist centre); of the wrist
branches, the one nearest the reference q is taken.

Along a path (each sample's reference the previous answer),
model/ik_path.py gives the same answers for all samples at once.
"""

import numpy as np

from robstiff_drake.model import kinematics as kin

# Numerical solver: tolerance on the pose error (m, rad), iterations, damping
NUMERIC_TOL = 1e-10
NUMERIC_MAX_ITER = 200


class IKError(ValueError):
    """The pose cannot be reached (out of reach, outside the joint limits,
    or no solution found)."""


def _wrap_near(angle, reference):
    return reference + (angle - reference + np.pi) % (2 * np.pi) - np.pi


def closed_form_reason(dh):
    """None when the closed form applies to ``dh``, else why not (words)."""
    eps = 1e-12
    why = []
    if max(abs(dh.a_m[3]), abs(dh.a_m[4]), abs(dh.d_m[4])) > eps:
        why.append("the wrist is not spherical (needs a4 = a5 = d5 = 0)")
    if abs(abs(np.sin(dh.alpha_rad[3])) - 1) > eps or abs(abs(np.sin(dh.alpha_rad[4])) - 1) > eps:
        why.append("axis 5 is not perpendicular to axes 4 and 6 (needs alpha4, alpha5 = +-90 deg)")
    if abs(np.sin(dh.alpha_rad[1])) > eps or np.cos(dh.alpha_rad[1]) < 0:
        why.append("axes 2 and 3 are not parallel (needs alpha2 = 0)")
    if abs(np.sin(dh.alpha_rad[0])) < 1e-6:
        why.append("axes 1 and 2 are parallel")
    return "; ".join(why) or None


def _check_limits(candidates, q_ref, q_lower_rad, q_upper_rad, limits):
    """The candidates inside the limits; IKError naming the joint when none is."""
    if limits is None and (q_lower_rad is None or q_upper_rad is None):
        return candidates

    def violation(q):
        if limits is not None:
            return limits(q)
        for i in range(6):
            if not q_lower_rad[i] - 1e-9 <= q[i] <= q_upper_rad[i] + 1e-9:
                return i, np.rad2deg(q[i]), np.rad2deg(q_lower_rad[i]), np.rad2deg(q_upper_rad[i])
        return None

    inside = [q for q in candidates if violation(q) is None]
    if not inside:
        q = min(candidates, key=lambda c: np.linalg.norm(c - q_ref))
        j, value, lo, hi = violation(q)
        raise IKError(f"the pose needs q{j + 1} = {value:.2f} deg, outside its joint limit [{lo:g}, {hi:g}] deg")
    return inside


def solve_ik(dh, target_pose, tool_m=None, q_ref_rad=None, q_lower_rad=None, q_upper_rad=None, tol_m=1e-12,
             limits=None):
    """Joint angles (rad) that put the tool frame at ``target_pose`` (4x4, m).

    ``limits``: a function of q (rad) giving None inside the working ranges
    or (joint index, angle deg, lower deg, upper deg) outside
    (RobotModel.limit_violation); or a box ``q_lower_rad``/``q_upper_rad``
    of the model's angles.  Of the solutions the one closest to
    ``q_ref_rad`` (default zero) is returned, each joint wrapped near the
    reference.  Raises IKError when the pose is out of reach, outside the
    limits, or (numerical solver) not found."""
    T = np.asarray(target_pose, dtype=float)
    tool = np.zeros(3) if tool_m is None else np.asarray(tool_m, dtype=float)
    q_ref = np.zeros(6) if q_ref_rad is None else np.asarray(q_ref_rad, dtype=float)
    why = closed_form_reason(dh)
    if why is None:
        candidates = [_polish(dh, q, T, tool, tol_m) for q in _closed_form(dh, T, tool, q_ref)]
    else:
        candidates = [_numerical(dh, T, tool, q_ref, q_lower_rad, q_upper_rad, limits, why)]
    candidates = _check_limits(candidates, q_ref, q_lower_rad, q_upper_rad, limits)
    return min(candidates, key=lambda c: np.linalg.norm(c - q_ref))


def solve_for(robot, target_pose, tool_m, q_ref_rad=None):
    """solve_ik for a RobotModel, within its working ranges."""
    return solve_ik(robot.dh, target_pose, tool_m, q_ref_rad=q_ref_rad, limits=robot.limit_violation)


def _out_of_reach(T):
    return IKError(f"tool point ({T[0, 3] * 1e3:.1f}, {T[1, 3] * 1e3:.1f}, {T[2, 3] * 1e3:.1f}) mm is out of reach")


def wrist_centre(dh, T, tool):
    """The wrist centre (m, base frame) of tool pose T."""
    R6 = T[:3, :3]
    p6 = T[:3, 3] - R6 @ tool
    a6, d6, al6 = dh.a_m[5], dh.d_m[5], dh.alpha_rad[5]
    return p6 - R6 @ np.array([a6, d6 * np.sin(al6), d6 * np.cos(al6)])


def _link(dh, i, theta):
    """Standard-DH link transform i (0-based) at DH angle theta."""
    ct, st = np.cos(theta), np.sin(theta)
    ca, sa = np.cos(dh.alpha_rad[i]), np.sin(dh.alpha_rad[i])
    return np.array([[ct, -st * ca, st * sa, dh.a_m[i] * ct], [st, ct * ca, -ct * sa, dh.a_m[i] * st],
                     [0.0, sa, ca, dh.d_m[i]], [0.0, 0.0, 0.0, 1.0]])


def _arm(dh, pc):
    """theta1..3 of the machining branch (front of axis 1, elbow up)."""
    base = np.eye(4) if dh.base is None else dh.base
    pc1 = np.append(pc, 1.0)  # (homogeneous; np.append, not np.r_: the same array, a tenth of the IK's time less)
    p0 = np.linalg.solve(base, pc1)[:3]  # wrist centre in frame 0
    x, y, z = p0
    d, a, al = dh.d_m, dh.a_m, dh.alpha_rad
    e = d[1] + d[2] + np.cos(al[2]) * d[3]  # wrist centre's height along axis 2, frame 1
    k = (e - np.cos(al[0]) * (z - d[0])) / np.sin(al[0])  # = x sin(theta1) - y cos(theta1)
    r = np.hypot(x, y)
    if abs(k) > r + 1e-12:
        return None
    phi = np.arctan2(y, x)
    shift = np.arcsin(np.clip(k / r, -1.0, 1.0)) if r > 1e-12 else 0.0  # r = 0: on axis 1, any theta1
    w = np.array([a[2], -np.sin(al[2]) * d[3]])
    L = np.hypot(*w)
    phi_w = np.arctan2(w[1], w[0])
    best = None
    for th1 in (phi + shift, phi + np.pi - shift):
        T1 = base @ _link(dh, 0, th1)
        v = np.linalg.solve(T1, pc1)[:3]
        c = (v[0] ** 2 + v[1] ** 2 - a[1] ** 2 - L ** 2) / (2 * a[1] * L)
        if abs(c) > 1.0:
            continue
        shoulder = T1[:3, 3]
        front = np.dot(shoulder[:2] - base[:2, 3], pc[:2] - base[:2, 3]) >= 0 if abs(a[0]) > 1e-9 else \
            np.dot(T1[:2, 0], pc[:2] - base[:2, 3]) >= 0
        for sign in (1.0, -1.0):
            beta = sign * np.arccos(c)  # theta3 + phi_w
            th3 = beta - phi_w
            th2 = np.arctan2(v[1], v[0]) - np.arctan2(L * np.sin(beta), a[1] + L * np.cos(beta))
            elbow = (T1 @ _link(dh, 1, th2))[:3, 3]
            s2w, s2e = pc - shoulder, elbow - shoulder
            n = s2w / max(np.linalg.norm(s2w), 1e-300)
            up = (s2e - np.dot(s2e, n) * n)[2] >= 0
            score = 2 * front + up
            if best is None or score > best[0]:
                best = (score, np.array([th1, th2, th3]))
    return None if best is None else best[1]


def _closed_form(dh, T, tool, q_ref):
    """The closed-form solutions (rad): the machining arm branch, both wrist branches."""
    R6 = T[:3, :3]
    pc = wrist_centre(dh, T, tool)
    theta123 = _arm(dh, pc)
    if theta123 is None:
        raise _out_of_reach(T)
    home = dh.home_rad
    q123 = theta123 - home[:3]
    R3 = kin.frames(dh, np.concatenate([q123, np.zeros(3)]))[3][:3, :3]
    al4, al5, al6 = dh.alpha_rad[3], dh.alpha_rad[4], dh.alpha_rad[5]
    s4, s5 = np.sign(np.sin(al4)), np.sign(np.sin(al5))
    z6 = R6 @ np.array([0.0, np.sin(al6), np.cos(al6)])  # axis 6
    z4 = R3[:, 2]  # axis 4
    n = np.cross(z4, z6)
    singular = np.linalg.norm(n) < 1e-12
    out = []
    for branch in ((1.0,) if singular else (1.0, -1.0)):
        if singular:  # axes 4 and 6 aligned: keep axis 4 at its reference
            th4 = q_ref[3] + home[3]
        else:
            u = R3.T @ (branch * n / np.linalg.norm(n))  # axis 5 in frame 3
            th4 = np.arctan2(s4 * u[0], -s4 * u[1])
        R4 = R3 @ _link(dh, 3, th4)[:3, :3]
        w = R4.T @ z6
        th5 = np.arctan2(s5 * w[0], -s5 * w[1])
        R5 = R4 @ _link(dh, 4, th5)[:3, :3]
        M = R5.T @ R6 @ _link(dh, 5, 0.0)[:3, :3].T  # Rz(theta6)
        th6 = np.arctan2(M[1, 0], M[0, 0])
        q = np.concatenate([q123, np.array([th4, th5, th6]) - home[3:]])
        out.append(np.array([_wrap_near(q[i], q_ref[i]) for i in range(6)]))
    return out


def _pose_error(dh, q, T, tool):
    Tq = kin.tool_pose(dh, q, tool)
    dp = T[:3, 3] - Tq[:3, 3]
    Re = T[:3, :3] @ Tq[:3, :3].T
    dphi = 0.5 * np.array([Re[2, 1] - Re[1, 2], Re[0, 2] - Re[2, 0], Re[1, 0] - Re[0, 1]])
    return np.concatenate([dp, dphi])


def _polish(dh, q, T, tool, tol_m):
    """A few Newton steps on the closed-form answer (round-off, and a guard
    against a geometry slightly off the closed form's assumptions)."""
    for _ in range(10):
        e = _pose_error(dh, q, T, tool)
        if np.max(np.abs(e)) < tol_m:
            break
        J = kin.jacobian(dh, q, tool)
        q = q + np.linalg.lstsq(J, e, rcond=None)[0]
    return q


def _numerical(dh, T, tool, q_ref, q_lower_rad, q_upper_rad, limits, why):
    """Damped least squares from the reference (then from zero): the
    solution (rad), or IKError saying why no closed form and what was left."""
    starts = [q_ref, np.zeros(6)]
    best = (np.inf, None)
    for q0 in starts:
        q = np.array(q0, dtype=float)
        lam = 1e-3
        e = _pose_error(dh, q, T, tool)
        err = np.linalg.norm(e)
        for _ in range(NUMERIC_MAX_ITER):
            if err < NUMERIC_TOL:
                break
            J = kin.jacobian(dh, q, tool)
            step = np.linalg.solve(J.T @ J + lam * np.eye(6), J.T @ e)
            q_new = q + step
            e_new = _pose_error(dh, q_new, T, tool)
            if np.linalg.norm(e_new) < err:
                q, e, err = q_new, e_new, np.linalg.norm(e_new)
                lam = max(lam / 10.0, 1e-12)
            else:
                lam = min(lam * 10.0, 1e6)
        if err < NUMERIC_TOL:
            return np.array([_wrap_near(q[i], q_ref[i]) for i in range(6)])
        best = min(best, (err, q.tolist()), key=lambda b: b[0])
    raise IKError(f"tool point ({T[0, 3] * 1e3:.1f}, {T[1, 3] * 1e3:.1f}, {T[2, 3] * 1e3:.1f}) mm: the numerical "
                  f"IK found no solution (pose error {best[0] * 1e3:.3g} mm/mrad left after {NUMERIC_MAX_ITER} "
                  f"iterations from {len(starts)} starts; out of reach?); no closed form because {why}")


def tool_down_pose(p_m, yaw_rad=0.0):
    """A tool frame at ``p_m`` (m) with the tool z axis pointing straight
    down (the spindle axis of a face-milling set-up), turned by ``yaw_rad``
    about the vertical.  At zero yaw the tool x axis points back towards the
    robot (-x of the base)."""
    c, s = np.cos(yaw_rad), np.sin(yaw_rad)
    T = np.eye(4)
    T[:3, :3] = np.array([[-c, -s, 0.0], [-s, c, 0.0], [0.0, 0.0, -1.0]])
    T[:3, 3] = p_m
    return T


def workspace_poses(robot, n_per_axis, tool_m, box=None, on_point=None):
    """Joint angles (rad) for a grid of tool points in the machining box with
    the spindle axis down, each solved by IK within the joint limits and
    warm-started from its neighbour.  Returns (points_m (N, 3), q_rad (N, 6));
    points that cannot be reached are left out.  ``on_point()``: called after
    each grid point (a progress bar's step)."""
    ws = robot.workspace
    xs, ys, zs = (np.linspace(lo, hi, n_per_axis) for lo, hi in (box or (ws.x_m, ws.y_m, ws.z_m)))
    points, qs = [], []
    q_ref = None
    for x in xs:
        for y in ys:
            for z in zs:
                if on_point is not None:
                    on_point()
                try:
                    q = solve_for(robot, tool_down_pose([x, y, z]), tool_m, q_ref_rad=q_ref)
                except IKError:
                    continue
                points.append((x, y, z))
                qs.append(q)
                q_ref = q
    return np.array(points).reshape(-1, 3), np.array(qs).reshape(-1, 6)
