"""A second, deliberately plain implementation of the standard-DH chain
(lists and loops, textbook formula), used only by the tests to check the
project's vectorised kinematics and the CLI's JSON against."""

import math


def matmul4(A, B):
    return [[sum(A[i][k] * B[k][j] for k in range(4)) for j in range(4)] for i in range(4)]


def dh_matrix(theta, d, a, alpha):
    ct, st, ca, sa = math.cos(theta), math.sin(theta), math.cos(alpha), math.sin(alpha)
    return [
        [ct, -st * ca, st * sa, a * ct],
        [st, ct * ca, -ct * sa, a * st],
        [0.0, sa, ca, d],
        [0.0, 0.0, 0.0, 1.0],
    ]


# Table 1 of the paper, typed in again here (mm, degrees).
TABLE1 = [  # d, a, alpha, home
    (900.0, 188.0, -90.0, 0.0),
    (0.0, 950.0, 0.0, -90.0),
    (0.0, 225.0, -90.0, 0.0),
    (1300.0, 0.0, -90.0, 180.0),
    (0.0, 0.0, 90.0, 0.0),
    (200.0, 0.0, 0.0, 0.0),
]


def fk_mm(q_deg, tool_mm=(0.0, 0.0, 0.0)):
    """Tool point (mm) and flange rotation for controller angles in degrees."""
    T = [[1.0 if i == j else 0.0 for j in range(4)] for i in range(4)]
    for (d, a, alpha, home), q in zip(TABLE1, q_deg):
        T = matmul4(T, dh_matrix(math.radians(q + home), d, a, math.radians(alpha)))
    p = [T[i][3] + sum(T[i][k] * tool_mm[k] for k in range(3)) for i in range(3)]
    R = [row[:3] for row in T[:3]]
    return p, R


def jacobian_fd(q_deg, tool_mm=(0.0, 0.0, 0.0), h_deg=1e-4):
    """6x6 Jacobian by central differences: linear rows in m/rad, angular in rad/rad."""
    J = [[0.0] * 6 for _ in range(6)]
    h = math.radians(h_deg)
    for j in range(6):
        qp = list(q_deg)
        qm = list(q_deg)
        qp[j] += h_deg
        qm[j] -= h_deg
        pp, Rp = fk_mm(qp, tool_mm)
        pm, Rm = fk_mm(qm, tool_mm)
        for i in range(3):
            J[i][j] = (pp[i] - pm[i]) / 1000.0 / (2 * h)
        # angular: vee(dR R^T) / dq
        _, R0 = fk_mm(q_deg, tool_mm)
        dR = [[(Rp[r][c] - Rm[r][c]) / (2 * h) for c in range(3)] for r in range(3)]
        W = [[sum(dR[r][k] * R0[c][k] for k in range(3)) for c in range(3)] for r in range(3)]
        J[3][j], J[4][j], J[5][j] = W[2][1], W[0][2], W[1][0]
    return J
