"""The closed loop's per-tick kinematics and compensator arithmetic as
compiled kernels (model/jit.py): the tool's pose from the link angles (the
milling force's update, model/realtime.DeflectionPredictor.pose_only) and
the compensator tick's whole update (systems/compensator_tick.py: the
carried wrench guard, gravity removal, the deflection prediction
dq = C J(q)^T W, the saturation, the delay line and the rate-limited
correction; ``tick_update`` runs it all in one call on the tick's state).

The same scalar operations in the same order as the plain-Python
references they replace (model/realtime.DeflectionPredictor._forward and
_chain_uncached, model/payload.payload_weight, model/wrench_frames,
model/compensator.rate_limited_step, compensator_tick.saturate), so the
compiled results equal them to round-off (tests/test_tick_kernels.py).
Without numba (or with ROBSTIFF_NO_JIT set) the callers keep those
references: the kernel's Python original, indexing numpy arrays one value
at a time, would be slower than them.  The real-time ``compensate``
process (cell/compensate.py, model/compensator.Compensator) does not call
these kernels: it stays on the references, so no compilation can land in
its loop.

Constant packing (float64 arrays): ``chain`` (CHAIN_SIZE, ``chain_constants``):
the DH home angles, d, a (m), cos alpha, sin alpha (6 each), the tool point in
the flange frame (3, m), the base rotation (9, row-major) and origin (3, m);
``gravity`` (GRAVITY_SIZE, ``gravity_constants``): the bias (6: N, N*m), the
payload's mass (kg) and centre of mass (3, m, sensor frame), the sensor
mount's rotation as the calibration has it (9), the base-frame gravity (3,
m/s^2); ``model`` (MODEL_SIZE, ``model_constants``): the deflection model's
mount rotation (9), 1.0 when it is the identity (else 0.0), the tool point in
the sensor frame (3, m) and the joint compliances (6, rad/(N*m)).  ``tick_update``
takes all of its constants packed in one float64 array and their offsets in one
int64 array (``pack_tick_constants``): numba's dispatcher costs about 0.05 us
per argument and call.
"""

import math

import numpy as np

from robstiff_drake.model import jit
from robstiff_drake.model.jit import kernel

CHAIN_SIZE = 45
GRAVITY_SIZE = 22
MODEL_SIZE = 19


def chain_constants(predictor):
    """``chain`` (see the module docstring) of a model/realtime.DeflectionPredictor."""
    return np.array(predictor.chain_constants(), dtype=float)


def gravity_constants(remover, gravity_m_per_s2):
    """``gravity`` of a model/compensator.GravityRemover."""
    return np.array(list(remover._bias) + [remover._m] + list(remover._c) + list(remover._R_mount)
                    + list(gravity_m_per_s2), dtype=float)


def model_constants(model):
    """``model`` of a model/compensator.DeflectionModel (linear: no lost motion, no coupling)."""
    return np.array(list(model._R_mount) + [1.0 if model._identity_mount else 0.0] + list(model._r_s)
                    + list(model._pred.joint_compliance_list), dtype=float)


@kernel
def pose_and_deflection(q, chain, w, gravity, model, out):
    """Writes the tool's pose (row-major flange rotation 9, tool point 3,
    m, base frame) to ``out[:12]`` for link angles ``q`` (6, rad); with
    ``out`` of 18 or more, also the process wrench ``w`` - bias - the
    payload's weight at q (6, sensor frame) to ``out[12:18]``; with ``out``
    of 24, dq = C J(q)^T W (6, rad) of it to ``out[18:24]``."""
    r0, r1, r2, r3, r4, r5 = chain[33], chain[34], chain[35], chain[36], chain[37], chain[38]
    r6, r7, r8, px, py, pz = chain[39], chain[40], chain[41], chain[42], chain[43], chain[44]
    axes = np.empty((6, 6))
    for i in range(6):
        axes[i, 0], axes[i, 1], axes[i, 2], axes[i, 3], axes[i, 4], axes[i, 5] = r2, r5, r8, px, py, pz
        th = q[i] + chain[i]
        ct, st = math.cos(th), math.sin(th)
        c, s, a, d = chain[18 + i], chain[24 + i], chain[12 + i], chain[6 + i]
        n0 = r0 * ct + r1 * st
        n3 = r3 * ct + r4 * st
        n6 = r6 * ct + r7 * st
        m0 = -r0 * st + r1 * ct
        m3 = -r3 * st + r4 * ct
        m6 = -r6 * st + r7 * ct
        px += a * n0 + d * r2
        py += a * n3 + d * r5
        pz += a * n6 + d * r8
        r0, r1, r2 = n0, m0 * c + r2 * s, -m0 * s + r2 * c
        r3, r4, r5 = n3, m3 * c + r5 * s, -m3 * s + r5 * c
        r6, r7, r8 = n6, m6 * c + r8 * s, -m6 * s + r8 * c
    tx, ty, tz = chain[30], chain[31], chain[32]
    px += r0 * tx + r1 * ty + r2 * tz
    py += r3 * tx + r4 * ty + r5 * tz
    pz += r6 * tx + r7 * ty + r8 * tz
    R = (r0, r1, r2, r3, r4, r5, r6, r7, r8)
    for i in range(9):
        out[i] = R[i]
    out[9], out[10], out[11] = px, py, pz
    if out.shape[0] < 18:
        return
    # the payload's weight (model/payload.payload_weight) and the process wrench (GravityRemover)
    G0, G1, G2 = gravity[19], gravity[20], gravity[21]
    v0 = r0 * G0 + r3 * G1 + r6 * G2
    v1 = r1 * G0 + r4 * G1 + r7 * G2
    v2 = r2 * G0 + r5 * G1 + r8 * G2
    M = gravity[10:19]
    gx = M[0] * v0 + M[3] * v1 + M[6] * v2
    gy = M[1] * v0 + M[4] * v1 + M[7] * v2
    gz = M[2] * v0 + M[5] * v1 + M[8] * v2
    mass = gravity[6]
    fx, fy, fz = mass * gx, mass * gy, mass * gz
    cx, cy, cz = gravity[7], gravity[8], gravity[9]
    weight = (fx, fy, fz, cy * fz - cz * fy, cz * fx - cx * fz, cx * fy - cy * fx)
    for i in range(6):
        out[12 + i] = w[i] - gravity[i] - weight[i]
    if out.shape[0] < 24:
        return
    # the wrench at the tool point, base frame (DeflectionModel.tool_wrench, wrench_to_tool_base)
    if model[9] == 0.0:
        Mm = model[:9]
        Rs = np.empty(9)
        for i in range(3):
            for j in range(3):
                Rs[3 * i + j] = R[3 * i] * Mm[j] + R[3 * i + 1] * Mm[3 + j] + R[3 * i + 2] * Mm[6 + j]
        s0, s1, s2, s3, s4, s5, s6, s7, s8 = Rs[0], Rs[1], Rs[2], Rs[3], Rs[4], Rs[5], Rs[6], Rs[7], Rs[8]
    else:
        s0, s1, s2, s3, s4, s5, s6, s7, s8 = r0, r1, r2, r3, r4, r5, r6, r7, r8
    wx, wy, wz, mx, my, mz = out[12], out[13], out[14], out[15], out[16], out[17]
    rx, ry, rz = model[10], model[11], model[12]
    bx, by, bz = mx - (ry * wz - rz * wy), my - (rz * wx - rx * wz), mz - (rx * wy - ry * wx)
    F = (s0 * wx + s1 * wy + s2 * wz, s3 * wx + s4 * wy + s5 * wz, s6 * wx + s7 * wy + s8 * wz,
         s0 * bx + s1 * by + s2 * bz, s3 * bx + s4 * by + s5 * bz, s6 * bx + s7 * by + s8 * bz)
    # tau = J^T W (the Jacobian's columns z x (p - o), z: DeflectionPredictor._chain_uncached), dq = C tau
    for i in range(6):
        zx, zy, zz, ox, oy, oz = axes[i, 0], axes[i, 1], axes[i, 2], axes[i, 3], axes[i, 4], axes[i, 5]
        ex, ey, ez = px - ox, py - oy, pz - oz
        tau = ((zy * ez - zz * ey) * F[0] + (zz * ex - zx * ez) * F[1] + (zx * ey - zy * ex) * F[2]
               + zx * F[3] + zy * F[4] + zz * F[5])
        out[18 + i] = model[13 + i] * tau


@kernel
def correction_step(dq, line, c, lo, hi, step, out):
    """The compensator tick's saturation, delay line and rate-limited
    correction (systems/compensator_tick.CompensatorTick's update): ``dq``
    (6, rad) the deflection of the last sample, ``line`` (6 n, oldest
    first) the delay line, ``c`` (6, rad) the held correction.  Writes the
    new line to ``out[:6 n]`` and the new correction to ``out[6 n:]`` (the
    held one when the delayed deflection is not finite)."""
    n6 = line.shape[0]
    s = np.empty(6)
    for i in range(6):
        v = dq[i]
        s[i] = lo[i] if v < lo[i] else (hi[i] if v > hi[i] else v)
    if n6:
        d = line[:6].copy()
        for i in range(n6 - 6):
            out[i] = line[6 + i]
        for i in range(6):
            out[n6 - 6 + i] = s[i]
    else:
        d = s
    total = 0.0
    for i in range(6):
        total += d[i]
    finite = math.isfinite(total)
    for i in range(6):
        x = c[i]
        if finite:  # (rate_limited_step: x + min(s, max(-s, -d - x)), Python's min and max exactly)
            a = -d[i] - x
            b = a if a > -step[i] else -step[i]
            out[n6 + i] = x + (b if b < step[i] else step[i])
        else:
            out[n6 + i] = x


# The compensator tick's state layout for ``tick_update`` (int64 offsets into its one state group; -1: absent):
# the sampled wrench, the sampled q, the process wrench, dq, the delay line, its length (6 n), the correction,
# the carried guard's last good sample, its rejections so far and in a row, the carried force filter's output
# and its state.
TICK_AT_SIZE = 12
# then (pack_tick_constants) where each of the TICK_PIECES packed constants starts and where the last ends, and
# the force filter's order
TICK_PIECES = 11
TICK_OFFSETS_SIZE = TICK_AT_SIZE + TICK_PIECES + 2


@kernel
def filter_state_step(A, B, xf, u):
    """The force filter's discrete update (Drake's LinearSystem,
    systems/force_filter.filter_system): ``xf`` (n) <- A xf + B u for the
    filter's input ``u`` (6) before this update, in place.  Each product is
    summed in the column order from 0.0 and the two added last, as Drake's
    Eigen products do: the same bits (tests/test_tick_filter.py)."""
    n = xf.shape[0]
    nxt = np.empty(n)
    for i in range(n):
        s1 = 0.0
        for j in range(n):
            s1 += A[i, j] * xf[j]
        s2 = 0.0
        for j in range(u.shape[0]):
            s2 += B[i, j] * u[j]
        nxt[i] = s1 + s2
    for i in range(n):
        xf[i] = nxt[i]


@kernel
def filter_output(C, D, xf, u, y):
    """The force filter's output y = C xf + D u (6) written to ``y``, in
    ``filter_state_step``'s order (Drake's LinearSystem output)."""
    for i in range(y.shape[0]):
        s1 = 0.0
        for j in range(xf.shape[0]):
            s1 += C[i, j] * xf[j]
        s2 = 0.0
        for j in range(u.shape[0]):
            s2 += D[i, j] * u[j]
        y[i] = s1 + s2


def pack_tick_constants(at, guard, chain, gravity, model, lo, hi, step, fA, fB, fC, fD):
    """(consts, offsets) for ``tick_update``: the float64 constants (the
    guard's 2, ``chain``, ``gravity``, ``model``, ``lo``, ``hi``, ``step``
    and the force filter's matrices ``fA``-``fD`` row-major, in that
    order) in one array, and int64 ``offsets``: the state layout ``at``
    (TICK_AT_SIZE), then where each of those TICK_PIECES constants starts
    in ``consts`` and where the last ends, then the filter's order n (0
    without one).  Built once: two arguments in place of twelve, each of
    which costs numba's dispatcher its type's look-up at every call."""
    n = np.shape(fA)[0]
    if n and (np.shape(fA) != (n, n) or np.shape(fB) != (n, 6) or np.shape(fC) != (6, n) or np.shape(fD) != (6, 6)):
        raise ValueError(f"a carried force filter takes and gives a wrench (6): A {np.shape(fA)}, B {np.shape(fB)}, "
                         f"C {np.shape(fC)}, D {np.shape(fD)}")
    pieces = [np.ravel(np.asarray(v, dtype=float)) for v in (guard, chain, gravity, model, lo, hi, step,
                                                              fA, fB, fC, fD)]
    starts = np.cumsum([0] + [len(v) for v in pieces])
    offsets = np.concatenate((np.asarray(at, dtype=np.int64), starts, [n])).astype(np.int64)
    return np.concatenate(pieces), offsets


@kernel
def tick_update(x, raw, w, q, dq_in, consts, at):
    """The compensator tick's whole update on its state ``x`` (one group,
    written in place; offsets ``at[:TICK_AT_SIZE]``: see above; the
    constants packed in ``consts`` by ``pack_tick_constants``), in the
    order systems/compensator_tick.CompensatorTick's update takes it: with a
    carried guard (``at[7]`` >= 0; ``guard``: max jump N, the rejections in
    a row that re-arm it) the raw sample ``raw`` (6) through
    systems/wrist_sensor.guard_step's arithmetic; then ``correction_step``
    on the held dq (or ``dq_in`` where ``at[3]`` < 0), the delay line and
    the correction; then this tick's sample: the filtered wrench ``w`` and
    the joint angles ``q`` (6 each), their process wrench and dq
    (``pose_and_deflection``).  With a carried force filter (``at[10]``
    >= 0: its output held at ``at[10]``, its state at ``at[11]``, matrices
    ``fA``-``fD``) the tick samples the filter's held output instead of
    ``w``, the filter steps on the guard's sample before the guard's update
    (``filter_state_step``) and its output is held anew from the guard's new
    one (``filter_output``): the separate LinearSystem's values at every
    instant.  Nothing is computed that the separate kernels do not: the
    same values bit for bit."""
    c = TICK_AT_SIZE  # (the constants' starts: guard, chain, gravity, model, lo, hi, step, fA, fB, fC, fD, end)
    guard, chain = consts[at[c]:at[c + 1]], consts[at[c + 1]:at[c + 2]]
    gravity, model = consts[at[c + 2]:at[c + 3]], consts[at[c + 3]:at[c + 4]]
    lo, hi, step = consts[at[c + 4]:at[c + 5]], consts[at[c + 5]:at[c + 6]], consts[at[c + 6]:at[c + 7]]
    nf = at[c + TICK_PIECES + 1]
    f = at[10]
    ws = np.empty(6)
    for i in range(6):
        ws[i] = x[f + i] if f >= 0 else w[i]
    if f >= 0:  # (the filter's update reads the guard's sample before the guard's own update)
        fA, fB = consts[at[c + 7]:at[c + 8]].reshape((nf, nf)), consts[at[c + 8]:at[c + 9]].reshape((nf, 6))
        filter_state_step(fA, fB, x[at[11]:at[11] + nf], x[at[7]:at[7] + 6])
    g = at[7]
    if g >= 0:  # (guard_step: model/compensator.guard_accepts, then the re-arm)
        mj = guard[0]
        if (abs(raw[0] - x[g]) <= mj and abs(raw[1] - x[g + 1]) <= mj and abs(raw[2] - x[g + 2]) <= mj
                and math.isfinite(raw[3] + raw[4] + raw[5])):
            for i in range(6):
                x[g + i] = raw[i]
            x[at[9]] = 0.0
        else:
            x[at[8]] += 1.0
            x[at[9]] += 1.0
            if x[at[9]] > guard[1]:
                finite = True
                for i in range(6):
                    if not math.isfinite(raw[i]):
                        finite = False
                if finite:
                    for i in range(6):
                        x[g + i] = raw[i]
                    x[at[9]] = 0.0
    if f >= 0:
        fC, fD = consts[at[c + 9]:at[c + 10]].reshape((6, nf)), consts[at[c + 10]:at[c + 11]].reshape((6, 6))
        filter_output(fC, fD, x[at[11]:at[11] + nf], x[g:g + 6], x[f:f + 6])
    o_dq, o_line, n6, o_c = at[3], at[4], at[5], at[6]
    buf = np.empty(n6 + 6)
    if o_dq >= 0:
        correction_step(x[o_dq:o_dq + 6], x[o_line:o_line + n6], x[o_c:o_c + 6], lo, hi, step, buf)
    else:
        correction_step(dq_in, x[o_line:o_line + n6], x[o_c:o_c + 6], lo, hi, step, buf)
    for i in range(n6):
        x[o_line + i] = buf[i]
    for i in range(6):
        x[o_c + i] = buf[n6 + i]
    res = np.empty(24 if o_dq >= 0 else 18)
    pose_and_deflection(q, chain, ws, gravity, model, res)
    o_w, o_q, o_p = at[0], at[1], at[2]
    for i in range(6):
        x[o_w + i] = ws[i]
        x[o_q + i] = q[i]
        x[o_p + i] = res[12 + i]
    if o_dq >= 0:
        for i in range(6):
            x[o_dq + i] = res[18 + i]


@kernel
def sensor_ripples(inst, w, pose, tool, values):
    """The tooth-resolved milling force's table (systems/milling_force.py):
    for each row i of ``inst`` (k, 6: instantaneous wrenches, base frame,
    at the tool point), the ripple ``inst[i] - w`` as the wrist sensor sees
    it (model/wrench_frames.to_sensor_frame with the flange rotation
    ``pose[:9]`` and the tool point ``tool`` (3, m, flange frame)) written to
    ``values[i, 6:12]``."""
    R = pose
    tx, ty, tz = tool[0], tool[1], tool[2]
    for i in range(inst.shape[0]):
        d0, d1, d2 = inst[i, 0] - w[0], inst[i, 1] - w[1], inst[i, 2] - w[2]
        d3, d4, d5 = inst[i, 3] - w[3], inst[i, 4] - w[4], inst[i, 5] - w[5]
        f0 = R[0] * d0 + R[3] * d1 + R[6] * d2
        f1 = R[1] * d0 + R[4] * d1 + R[7] * d2
        f2 = R[2] * d0 + R[5] * d1 + R[8] * d2
        m0 = R[0] * d3 + R[3] * d4 + R[6] * d5
        m1 = R[1] * d3 + R[4] * d4 + R[7] * d5
        m2 = R[2] * d3 + R[5] * d4 + R[8] * d5
        values[i, 6], values[i, 7], values[i, 8] = f0, f1, f2
        values[i, 9] = m0 + ty * f2 - tz * f1
        values[i, 10] = m1 + tz * f0 - tx * f2
        values[i, 11] = m2 + tx * f1 - ty * f0


def warm_up(chain):
    """Load (or compile) the milling force's kernels now (the tool's pose
    for the chain constants ``chain``, the sensor ripples), not in the first
    update of a timed simulation (nothing without numba).  The compensator
    tick loads its own (CompensatorTick.warm_up)."""
    if jit.available():
        none = np.empty(0)
        pose = np.zeros(12)
        pose_and_deflection(np.zeros(6), chain, none, none, none, pose)
        sensor_ripples(np.zeros((1, 6)), np.zeros(6), pose, np.zeros(3), np.zeros((2, 12)))
