"""The plant's cutting law (model/plant_cutting.py) as scalar loops, for
compilation (model/jit.py): its revolution average, the arithmetic of every
averaged force update of the closed loop.  The same sums as the numpy
reference (``PlantCuttingLaw.average_wrench`` with numba absent), in
another order: equal to round-off (tests/test_jit_kernels.py).  Also the
linear model's revolution average (MillingForceModel.average_wrench, which
predictive compensation evaluates a few times a tick:
``linear_average_wrench``), its operations in its order
(tests/test_predictive_wrench.py).  Plain Python, no Drake.
"""

import math

import numpy as np

from robstiff_drake.model.jit import kernel


@kernel
def lead_arcs(tool_x, tool_y, tool_z, u0, u1, boxes, radius_m):
    """(arcs (k, 3), n): the first n rows are the engaged arcs of the
    cutter's leading half (theta_a, theta_b rad, depth m) at the tool point
    (``tool_x``, ``tool_y``, ``tool_z``, m) in ``boxes`` ((B, 5): x0, x1,
    y0, y1, top, m) for the feed direction (u0, u1):
    MillingForceModel.lead_intervals's operations in its order (the arcs
    it returns, each the same floats)."""
    phi = math.atan2(u1, u0)
    half_pi = 0.5 * math.pi
    cuts = np.empty(2 + 8 * boxes.shape[0])
    cuts[0], cuts[1] = -half_pi, half_pi
    m = 2
    n_in = 0
    for b in range(boxes.shape[0]):
        if boxes[b, 4] <= tool_z:
            continue
        n_in += 1
        for X in (boxes[b, 0], boxes[b, 1]):
            r = (X - tool_x) / radius_m
            if -1.0 < r < 1.0:
                a = math.acos(r)
                cuts[m], cuts[m + 1] = a - phi, -a - phi
                m += 2
        for Y in (boxes[b, 2], boxes[b, 3]):
            r = (Y - tool_y) / radius_m
            if -1.0 < r < 1.0:
                a = math.asin(r)
                cuts[m], cuts[m + 1] = a - phi, math.pi - a - phi
                m += 2
    if n_in == 0:
        return np.empty((0, 3)), 0
    two_pi = 2 * math.pi
    angles = np.empty(m)
    k = 0
    for i in range(m):
        t = (cuts[i] + math.pi) % two_pi - math.pi
        if -half_pi <= t <= half_pi:
            angles[k] = t
            k += 1
    angles = np.sort(angles[:k])
    arcs = np.empty((max(k - 1, 0), 3))
    n_arcs = 0
    prev = math.nan
    for i in range(k):
        tb = angles[i]
        if i == 0 or tb != prev:  # (the distinct angles, as a set)
            if i > 0:
                ta = prev
                tm = 0.5 * (ta + tb) + phi
                x, y = tool_x + radius_m * math.cos(tm), tool_y + radius_m * math.sin(tm)
                depth = 0.0
                for b in range(boxes.shape[0]):
                    d = boxes[b, 4] - tool_z
                    if d > 0.0 and d > depth and boxes[b, 0] <= x <= boxes[b, 1] and boxes[b, 2] <= y <= boxes[b, 3]:
                        depth = d
                if depth > 0.0:
                    if n_arcs > 0 and arcs[n_arcs - 1, 1] == ta and arcs[n_arcs - 1, 2] == depth:
                        arcs[n_arcs - 1, 1] = tb
                    else:
                        arcs[n_arcs, 0], arcs[n_arcs, 1], arcs[n_arcs, 2] = ta, tb, depth
                        n_arcs += 1
            prev = tb
    return arcs, n_arcs


@kernel
def linear_average_wrench(tool_x, tool_y, tool_z, u0, u1, boxes, radius_m, basis):
    """MillingForceModel.average_wrench at its own feed: the wrench (6,:
    force N, moment N*m about the tool point, base frame) averaged over a
    revolution at the tool point (``tool_x``, ``tool_y``, ``tool_z``, m) in
    ``boxes`` ((B, 5), as ``lead_arcs``) for the feed direction (u0, u1);
    ``basis`` (6, 5): the model's ``_basis`` (its rows' coefficients of the
    integrals of 1, c, s, c s, c^2 over the engaged arcs)."""
    arcs, n_arcs = lead_arcs(tool_x, tool_y, tool_z, u0, u1, boxes, radius_m)
    S0 = S1 = S2 = S3 = S4 = 0.0
    for i in range(n_arcs):
        ta, tb, a = arcs[i, 0], arcs[i, 1], arcs[i, 2]
        sa, ca, sb, cb = math.sin(ta), math.cos(ta), math.sin(tb), math.cos(tb)
        # antiderivatives of 1, c, s, c s, c^2
        S0 += a * (tb - ta)
        S1 += a * (sb - sa)
        S2 += a * (ca - cb)
        S3 += a * 0.5 * (sb * sb - sa * sa)
        S4 += a * 0.5 * ((tb - ta) + sb * cb - sa * ca)
    w = np.empty(6)
    for r in range(6):
        w[r] = basis[r, 0] * S0 + basis[r, 1] * S1 + basis[r, 2] * S2 + basis[r, 3] * S3 + basis[r, 4] * S4
    out = np.empty(6)
    out[0] = w[0] * u0 - w[1] * u1
    out[1] = w[0] * u1 + w[1] * u0
    out[2] = w[2]
    out[3] = w[3] * u0 - w[4] * u1
    out[4] = w[3] * u1 + w[4] * u0
    out[5] = w[5]
    return out


@kernel
def average_wrench_at(tool_x, tool_y, tool_z, u0, u1, boxes, c_f, h_scale, exponent, ramp_m, Kc, Ke, radius_m,
                      k_back, dR, gauss_x, gauss_w):
    """The revolution-averaged wrench (6,: force N, moment N*m about the
    tool point, base frame) of the cutter at the tool point (``tool_x``,
    ``tool_y``, ``tool_z``, m) in ``boxes`` ((B, 5): x0, x1, y0, y1, top,
    m): the engaged arcs of the leading half as MillingForceModel's
    ``lead_intervals`` finds them, each integrated with ``gauss_x``,
    ``gauss_w`` (Gauss-Legendre nodes and weights on [-1, 1]), the feed
    direction (u0, u1), feed per tooth ``c_f`` (m), the Kienzle law
    ``h_scale`` h^``exponent`` (exponent 1: h), the edge forces ramped in up
    to a chip of ``ramp_m`` (<= 0: a step), cutting and edge coefficients
    ``Kc``, ``Ke`` (3, N/m^2 and N/m), the runout chip's ``k_back`` (n,) and
    ``dR`` (n, n) (PlantCuttingLaw.chips_m)."""
    arcs, n_arcs = lead_arcs(tool_x, tool_y, tool_z, u0, u1, boxes, radius_m)
    if n_arcs == 0:
        return np.zeros(6)
    # the average over the arcs: Gauss-Legendre points in each, every tooth's chip there (runout), the law
    n = dR.shape[0]
    kt, kr, ka = Kc[0], Kc[1], Kc[2]
    et, er, ea = Ke[0], Ke[1], Ke[2]
    # sums over the points of Ft s, Ft c, Fr s, Fr c, Fa, Fa s, Fa c, Ft
    fts = ftc = frs = frc = fa_sum = fas = fac = ft_sum = 0.0
    for i in range(n_arcs):
        ta, tb, depth = arcs[i, 0], arcs[i, 1], arcs[i, 2]
        mid, half = 0.5 * (ta + tb), 0.5 * (tb - ta)
        for g in range(gauss_x.shape[0]):
            th = mid + half * gauss_x[g]
            wt = half * gauss_w[g]
            c, s = math.cos(th), math.sin(th)
            cfc = c_f * c
            ft = fr = fa = 0.0
            for j in range(n):
                h = math.inf
                for kk in range(n):
                    v = cfc * k_back[kk] + dR[j, kk]
                    if v < h or v != v:  # (the least; a NaN wins, as numpy's min)
                        h = v
                a = depth if h >= 0.0 else 0.0
                if h < 0.0:
                    h = 0.0
                chip = h if exponent == 1.0 else h_scale * h ** exponent
                if ramp_m <= 0.0:
                    edge = a
                else:
                    r = h / ramp_m
                    if r > 1.0:
                        r = 1.0
                    edge = a * r
                ft += kt * a * chip + et * edge
                fr += kr * a * chip + er * edge
                fa += ka * a * chip + ea * edge
            ft, fr, fa = ft * wt, fr * wt, fa * wt
            fts += ft * s
            ftc += ft * c
            frs += fr * s
            frc += fr * c
            fa_sum += fa
            fas += fa * s
            fac += fa * c
            ft_sum += ft
    two_pi = 2.0 * math.pi
    fu = (-fts - frc) / two_pi
    fv = (ftc - frs) / two_pi
    fz = fa_sum / two_pi
    mu = radius_m * fas / two_pi
    mv = -radius_m * fac / two_pi
    mz = radius_m * ft_sum / two_pi
    out = np.empty(6)
    out[0] = fu * u0 - fv * u1
    out[1] = fu * u1 + fv * u0
    out[2] = fz
    out[3] = mu * u0 - mv * u1
    out[4] = mu * u1 + mv * u0
    out[5] = mz
    return out


@kernel
def tooth_wrenches_at(times_s, tool_x, tool_y, tool_z, u0, u1, phase_rad, omega_rad_per_s, tooth_angles, c_f, h_scale,
                      exponent, ramp_m, Kc, Ke, radius_m, k_back, dR, boxes):
    """(T, 6): the tooth-resolved wrench (base frame) at each of
    ``times_s``, the teeth at phase - omega t + ``tooth_angles``; the tip's
    depth the highest of ``boxes`` ((B, 5): x0, x1, y0, y1, top, m) above
    the cutter bottom ``tool_z``; the leading half cuts (cos > 0); the
    chip, law and edge as ``average_wrench_at``."""
    n = dR.shape[0]
    kt, kr, ka = Kc[0], Kc[1], Kc[2]
    et, er, ea = Ke[0], Ke[1], Ke[2]
    out = np.empty((times_s.shape[0], 6))
    for r in range(times_s.shape[0]):
        base = phase_rad - omega_rad_per_s * times_s[r]
        fu_s = fv_s = fz_s = mu_s = mv_s = mz_s = 0.0
        for j in range(n):
            th = base + tooth_angles[j]
            c, s = math.cos(th), math.sin(th)
            x = tool_x + radius_m * (c * u0 - s * u1)
            y = tool_y + radius_m * (c * u1 + s * u0)
            depth = 0.0
            if c > 0.0:  # (the leading half cuts)
                for b in range(boxes.shape[0]):
                    top = boxes[b, 4]
                    if top > tool_z and boxes[b, 0] <= x <= boxes[b, 1] and boxes[b, 2] <= y <= boxes[b, 3]:
                        d = top - tool_z
                        if d > depth:
                            depth = d
            cfc = c_f * c
            h = math.inf
            for kk in range(n):
                v = cfc * k_back[kk] + dR[j, kk]
                if v < h or v != v:
                    h = v
            a = depth if h >= 0.0 else 0.0
            if h < 0.0:
                h = 0.0
            chip = h if exponent == 1.0 else h_scale * h ** exponent
            if ramp_m <= 0.0:
                edge = a
            else:
                q = h / ramp_m
                if q > 1.0:
                    q = 1.0
                edge = a * q
            ft = kt * a * chip + et * edge
            fr = kr * a * chip + er * edge
            fa = ka * a * chip + ea * edge
            fu = -ft * s - fr * c
            fv = ft * c - fr * s
            fu_s += fu
            fv_s += fv
            fz_s += fa
            mu_s += radius_m * s * fa
            mv_s += -radius_m * c * fa
            mz_s += radius_m * (c * fv - s * fu)
        out[r, 0] = fu_s * u0 - fv_s * u1
        out[r, 1] = fu_s * u1 + fv_s * u0
        out[r, 2] = fz_s
        out[r, 3] = mu_s * u0 - mv_s * u1
        out[r, 4] = mu_s * u1 + mv_s * u0
        out[r, 5] = mz_s
    return out
