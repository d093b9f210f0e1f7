"""The per-cycle path of the compensator: Jacobian at the measured joint
angles, joint torques from the measured wrench, joint and tool deflection.

It runs every controller cycle (4 ms on the IRC5), so it is written for speed
in plain Python floats: one pass down the chain builds the joint axes and
origins with scalar arithmetic (no small-array numpy calls, whose fixed cost
of about a microsecond each would dominate), then the six Jacobian columns,
tau = J^T F, dq = C_q tau and dx = J dq.  ``kinematics.jacobian`` is the
reference it is tested against.

Units: q in rad (controller convention), wrench (N, N*m about the tool
point, base frame), dq in rad, dx = (m, rad).
"""

import math

import numpy as np

from robstiff_drake.model import jit, tick_kernels

MEMO_SIZE = 4
_NONE = np.empty(0)  # (an unused argument of the compiled kernel)
_SHARED_CHAINS = {}  # arm and tool -> {q: chain}, insertion-ordered


def rotate(R, v):
    """R v for R row-major (9 floats) and v (3 floats)."""
    return (R[0] * v[0] + R[1] * v[1] + R[2] * v[2], R[3] * v[0] + R[4] * v[1] + R[5] * v[2],
            R[6] * v[0] + R[7] * v[1] + R[8] * v[2])


def rotate_transposed(R, v):
    """R^T v for R row-major (9 floats) and v (3 floats)."""
    return (R[0] * v[0] + R[3] * v[1] + R[6] * v[2], R[1] * v[0] + R[4] * v[1] + R[7] * v[2],
            R[2] * v[0] + R[5] * v[1] + R[8] * v[2])


class DeflectionPredictor:
    """dq = C_q J(q)^T F and dx = J(q) dq for one configuration per call."""

    def __init__(self, dh, joint_stiffness_Nm_per_rad, tool_m=None):
        self._home = [float(v) for v in dh.home_rad]
        self._d = [float(v) for v in dh.d_m]
        self._a = [float(v) for v in dh.a_m]
        self._ca = [math.cos(v) for v in dh.alpha_rad]
        self._sa = [math.sin(v) for v in dh.alpha_rad]
        tool = np.zeros(3) if tool_m is None else np.asarray(tool_m, dtype=float)
        self._tool = [float(v) for v in tool]
        base = np.eye(4) if getattr(dh, "base", None) is None else np.asarray(dh.base, dtype=float)
        self._base = tuple(float(v) for v in base[:3, :3].ravel()) + tuple(float(v) for v in base[:3, 3])
        # The last chains, shared by every predictor of the same arm and tool
        # (the plant's and the compensator's differ only in stiffness).
        key = (tuple(self._home), tuple(self._d), tuple(self._a), tuple(self._ca), tuple(self._sa), tuple(self._tool),
               self._base)
        self._memo = _SHARED_CHAINS.setdefault(key, {})
        self.set_joint_stiffness(joint_stiffness_Nm_per_rad)

    def set_joint_stiffness(self, joint_stiffness_Nm_per_rad):
        k = np.asarray(joint_stiffness_Nm_per_rad, dtype=float).reshape(6)
        if np.any(k <= 0):
            raise ValueError("joint stiffness must be positive")
        self._c = [1.0 / float(v) for v in k]

    @property
    def joint_compliance(self):
        """The joint compliances (rad/(N*m)) this predictor uses."""
        return np.array(self._c)

    @property
    def joint_compliance_list(self):
        """The joint compliances (rad/(N*m)) as a list of floats."""
        return self._c

    def flange_rotation_and_tool_point(self, q_rad):
        """Rotation of DH frame 6 (3x3 numpy) and the tool point (m), base frame."""
        T = self._chain(q_rad)[1]
        R = np.array(T[:9]).reshape(3, 3)
        return R, np.array(T[9:])

    def pose(self, q_rad):
        """(R row-major 9 floats, tool point 3 floats, m): the flange rotation
        and the tool point in the base frame, as a tuple (no numpy)."""
        return self._chain(q_rad)[1]

    def joint_torques(self, q_rad, wrench):
        """tau = J(q)^T W (N*m) as a list, for a wrench (N, N*m about the tool
        point, base frame)."""
        f0, f1, f2, f3, f4, f5 = wrench
        return [j0 * f0 + j1 * f1 + j2 * f2 + j3 * f3 + j4 * f4 + j5 * f5
                for j0, j1, j2, j3, j4, j5 in self.jacobian_rows(q_rad)]

    def jacobian_rows(self, q_rad):
        """Six Jacobian columns as tuples (jvx, jvy, jvz, jwx, jwy, jwz)."""
        return self._chain(q_rad)[2]

    def _chain(self, q_rad):
        """Joint axes/origins (six tuples), (R row-major 9 values, tool
        point 3) and the six Jacobian columns.  The blocks of a controller cycle ask for the same few q
        (the plant's now and the one sampled a period ago), so the last
        ``MEMO_SIZE`` results are kept."""
        q = tuple(q_rad.tolist() if hasattr(q_rad, "tolist") else q_rad)
        memo = self._memo
        chain = memo.get(q)
        if chain is None:
            if len(memo) >= MEMO_SIZE:
                del memo[next(iter(memo))]  # the oldest
            chain = memo[q] = self._chain_uncached(q)
        return chain

    def pose_only(self, q_rad):
        """``pose`` without the Jacobian (for a caller that needs only the
        tool's pose: less arithmetic): with numba the compiled kernel
        (model/tick_kernels.py; the same arithmetic to round-off), else a
        memoised chain if there is one or the chain's plain arithmetic.
        (Not on the ``compensate`` process's path: a first call may
        compile; tick_kernels.warm_up first.)"""
        if jit.available():
            out = np.empty(12)
            tick_kernels.pose_and_deflection(np.asarray(q_rad, dtype=float), self.chain_constants(), _NONE, _NONE,
                                             _NONE, out)
            return tuple(out.tolist())
        q = tuple(q_rad.tolist() if hasattr(q_rad, "tolist") else q_rad)
        chain = self._memo.get(q)
        return chain[1] if chain is not None else self._forward(q, None)

    def chain_constants(self):
        """The chain's constants as model/tick_kernels.py packs them (a
        float array of CHAIN_SIZE, kept)."""
        k = getattr(self, "_chain_k", None)
        if k is None:
            k = self._chain_k = np.array(self._home + self._d + self._a + self._ca + self._sa + self._tool
                                         + list(self._base), dtype=float)
        return k

    def _chain_uncached(self, q_rad):
        axes = []
        pose = self._forward(q_rad, axes)
        px, py, pz = pose[9:]
        cols = []  # Jacobian columns: (z x (p - o), z)
        for zx, zy, zz, ox, oy, oz in axes:
            ex, ey, ez = px - ox, py - oy, pz - oz
            cols.append((zy * ez - zz * ey, zz * ex - zx * ez, zx * ey - zy * ex, zx, zy, zz))
        return axes, pose, tuple(cols)

    def _forward(self, q_rad, axes):
        """(R row-major 9, tool point 3) of the tool frame; each joint's axis
        and origin appended to ``axes`` when it is a list."""
        # Rotation R (rows r0..r8) and position p of the current frame, from
        # the chain's base transform.
        r0, r1, r2, r3, r4, r5, r6, r7, r8, px, py, pz = self._base
        home, d, a, ca, sa = self._home, self._d, self._a, self._ca, self._sa
        for i, qi in enumerate(q_rad):
            if axes is not None:
                axes.append((r2, r5, r8, px, py, pz))  # z axis and origin of frame i
            th = qi + home[i]
            ct, st = math.cos(th), math.sin(th)
            c, s = ca[i], sa[i]
            # A = [[ct, -st c, st s, a ct], [st, ct c, -ct s, a st], [0, s, c, d]]
            n0 = r0 * ct + r1 * st
            n3 = r3 * ct + r4 * st
            n6 = r6 * ct + r7 * st
            m0 = -r0 * st + r1 * ct
            m3 = -r3 * st + r4 * ct
            m6 = -r6 * st + r7 * ct
            px += a[i] * n0 + d[i] * r2
            py += a[i] * n3 + d[i] * r5
            pz += a[i] * n6 + d[i] * r8
            r0, r1, r2 = n0, m0 * c + r2 * s, -m0 * s + r2 * c
            r3, r4, r5 = n3, m3 * c + r5 * s, -m3 * s + r5 * c
            r6, r7, r8 = n6, m6 * c + r8 * s, -m6 * s + r8 * c
        tx, ty, tz = self._tool
        px += r0 * tx + r1 * ty + r2 * tz
        py += r3 * tx + r4 * ty + r5 * tz
        pz += r6 * tx + r7 * ty + r8 * tz
        return (r0, r1, r2, r3, r4, r5, r6, r7, r8, px, py, pz)

    def __call__(self, q_rad, wrench):
        """Return (dq, dx) as numpy arrays: joint deflection (rad) and the
        tool's deflection (m, rad) under ``wrench`` at the measured q."""
        cols = self.jacobian_rows(q_rad)
        dq = [c * t for c, t in zip(self._c, self.joint_torques(q_rad, wrench.tolist() if hasattr(wrench, "tolist")
                                                                    else wrench))]
        dx = [sum(col[r] * dqi for dqi, col in zip(dq, cols)) for r in range(6)]
        return np.array(dq), np.array(dx)

    def jacobian(self, q_rad):
        """The 6x6 Jacobian (same convention as kinematics.jacobian)."""
        return np.array(self.jacobian_rows(q_rad)).T
