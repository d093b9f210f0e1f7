"""Forward kinematics, the geometric Jacobian at a tool point, and its
derivative (the K_g term of the CCT model), for any serial 6R arm given as
the canonical chain of model/robot.py (an optional fixed base transform,
then six standard-DH links; a modified-DH table is turned into this form
when the robot file is read).

Plain numpy.  Every function takes the model's joint angles ``q_rad``
(radians; the DH angle is q + home; RobotModel.joint_rad turns the
controller's angles into these) with shape (6,) or (..., 6): leading
dimensions are batches.  Lengths are metres.

Jacobian convention (used everywhere in the project): J is 6x6, rows 0-2 map
joint rates to the tool point's linear velocity (m/rad), rows 3-5 to the
angular velocity (rad/rad), both in the base frame.  A wrench
F = (force N, moment N*m about the tool point), in the base frame, loads the
joints with tau = J^T F (N*m).
"""

import numpy as np


def _as_tool(tool_m):
    if tool_m is None:
        return np.zeros(3)
    tool = np.asarray(tool_m, dtype=float)
    if tool.shape != (3,):
        raise ValueError(f"tool offset must have 3 components (m), got shape {tool.shape}")
    return tool


def link_transforms(dh, q_rad):
    """The six DH link transforms A_i(q_i), shape (..., 6, 4, 4)
    (Rz(theta) Tz(d) Tx(a) Rx(alpha), then Ry(beta) when the chain has it)."""
    q = np.asarray(q_rad, dtype=float)
    theta = q + dh.home_rad
    ct, st = np.cos(theta), np.sin(theta)
    ca, sa = np.cos(dh.alpha_rad), np.sin(dh.alpha_rad)
    A = np.zeros(q.shape + (4, 4))
    A[..., 0, 0] = ct
    A[..., 0, 1] = -st * ca
    A[..., 0, 2] = st * sa
    A[..., 0, 3] = dh.a_m * ct
    A[..., 1, 0] = st
    A[..., 1, 1] = ct * ca
    A[..., 1, 2] = -ct * sa
    A[..., 1, 3] = dh.a_m * st
    A[..., 2, 1] = sa
    A[..., 2, 2] = ca
    A[..., 2, 3] = dh.d_m
    A[..., 3, 3] = 1.0
    beta = getattr(dh, "beta_rad", None)
    if beta is not None:  # Hayati's Ry(beta) after Rx(alpha): the rotation's columns mix, the origin stays
        cb, sb = np.cos(beta), np.sin(beta)
        x, z = A[..., :3, 0].copy(), A[..., :3, 2].copy()
        A[..., :3, 0] = x * cb[:, None] - z * sb[:, None]
        A[..., :3, 2] = x * sb[:, None] + z * cb[:, None]
    return A


def frames(dh, q_rad, rows=4):
    """Poses of DH frames 0..6 in the base frame, shape (..., 7, 4, 4);
    ``rows=3``: without the constant last row, (..., 7, 3, 4) (a quarter
    less memory for callers that read only rotations and origins).

    Frame 0 is the base (moved by the chain's fixed base transform, if any);
    frame i (i >= 1) moves with link i; frame 6 is the flange (the wrist
    sensor frame).  The axis of joint i is the z axis of frame i-1.

    The chain's product written out per element over the batch (a link's
    transform is Rz(theta) Tz(d) Tx(a) Rx(alpha) [Ry(beta)]): each frame's
    columns are a few multiply-adds of the previous frame's, with no stack
    of 4x4 link transforms (a batch of 100,000 poses: no 77 MB temporary).
    """
    q = np.asarray(q_rad, dtype=float)
    batch = q.shape[:-1]
    base = np.eye(4) if dh.base is None else np.asarray(dh.base, dtype=float)
    if rows not in (3, 4):
        raise ValueError(f"rows must be 3 or 4, not {rows}")
    T = np.zeros(batch + (7, rows, 4))
    T[..., 0, :, :] = base[:rows]
    if rows == 4:
        T[..., :, 3, 3] = 1.0
    theta = q + dh.home_rad
    ct, st = np.cos(theta), np.sin(theta)
    ca, sa = np.cos(dh.alpha_rad), np.sin(dh.alpha_rad)
    beta = getattr(dh, "beta_rad", None)
    # the current frame's rotation columns x, y, z and origin o, each a list of 3 (batch) arrays (or scalars)
    x, y, z, o = ([base[r, c] for r in range(3)] for c in range(4))
    for i in range(6):
        c, s = ct[..., i], st[..., i]
        xr = [x[r] * c + y[r] * s for r in range(3)]  # Rz(theta): x, y turn
        yr = [y[r] * c - x[r] * s for r in range(3)]
        o = [o[r] + dh.a_m[i] * xr[r] + dh.d_m[i] * z[r] for r in range(3)]  # Tz(d) Tx(a)
        y = [ca[i] * yr[r] + sa[i] * z[r] for r in range(3)]  # Rx(alpha): y, z turn
        z = [ca[i] * z[r] - sa[i] * yr[r] for r in range(3)]
        x = xr
        if beta is not None and beta[i] != 0.0:  # Hayati's Ry(beta): x, z turn, the origin stays
            cb, sb = np.cos(beta[i]), np.sin(beta[i])
            x, z = [x[r] * cb - z[r] * sb for r in range(3)], [x[r] * sb + z[r] * cb for r in range(3)]
        # one write of the frame's 12 values per pose (12 strided writes of the batch cost 3x as much)
        values = [v[r] for r in range(3) for v in (x, y, z, o)]
        if not batch:  # one pose (the IK's calls): the same 12 values, without broadcasting scalars
            T[i + 1, :3, :] = np.array(values, dtype=float).reshape(3, 4)
            continue
        rows = np.broadcast_arrays(*values)
        T[..., i + 1, :3, :] = np.moveaxis(np.array(rows), 0, -1).reshape(batch + (3, 4))
    return T


def tool_pose(dh, q_rad, tool_m=None):
    """4x4 pose of the tool frame: the flange frame moved by ``tool_m``
    (offset in the flange frame, m)."""
    T6 = frames(dh, q_rad)[..., 6, :, :]
    out = T6.copy()
    out[..., :3, 3] = T6[..., :3, 3] + T6[..., :3, :3] @ _as_tool(tool_m)
    return out


def tool_position(dh, q_rad, tool_m=None):
    """Tool-point position in the base frame (m), shape (..., 3)."""
    return tool_pose(dh, q_rad, tool_m)[..., :3, 3]


def _axes_and_origins(dh, q_rad, tool_m, T=None):
    T = frames(dh, q_rad) if T is None else T
    z = T[..., :6, :3, 2]  # joint axes, (..., 6, 3)
    o = T[..., :6, :3, 3]  # points on the axes, (..., 6, 3)
    p = T[..., 6, :3, 3] + T[..., 6, :3, :3] @ _as_tool(tool_m)
    return z, o, p


def jacobian(dh, q_rad, tool_m=None, T=None):
    """Geometric Jacobian at the tool point, base frame, shape (..., 6, 6).
    ``T``: ``frames(dh, q_rad)`` when the caller has them."""
    z, o, p = _axes_and_origins(dh, q_rad, tool_m, T)
    Jv = np.cross(z, p[..., None, :] - o)  # (..., 6, 3)
    J = np.concatenate([Jv, z], axis=-1)  # (..., 6 joints, 6 rows)
    return np.swapaxes(J, -1, -2)


def jacobian_derivative(dh, q_rad, tool_m=None):
    """dJ/dq: array D with D[..., r, i, j] = d J[r, i] / d q_j, shape (..., 6, 6, 6).

    Analytic: the axis z_i and origin o_i of joint i move only with the joints
    before it (dz_i/dq_j = z_j x z_i, do_i/dq_j = z_j x (o_i - o_j) for j < i),
    and the tool point moves with all of them (dp/dq_j = z_j x (p - o_j))."""
    z, o, p = _axes_and_origins(dh, q_rad, tool_m)
    zi = z[..., :, None, :]  # joint i along axis -3
    zj = z[..., None, :, :]  # joint j along axis -2
    r_i = (p[..., None, :] - o)[..., :, None, :]  # p - o_i
    r_j = (p[..., None, :] - o)[..., None, :, :]  # p - o_j
    before = np.tril(np.ones((6, 6), dtype=bool), k=-1)  # before[i, j]: j < i
    dz = np.where(before[..., None], np.cross(zj, zi), 0.0)  # (..., i, j, 3)
    # d(z_i x (p - o_i))/dq_j = dz_i x (p - o_i) + z_i x (dp - do_i); for j < i,
    # dp - do_i = z_j x (p - o_i); for j >= i, dz_i = do_i = 0 and dp = z_j x (p - o_j).
    lever = np.where(before[..., None], r_i, r_j)
    dJv = np.cross(dz, r_i) + np.cross(zi, np.cross(zj, lever))
    D = np.concatenate([dJv, dz], axis=-1)  # (..., i, j, 6 rows)
    return np.moveaxis(D, -1, -3)


def geometric_stiffness(dh, q_rad, wrench, tool_m=None):
    """K_g of the CCT model (the paper's Eq. 7): K_g = d(J^T F)/dq at constant F,
    shape (..., 6, 6), N*m/rad.  ``wrench`` = (force N, moment N*m) at the
    tool point in the base frame, the external load on the robot."""
    D = jacobian_derivative(dh, q_rad, tool_m)
    F = np.asarray(wrench, dtype=float)
    return np.einsum("...rij,...r->...ij", D, F)


def rotation_to_rpy(R):
    """Roll-pitch-yaw (URDF convention R = Rz(yaw) Ry(pitch) Rx(roll))."""
    R = np.asarray(R, dtype=float)
    pitch = np.arctan2(-R[2, 0], np.hypot(R[0, 0], R[1, 0]))
    if np.hypot(R[0, 0], R[1, 0]) < 1e-12:  # gimbal lock: put it all in yaw
        roll = 0.0
        yaw = np.arctan2(-R[0, 1], R[1, 1])
    else:
        roll = np.arctan2(R[2, 1], R[2, 2])
        yaw = np.arctan2(R[1, 0], R[0, 0])
    return np.array([roll, pitch, yaw])


def rpy_to_rotation(rpy):
    r, p, y = rpy
    cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
    Rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    Ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    Rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    return Rz @ Ry @ Rx


def cross3(a, b):
    """Cross product of two 3-vectors, without np.cross's overhead (per-cycle code)."""
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])
