"""A modal test as a user runs one on the cell: hammer blows on the tool
in x, y and z with the drives on, the tool's response recorded by an
accelerometer (here its displacement: the same poles), and the modes
fitted from the response by the Eigensystem Realization Algorithm (Juang
and Pappa, J. Guidance 8(5), 1985), the standard time-domain fit of
modal test software.  Plain numpy/scipy; the system to test is given as
matrices (diagrams/user_measurements.py builds them from the station's
joints at a pose).

Units: s, Hz, the response's own units (m per N*s of impulse).
"""

import numpy as np
from scipy import linalg

# The fit's model order (states): the arm's six modes and the drives' own
# poles with room to spare; the noise's modes are told apart by their
# damping and frequency (MODE_RANGE).
ERA_ORDER = 36
STABLE_DROP = 4
NOISE_GAP = 3.0
# A mode whose peak response is below this fraction of the largest one's is the noise's.
MIN_AMPLITUDE = 0.001
HANKEL_COLUMNS = 400  # samples per Hankel row (0.4 s at 1 kHz: two periods of the slowest mode)
# What a fitted pole must be to count as a structural mode: lightly
# damped, below the test's useful band (ASSUMPTION: an impact hammer with a
# medium tip excites up to about 500 Hz; modes above 300 Hz are not the
# arm's).
MODE_RANGE = {"damping": (0.002, 0.4), "hz": (1.0, 300.0)}


def impulse_response(A, B, C, dt_s, duration_s, noise_rel=0.01, seed=0):
    """(k, outputs, inputs): the response of the continuous system
    (A, B, C) sampled every dt_s to a unit impulse on each input (the
    hammer's blow: the state jumps by B), with white measurement noise of
    ``noise_rel`` times each output's largest value (1 sigma)."""
    Ad = linalg.expm(np.asarray(A, dtype=float) * dt_s)
    n_k = int(round(duration_s / dt_s))
    X = np.asarray(B, dtype=float).copy()
    out = np.empty((n_k, C.shape[0], B.shape[1]))
    for k in range(n_k):
        out[k] = C @ X
        X = Ad @ X
    rng = np.random.default_rng(seed)
    scale = np.abs(out).max(axis=(0, 2), keepdims=True)
    return out + noise_rel * scale * rng.standard_normal(out.shape)


def _poles(U, S, Vt, H1, n, dt_s, p, m):
    """(frequencies Hz, damping ratios, peak amplitudes) of the poles of
    the n-state realisation; a pole's amplitude: its mode's peak response
    |C phi| |psi B| / (1 - |lambda|) in acceleration (times omega^2; the
    noise's poles carry little)."""
    Si = np.diag(1.0 / np.sqrt(S[:n]))
    Ar = Si @ U[:, :n].T @ H1 @ Vt[:n].T @ Si
    Br = np.diag(np.sqrt(S[:n])) @ Vt[:n, :m]
    Cr = U[:p, :n] @ np.diag(np.sqrt(S[:n]))
    lam_d, phi = np.linalg.eig(Ar)
    psi = np.linalg.inv(phi)
    amp = (np.linalg.norm(Cr @ phi, axis=0) * np.linalg.norm(psi @ Br, axis=1)
           / np.maximum(1.0 - np.abs(lam_d), 1e-12))
    lam = np.log(lam_d.astype(complex)) / dt_s
    up = lam.imag > 0
    lam, amp = lam[up], amp[up] * np.abs(lam[up]) ** 2  # as an accelerometer sees it: times omega^2
    return np.abs(lam) / (2 * np.pi), -lam.real / np.abs(lam), amp


def era_modes(response, dt_s, order=ERA_ORDER, rows=None):
    """(frequencies Hz, damping ratios) of the modes fitted to an impulse
    response (k, outputs, inputs) by ERA: the poles of the fit of as
    many states as singular values of the Hankel matrix stand NOISE_GAP
    times above the noise's floor (at most ``order``) that a fit of
    STABLE_DROP more states also finds
    (within 1 % in frequency and 20 % in damping: a stabilisation check,
    as modal software's stabilisation diagram; a pole of the noise moves
    with the order), in MODE_RANGE, whose peak response is at least
    MIN_AMPLITUDE of the largest's, ascending."""
    Y = np.asarray(response, dtype=float)
    n_k, p, m = Y.shape
    r = rows or min(n_k // 4, 60)
    s = min(n_k - r - 2, HANKEL_COLUMNS)
    H0 = np.empty((r * p, s * m))
    H1 = np.empty((r * p, s * m))
    for i in range(r):
        H0[i * p:(i + 1) * p] = Y[i + 1:i + 1 + s].transpose(1, 0, 2).reshape(p, s * m)
        H1[i * p:(i + 1) * p] = Y[i + 2:i + 2 + s].transpose(1, 0, 2).reshape(p, s * m)
    # the SVD of the wide H0 from the small H0 H0^T (rows x rows)
    S2, U = np.linalg.eigh(H0 @ H0.T)
    idx = np.argsort(S2)[::-1]
    S2, U = np.maximum(S2[idx], 1e-300), U[:, idx]
    S = np.sqrt(S2)
    Vt = (H0.T @ U / S).T
    # the model order: the singular values above the noise's floor (the median of those past ``order``)
    floor = float(np.median(S[order:2 * order])) if len(S) > order else 0.0
    n = int(np.clip(np.count_nonzero(S > NOISE_GAP * floor), 2, order))
    n += n % 2
    f, z, amp = _poles(U, S, Vt, H1, n, dt_s, p, m)
    f2, z2, _ = _poles(U, S, Vt, H1, min(n + STABLE_DROP, len(S)), dt_s, p, m)
    stable = np.array([np.any((np.abs(f2 - fi) < 0.01 * fi) & (np.abs(z2 - zi) < 0.2 * zi)) for fi, zi in zip(f, z)],
                      dtype=bool)
    lo, hi = MODE_RANGE["damping"]
    keep = stable & (z > lo) & (z < hi) & (f > MODE_RANGE["hz"][0]) & (f < MODE_RANGE["hz"][1])
    keep &= amp > MIN_AMPLITUDE * amp[keep].max(initial=0.0)
    order_ = np.argsort(f[keep])
    return f[keep][order_], z[keep][order_]


def merge_close(freqs_hz, ratios, rel=0.03):
    """The fitted modes with those within ``rel`` of each other in frequency
    merged (a mode fitted twice, once per blow direction's share), their
    damping averaged."""
    out_f, out_z = [], []
    for f, z in zip(freqs_hz, ratios):
        if out_f and abs(f - out_f[-1][-1]) <= rel * f:
            out_f[-1].append(f)
            out_z[-1].append(z)
        else:
            out_f.append([f])
            out_z.append([z])
    return np.array([np.mean(v) for v in out_f]), np.array([np.mean(v) for v in out_z])
