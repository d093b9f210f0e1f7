"""Second, deliberately plain implementations of the library robots'
kinematics (lists and loops, no numpy, nothing from robstiff_drake), used
only by the tests:

* ``fk_urdf``: the robots as their published URDF descriptions give them
  (joint origins xyz/rpy and axes, typed in again from the ROS-Industrial
  and KUKA files the robot files cite), driven by the controller's angles
  through the manufacturers' own joint conventions (FANUC's J2/J3
  interaction as the ROS-Industrial driver applies it: J3_urdf = J3 + J2);
* ``fk_modified_dh``: Craig's modified Denavit-Hartenberg formula, for the
  FANUC table typed in again with its controller map written out by hand.

Lengths in mm, angles in degrees, the flange frame is each description's
tool0 (z out of the flange).
"""

import math


def matmul4(A, B):
    return [[sum(A[i][k] * B[k][j] for k in range(4)) for j in range(4)] for i in range(4)]


def rpy_matrix(xyz, rpy):
    """URDF origin: translation xyz (mm) and R = Rz(yaw) Ry(pitch) Rx(roll)."""
    r, p, y = rpy
    cr, sr, cp, sp, cy, sy = math.cos(r), math.sin(r), math.cos(p), math.sin(p), math.cos(y), math.sin(y)
    R = [[cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
         [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
         [-sp, cp * sr, cp * cr]]
    return [R[0] + [xyz[0]], R[1] + [xyz[1]], R[2] + [xyz[2]], [0.0, 0.0, 0.0, 1.0]]


def axis_rotation(axis, angle):
    """Rotation by ``angle`` (rad) about a unit axis (Rodrigues), 4x4."""
    x, y, z = axis
    c, s, v = math.cos(angle), math.sin(angle), 1.0 - math.cos(angle)
    return [[c + x * x * v, x * y * v - z * s, x * z * v + y * s, 0.0],
            [y * x * v + z * s, c + y * y * v, y * z * v - x * s, 0.0],
            [z * x * v - y * s, z * y * v + x * s, c + z * z * v, 0.0],
            [0.0, 0.0, 0.0, 1.0]]


PI = math.pi
# (joint origin xyz mm, rpy rad, axis), six joints, then the flange (tool0) origin
URDF = {
    # ROS-Industrial abb_irb6640_support, urdf/irb6640_235_255_macro.xacro
    "irb6640": dict(
        joints=[((0, 0, 780), (0, 0, 0), (0, 0, 1)), ((320, 0, 0), (0, 0, 0), (0, 1, 0)),
                ((0, 0, 1075), (0, 0, 0), (0, 1, 0)), ((0, 0, 200), (0, 0, 0), (1, 0, 0)),
                ((1142, 0, 0), (0, 0, 0), (0, 1, 0)), ((200, 0, 0), (0, 0, 0), (1, 0, 0))],
        tool0=((0, 0, 0), (0, PI / 2, 0)),
        urdf_angles=lambda q: list(q)),
    # kroshu/kuka_robot_descriptions, kuka_quantec_support/urdf/kr240_r2900_2_macro.xacro
    "kr240_r2900": dict(
        joints=[((0, 0, 305.6), (PI, 0, 0), (0, 0, 1)), ((330, 72, -339.4), (PI / 2, 0, 0), (0, 0, 1)),
                ((1350, 0, -103), (0, 0, 0), (0, 0, 1)), ((828, -115, 175), (PI / 2, 0, -PI / 2), (0, 0, 1)),
                ((0, 106.5, -392), (0, PI / 2, PI / 2), (0, 0, 1)), ((169.5, 0, -106.5), (PI / 2, 0, -PI / 2), (0, 0, 1))],
        tool0=((0, 0, -70.5), (PI, 0, PI)),
        urdf_angles=lambda q: list(q)),
    # ROS-Industrial fanuc_r2000ic_support, urdf/r2000ic165f_macro.xacro; the
    # driver's J23_factor = 1 for this robot: J3_urdf = J3 + J2
    "r2000ic_165f": dict(
        joints=[((0, 0, 670), (0, 0, 0), (0, 0, 1)), ((312, 0, 0), (0, 0, 0), (0, 1, 0)),
                ((0, 0, 1075), (0, 0, 0), (0, -1, 0)), ((0, 0, 225), (0, 0, 0), (-1, 0, 0)),
                ((1280, 0, 0), (0, 0, 0), (0, -1, 0)), ((215, 0, 0), (0, 0, 0), (-1, 0, 0))],
        tool0=((0, 0, 0), (PI, -PI / 2, 0)),
        urdf_angles=lambda q: [q[0], q[1], q[2] + q[1], q[3], q[4], q[5]]),
}


def _tool_point(T, tool_mm):
    return [T[i][3] + sum(T[i][k] * tool_mm[k] for k in range(3)) for i in range(3)]


def fk_urdf(name, q_ctrl_deg, tool_mm=(0.0, 0.0, 0.0)):
    """Tool point (mm) and tool0 rotation of a library robot at the
    controller's angles (deg), from its published URDF description."""
    d = URDF[name]
    q = d["urdf_angles"]([math.radians(v) for v in q_ctrl_deg])
    T = [[1.0 if i == j else 0.0 for j in range(4)] for i in range(4)]
    for (xyz, rpy, axis), qi in zip(d["joints"], q):
        T = matmul4(matmul4(T, rpy_matrix(xyz, rpy)), axis_rotation(axis, qi))
    T = matmul4(T, rpy_matrix(*d["tool0"]))
    return _tool_point(T, tool_mm), [row[:3] for row in T[:3]]


def craig_link(alpha, a, theta, d):
    """Modified DH link: Rx(alpha) Tx(a) Rz(theta) Tz(d) (rad, mm)."""
    ca, sa, ct, st = math.cos(alpha), math.sin(alpha), math.cos(theta), math.sin(theta)
    return [[ct, -st, 0.0, a],
            [st * ca, ct * ca, -sa, -sa * d],
            [st * sa, ct * sa, ca, ca * d],
            [0.0, 0.0, 0.0, 1.0]]


# FANUC R-2000iC/165F as a modified-DH table (alpha_{i-1} deg, a_{i-1} mm, d_i mm)
FANUC_MDH = [(0, 0, 670), (-90, 312, 0), (0, 1075, 0), (-90, 225, 1280), (90, 0, 0), (-90, 0, 215)]


def fanuc_theta_deg(J):
    """FANUC J1..J6 (deg) -> the table's joint angles theta (deg): J2 from the
    vertical, J3 from the horizontal (the J2/J3 interaction), J3..J6 turning
    the other way round the table's z axes."""
    return [J[0], J[1] - 90.0, -(J[2] + J[1]), -J[3], -J[4], -J[5]]


def fk_modified_dh(rows, theta_deg, tool_mm=(0.0, 0.0, 0.0)):
    """Tool point (mm) and flange rotation of a modified-DH chain."""
    T = [[1.0 if i == j else 0.0 for j in range(4)] for i in range(4)]
    for (alpha, a, d), th in zip(rows, theta_deg):
        T = matmul4(T, craig_link(math.radians(alpha), a, math.radians(th), d))
    return _tool_point(T, tool_mm), [row[:3] for row in T[:3]]


def jacobian_fd(fk, q_deg, tool_mm=(0.0, 0.0, 0.0), h_deg=1e-4):
    """6x6 Jacobian of ``fk(q_deg, tool_mm)`` with respect to the angles it
    takes, by central differences: linear rows m/rad, angular rad/rad."""
    J = [[0.0] * 6 for _ in range(6)]
    h = math.radians(h_deg)
    _, R0 = fk(q_deg, tool_mm)
    for j in range(6):
        qp, qm = list(q_deg), list(q_deg)
        qp[j] += h_deg
        qm[j] -= h_deg
        pp, Rp = fk(qp, tool_mm)
        pm, Rm = fk(qm, tool_mm)
        for i in range(3):
            J[i][j] = (pp[i] - pm[i]) / 1000.0 / (2 * h)
        dR = [[(Rp[r][c] - Rm[r][c]) / (2 * h) for c in range(3)] for r in range(3)]
        W = [[sum(dR[r][k] * R0[c][k] for k in range(3)) for c in range(3)] for r in range(3)]
        J[3][j], J[4][j], J[5][j] = W[2][1], W[0][2], W[1][0]
    return J
