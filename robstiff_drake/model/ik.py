"""Inverse kinematics for the IRB6400's geometry (spherical wrist, shoulder
offset a1, elbow offset a3), closed form and polished by Newton steps.

Plain numpy.  Angles in radians, controller convention (theta = q + home).

Closed form, in the plane of the arm (u radial from axis 1 beyond a1, w up
from the shoulder height d1), with beta = theta2 + theta3:
    u =  a2 cos(theta2) + a3 cos(beta) - d4 sin(beta)
    w = -a2 sin(theta2) - a3 sin(beta) - d4 cos(beta)
and the wrist R_3^6 = Rz(theta4) Ry(theta5) Rz(theta6) (a ZYZ set), because
alpha4 = -90 deg and alpha5 = +90 deg.
"""

import numpy as np

from robstiff_drake.model import kinematics as kin


class IKError(ValueError):
    """The pose cannot be reached (out of reach, or outside the joint limits)."""


def _wrap_near(angle, reference):
    return reference + (angle - reference + np.pi) % (2 * np.pi) - np.pi


def _check_geometry(dh):
    expected_zero = [dh.d_m[1], dh.d_m[2], dh.a_m[3], dh.a_m[4], dh.d_m[4], dh.a_m[5]]
    if max(abs(v) for v in expected_zero) > 1e-12 or abs(dh.alpha_rad[1]) > 1e-12:
        raise IKError("closed-form IK is written for the IRB6400 geometry (spherical wrist, planar arm)")


def solve_ik(dh, target_pose, tool_m=None, q_ref_rad=None, q_lower_rad=None,
             q_upper_rad=None, tol_m=1e-12):
    """Joint angles (rad) that put the tool frame at ``target_pose`` (4x4, m).

    Of the closed-form solutions (front of axis 1, elbow up; wrist flip both
    ways) the one closest to ``q_ref_rad`` (default zero) is returned, with
    multi-turn joints 4 and 6 wrapped near the reference.  Raises IKError when
    the pose is out of reach or outside the given joint limits."""
    _check_geometry(dh)
    T = np.asarray(target_pose, dtype=float)
    tool = np.zeros(3) if tool_m is None else np.asarray(tool_m, dtype=float)
    q_ref = np.zeros(6) if q_ref_rad is None else np.asarray(q_ref_rad, dtype=float)
    R6 = T[:3, :3]
    p6 = T[:3, 3] - R6 @ tool
    pc = p6 - dh.d_m[5] * R6[:, 2]  # wrist centre

    a1, d1, a2, a3, d4 = dh.a_m[0], dh.d_m[0], dh.a_m[1], dh.a_m[2], dh.d_m[3]
    th1 = np.arctan2(pc[1], pc[0])
    u = np.hypot(pc[0], pc[1]) - a1
    w = pc[2] - d1
    L3 = np.hypot(a3, d4)
    gamma = np.arctan2(d4, a3)
    D = (u * u + w * w - a2 * a2 - L3 * L3) / (2 * a2 * L3)
    if abs(D) > 1.0:
        raise IKError(
            f"tool point ({T[0, 3] * 1e3:.1f}, {T[1, 3] * 1e3:.1f}, {T[2, 3] * 1e3:.1f}) mm "
            "is out of reach"
        )
    th3 = np.arccos(D) - gamma  # elbow up (the home configuration's branch)
    phi = th3 + gamma
    th2 = np.arctan2(-w, u) - np.arctan2(L3 * np.sin(phi), a2 + L3 * np.cos(phi))

    q123 = np.array([th1, th2, th3]) - dh.home_rad[:3]
    q_arm = np.concatenate([q123, np.zeros(3)])
    T3 = kin.frames(dh, q_arm)[3]
    R36 = T3[:3, :3].T @ R6
    s5 = np.hypot(R36[0, 2], R36[1, 2])
    candidates = []
    for sign in (1.0, -1.0):
        th5 = np.arctan2(sign * s5, R36[2, 2])
        if s5 < 1e-12:  # wrist singular: keep axis 4 at its reference
            th4 = q_ref[3] + dh.home_rad[3]
            th6 = np.arctan2(R36[1, 0], R36[0, 0]) - th4
        else:
            th4 = np.arctan2(sign * R36[1, 2], sign * R36[0, 2])
            th6 = np.arctan2(sign * R36[2, 1], -sign * R36[2, 0])
        q = np.concatenate([q123, np.array([th4, th5, th6]) - dh.home_rad[3:]])
        for i in range(6):
            q[i] = _wrap_near(q[i], q_ref[i])
        candidates.append(_polish(dh, q, T, tool, tol_m))
    if q_lower_rad is not None and q_upper_rad is not None:
        inside = [q for q in candidates
                  if np.all(q >= q_lower_rad - 1e-9) and np.all(q <= q_upper_rad + 1e-9)]
        if not inside:
            q = min(candidates, key=lambda c: np.linalg.norm(c - q_ref))
            bad = [i for i in range(6) if not q_lower_rad[i] - 1e-9 <= q[i] <= q_upper_rad[i] + 1e-9]
            j = bad[0]
            raise IKError(
                f"the pose needs q{j + 1} = {np.rad2deg(q[j]):.2f} deg, outside its joint limit "
                f"[{np.rad2deg(q_lower_rad[j]):g}, {np.rad2deg(q_upper_rad[j]):g}] deg"
            )
        candidates = inside
    return min(candidates, key=lambda c: np.linalg.norm(c - q_ref))


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


def tool_down_pose(p_m, yaw_rad=0.0):
    """A tool frame at ``p_m`` (m) with the tool z axis pointing straight
    down (the spindle axis of a face-milling set-up), turned by ``yaw_rad``
    about the vertical.  At zero yaw the tool x axis points back towards the
    robot (-x of the base), the flange's orientation at q4 = q6 = 0."""
    c, s = np.cos(yaw_rad), np.sin(yaw_rad)
    T = np.eye(4)
    T[:3, :3] = np.array([[-c, -s, 0.0], [-s, c, 0.0], [0.0, 0.0, -1.0]])
    T[:3, 3] = p_m
    return T


def workspace_poses(robot, n_per_axis, tool_m, box=None):
    """Joint angles (rad) for a grid of tool points in the machining box with
    the spindle axis down, each solved by IK within the joint limits and
    warm-started from its neighbour.  Returns (points_m (N, 3), q_rad (N, 6));
    points that cannot be reached are left out."""
    ws = robot.workspace
    xs, ys, zs = (np.linspace(lo, hi, n_per_axis) for lo, hi in (box or (ws.x_m, ws.y_m, ws.z_m)))
    points, qs = [], []
    q_ref = None
    for x in xs:
        for y in ys:
            for z in zs:
                try:
                    q = solve_ik(robot.dh, tool_down_pose([x, y, z]), tool_m, q_ref_rad=q_ref,
                                 q_lower_rad=robot.q_lower_rad, q_upper_rad=robot.q_upper_rad)
                except IKError:
                    continue
                points.append((x, y, z))
                qs.append(q)
                q_ref = q
    return np.array(points).reshape(-1, 3), np.array(qs).reshape(-1, 6)
