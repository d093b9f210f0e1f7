"""The arm coupled to its own chip, linearised at one pose (issue 29):
is a plant whose chip follows the tool's actual motion stable, in physics
(continuous time) and in the plant's explicit scheme (discrete time)?
Plain numpy/scipy; no Drake.

The cut, linearised.  The revolution-averaged wrench on the tool (force N,
moment N*m about the tool point, base frame; model/plant_cutting.py's
``average_wrench``) depends on the tool point p (the engagement: depth of
cut, immersion) and on the chip vector f, the in-plane feed per tooth
(the plane normal to the vertical spindle: base x, y).  About an operating
point (p0, f0)

    dw = Kp dp + Kf df,        Kp (6, 3) N/m, Kf (6, 2) N/m,

both by central finite differences of the law (``linearise_law``).  The
regenerative chip: the chip a tooth cuts is the in-plane displacement of
the tool since the tooth before it, f(t) = S (p(t) - p(t - T)), T the tooth
period (S selects x, y), so

    dw(t) = Kp dp(t) + Kf S (dp(t) - dp(t - T))             (the delay law)

and well below the tooth-pass frequency (omega T << 1) its limit is a
velocity coupling, dw = Kp dp + C S dp', C = Kf T (N*s/m) (the
velocity law; the coupling studies/chip_direction.py measured, G).

The arm (``LinearArm``): x' = A x + Bw w, p = Cp x: for the robot, the
drives-closed JointModel (model/joint_dynamics.py: links on the gears,
motors, the drives' PI loops with their references held) with the wrench
entering as tau = J^T w (J the 6 x 6 geometric tool Jacobian, base frame)
and p = Jv q.  Its discrete step (``step``) is the station's: symplectic
Euler for the links with the gear torque explicit, the drives exact
(JointModel.step_map), the wrench held over the step.

Continuous time (the physics): ``velocity_law_matrix`` (the velocity law:
an ODE) and the delay law by a [n/n] Pade approximation of e^(-sT) per
chip coordinate (``pade_delay``, ``pade_roots``); ``delay_roots`` refines
each Pade root by Newton's method on the exact characteristic equation
det(s I - A0 - A1 e^(-sT)) = 0 (``refine_root``), so that the Pade
order's effect is measured, not assumed.

Discrete time (the plant's scheme, ``scheme_map``): the force source
updates every ``period_steps`` plant steps from the state at its update
(Drake applies an unrestricted update before the plant's discrete update
of the same instant: the step from t uses the wrench computed at t, from
the state at t), its chip the tool's displacement over ``window_s``
(interpolated in its history of updates, as systems/milling_force.py does)
scaled to a tooth, optionally only its component along the feed (the
plant's law: the direction is the program's) and optionally low-passed
(first order, ``cutoff_hz``, one step per update), then held over the
period.  Its spectral radius over one period decides the scheme's stability.

What this cannot say: it is linear (no play, no tooth-resolved force;
where the engagement has an edge and Kp jumps, the central difference
averages its two sides), at one pose and one
operating point, with the compensator's loop and the force sensor left
out (the compensator acts below 2 Hz), and the arm's damping is the
scenario's modal assumption.
"""

import math
from dataclasses import dataclass
from math import factorial

import numpy as np
from scipy import linalg, signal

STABLE_MARGIN = 1.0 + 1e-9  # spectral radius of a stable map (an undamped mode sits at 1)


@dataclass(frozen=True)
class LinearisedChip:
    """dw = Kp dp + Kf df (see the module docstring)."""

    Kp: np.ndarray  # (nw, np) wrench per tool displacement, N/m (moments N*m/m)
    Kf: np.ndarray  # (nw, nc) wrench per chip vector (in-plane feed per tooth), N/m
    tooth_period_s: float
    chip_rows: np.ndarray  # (nc, np) S: the chip's coordinates of the tool displacement (x, y of p)

    @property
    def velocity_coupling(self):
        """C = Kf T (nw, nc), N*s/m: the chip's low-frequency limit."""
        return self.Kf * self.tooth_period_s


def linearise_law(wrench_of, p0_m, feed_dir_xy, feed_m_per_s, tooth_period_s, dp_m=2e-5, rel_df=0.02,
                  min_chip_m=0.0):
    """The LinearisedChip of ``wrench_of(p (3,) m, u (2,) unit, feed m/s)
    -> (6,) wrench`` at the tool point p0, the feed direction u and the
    feed: central differences, the tool point by ``dp_m`` along each base
    axis, the chip vector f = feed T u by ``rel_df`` of |f| along each of
    x, y (its direction turned and its size changed as the tool's motion
    would).  ``min_chip_m``: the chip vector's size (the feed per tooth, m)
    below which the law is not linearised: a thinner one is taken at this
    size (the law's slope at the edge of its validity, not extrapolated
    below it: diagrams/chatter_check.MIN_CHIP_M says why)."""
    p0 = np.asarray(p0_m, dtype=float)
    u = np.asarray(feed_dir_xy, dtype=float)
    u = u / np.linalg.norm(u)
    T = float(tooth_period_s)
    f0 = u * max(feed_m_per_s * T, float(min_chip_m))
    Kp = np.empty((6, 3))
    for i in range(3):
        d = np.zeros(3)
        d[i] = dp_m
        Kp[:, i] = (np.asarray(wrench_of(p0 + d, u, feed_m_per_s)) - np.asarray(wrench_of(p0 - d, u, feed_m_per_s))) / (
            2 * dp_m)
    Kf = np.empty((6, 2))
    df = rel_df * np.linalg.norm(f0)
    for i in range(2):
        w = []
        for sg in (1.0, -1.0):
            f = f0.copy()
            f[i] += sg * df
            n = np.linalg.norm(f)
            w.append(np.asarray(wrench_of(p0, f / n, n / T), dtype=float))
        Kf[:, i] = (w[0] - w[1]) / (2 * df)
    return LinearisedChip(Kp=Kp, Kf=Kf, tooth_period_s=T, chip_rows=np.eye(3)[:2])


@dataclass
class LinearArm:
    """x' = A x + Bw w, tool displacement p = Cp x; ``step(h)`` -> (Phi,
    Gamma): the plant's scheme over one step with w held."""

    A: np.ndarray
    Bw: np.ndarray
    Cp: np.ndarray
    step: object

    @property
    def n(self):
        return self.A.shape[0]


def arm_from_joint_model(jm, J):
    """The LinearArm of JointModel ``jm`` (model/joint_dynamics.py; state
    q, q', theta, theta', z) with the wrench at the tool point through the
    6 x 6 geometric Jacobian J (base frame, rows v then omega, m/rad and
    rad/rad)."""
    A, B = jm.continuous()
    J = np.asarray(J, dtype=float)
    Minv = np.linalg.inv(jm.M)
    Bw = B[:, 18:24] @ J.T
    Cp = np.zeros((3, A.shape[0]))
    Cp[:, 0:6] = J[:3]

    def step(h):
        G = np.zeros((A.shape[0], 6))
        G[6:12] = h * Minv @ J.T  # v+ = v + h M^-1 (... + J^T w)
        G[0:6] = h * G[6:12]      # q+ = q + h v+
        return jm.step_map(h), G

    return LinearArm(A=A, Bw=Bw, Cp=Cp, step=step)


def mass_spring(m_kg, k_N_per_m, c_N_s_per_m=0.0):
    """A 1-DOF LinearArm (x, x'), its step symplectic Euler with the spring
    and its own damping explicit (the station's scheme), the force w (1,)
    on it: the tests' hand-checkable case."""
    A = np.array([[0.0, 1.0], [-k_N_per_m / m_kg, -c_N_s_per_m / m_kg]])

    def step(h):
        v = np.array([-h * k_N_per_m / m_kg, 1.0 - h * c_N_s_per_m / m_kg])
        return np.array([[1.0 + h * v[0], h * v[1]], v]), np.array([[h * h / m_kg], [h / m_kg]])

    return LinearArm(A=A, Bw=np.array([[0.0], [1.0 / m_kg]]), Cp=np.array([[1.0, 0.0]]), step=step)


# ---- continuous time ----

def velocity_law_matrix(arm, chip):
    """The coupled system's matrix with the chip's velocity law (the
    low-frequency limit): x' = A x + Bw (Kp Cp x + C S Cp x'), solved for
    x' (the tool's velocity Cp x' makes the wrench, which makes x')."""
    S = chip.chip_rows @ arm.Cp
    A0 = arm.A + arm.Bw @ chip.Kp @ arm.Cp
    Bc = arm.Bw @ chip.velocity_coupling
    # x' = A0 x + Bc S x'  ->  (I - Bc S) x' = A0 x
    return np.linalg.solve(np.eye(arm.n) - Bc @ S, A0)


def delay_matrices(arm, chip):
    """(A0, A1): x' = A0 x + A1 x(t - T), the chip's delay law."""
    S = chip.chip_rows @ arm.Cp
    A0 = arm.A + arm.Bw @ (chip.Kp @ arm.Cp + chip.Kf @ S)
    A1 = -arm.Bw @ chip.Kf @ S
    return A0, A1


def pade_delay(order, delay_s):
    """(a, b, c, d): a state-space realisation of the [n/n] Pade
    approximant of e^(-s T) (the coefficients (2n - k)! n! / ((2n)! k!
    (n - k)!), realised in s T and scaled, for its conditioning)."""
    n = int(order)
    if n < 1:
        raise ValueError(f"Pade order {order}: at least 1")
    ck = [factorial(2 * n - k) * factorial(n) / (factorial(2 * n) * factorial(k) * factorial(n - k))
          for k in range(n + 1)]
    num = [ck[k] * (-1) ** k for k in range(n, -1, -1)]  # highest power first
    den = [ck[k] for k in range(n, -1, -1)]
    a, b, c, d = signal.tf2ss(num, den)
    return a / delay_s, b / delay_s, c, d


def pade_matrix(arm, chip, order):
    """The delay law with e^(-sT) by its [order/order] Pade approximant on
    each chip coordinate: the augmented matrix (state x, then the delay
    lines' states)."""
    A0, A1 = delay_matrices(arm, chip)
    a, b, c, d = pade_delay(order, chip.tooth_period_s)
    nc = chip.chip_rows.shape[0]
    Ad, Bd = np.kron(np.eye(nc), a), np.kron(np.eye(nc), b)
    Cd, Dd = np.kron(np.eye(nc), c), np.kron(np.eye(nc), d)
    S = chip.chip_rows @ arm.Cp
    BK = arm.Bw @ chip.Kf  # w gets -Kf (delayed S x)
    n, m = arm.n, Ad.shape[0]
    out = np.zeros((n + m, n + m))
    out[:n, :n] = A0 - BK @ (Dd @ S)
    out[:n, n:] = -BK @ Cd
    out[n:, :n] = Bd @ S
    out[n:, n:] = Ad
    return out


def refine_root(A0, A1, delay_s, s0, iterations=50, tol=1e-10):
    """The root of det(s I - A0 - A1 e^(-s T)) = 0 nearest s0 by Newton's
    method on the eigenvalue lambda(s) of A0 + A1 e^(-sT) nearest s
    (f(s) = lambda(s) - s, f' from lambda's derivative by its left and
    right eigenvectors); None if it does not converge."""
    s = complex(s0)
    for _ in range(iterations):
        E = np.exp(-s * delay_s)
        lam, VL, VR = linalg.eig(A0 + A1 * E, left=True, right=True)
        i = int(np.argmin(np.abs(lam - s)))
        v, w = VR[:, i], VL[:, i]
        dlam = (w.conj() @ (-delay_s * E * A1) @ v) / (w.conj() @ v)
        step = (lam[i] - s) / (dlam - 1.0)
        s -= step
        if abs(step) < tol * max(1.0, abs(s)):
            return s
    return None


def pade_roots(arm, chip, order, max_hz=None):
    """The Pade matrix's eigenvalues of frequency >= 0 up to ``max_hz``
    (None: all), rightmost first."""
    lam = np.linalg.eigvals(pade_matrix(arm, chip, order))
    lam = lam[lam.imag >= -1e-9]
    if max_hz is not None:
        lam = lam[np.abs(lam.imag) <= 2 * np.pi * max_hz]
    return sorted((complex(s) for s in lam), key=lambda s: -s.real)


def delay_roots(arm, chip, order, max_hz=None):
    """The exact roots of the delay law near the Pade roots (``pade_roots``),
    each refined by ``refine_root`` (those where Newton fails dropped),
    of frequency >= 0, without repeats, rightmost first."""
    A0, A1 = delay_matrices(arm, chip)
    out = []
    for s in pade_roots(arm, chip, order, max_hz):
        r = refine_root(A0, A1, chip.tooth_period_s, s)
        if r is None:
            continue
        r = complex(r.real, abs(r.imag))
        if all(abs(r - o) > 1e-6 * max(1.0, abs(r)) for o in out):
            out.append(r)
    return sorted(out, key=lambda s: -s.real)


def rightmost(lam):
    """The eigenvalue of largest real part."""
    lam = np.asarray(lam)
    return complex(lam[np.argmax(lam.real)])


def mode_of(s):
    """(frequency Hz, damping ratio) of root s (a real root: 0 Hz, ratio +-1)."""
    s = complex(s)
    r = abs(s)
    return abs(s.imag) / (2 * np.pi), (-s.real / r if r > 0 else 0.0)


# ---- discrete time: the plant's scheme ----

def root_modes(jm, arm, chip, s):
    """(v, share, f_closed_hz): the coupled arm's eigenvector at the root s
    of the delay law (its state: links first), the shares of the arm's
    modes (motors held, from the lowest; mass-weighted, summing to one) in
    its link motion, and the arm's drives-closed frequencies (Hz); ``jm`` a
    model/joint_dynamics.JointModel at the pose."""
    from robstiff_drake.model import joint_dynamics as jd

    A0, A1 = delay_matrices(arm, chip)
    lam, V = np.linalg.eig(A0 + A1 * np.exp(-s * chip.tooth_period_s))
    v = V[:, np.argmin(np.abs(lam - s))]
    _, Phi = jd.held_modes(jm.M, jm.K, jm.G)
    share = np.abs(Phi.T @ jm.M @ v[:6]) ** 2
    return v, share / share.sum(), jm.arm_modes()[0]


def scheme_map(arm, chip, step_s, *, period_steps=1, window_s=None, along=None, cutoff_hz=None,
               along_cutoff_hz=None, coupled=True):
    """The linear map of the plant's scheme over one force period (see the
    module docstring): state (x, the tool's displacements at the last m
    updates, the filter's chip) at the updates.  ``window_s`` (None: the
    tooth period): the span the chip's displacement is taken over, scaled
    to a tooth.  Without ``along``: the chip as a vector, low-passed at
    ``cutoff_hz`` (first order, one step per update; None: unfiltered).
    ``along``, the program's unit in-plane feed direction: only the chip's
    component along it follows the tool, low-passed at ``cutoff_hz`` (the
    plant's law: the direction is the program's); with ``along_cutoff_hz``
    as well, that component is low-passed at ``along_cutoff_hz`` and the
    one across it follows the tool, low-passed at ``cutoff_hz`` (None:
    unfiltered; studies/chip_direction.py's ``raw``).  ``coupled`` False:
    the chip left out (Kp only).  Returns the map (a square array)."""
    h = float(step_s)
    r = int(period_steps)
    P = r * h
    T = chip.tooth_period_s
    W = T if window_s is None else float(window_s)
    if not coupled:
        W = max(W, P)
    if W < P - 1e-15:
        raise ValueError(f"window {W:g} s shorter than the force period {P:g} s")
    Phi1, Gam1 = arm.step(h)
    Phi, Gam = np.eye(arm.n), np.zeros_like(Gam1)
    for _ in range(r):  # r plant steps with the wrench held
        Phi, Gam = Phi1 @ Phi, Phi1 @ Gam + Gam1
    npp = arm.Cp.shape[0]
    j = int(math.floor(W / P + 1e-12))
    frac = W / P - j
    m = j + (1 if frac > 1e-12 else 0)  # past updates kept
    nc = chip.chip_rows.shape[0]
    # the chip's basis: along the program's feed and across it (the identity without ``along``)
    U = np.eye(nc)
    keep = np.ones(nc)
    gains = [None] * nc
    if along is not None:
        u = np.asarray(along, dtype=float).ravel()
        u = u / np.linalg.norm(u)
        U = np.array([u, [-u[1], u[0]]]) if nc == 2 else u.reshape(1, 1)
        if along_cutoff_hz is None:
            keep[1:] = 0.0  # the direction fixed: only the feed follows the tool
        gains[0] = along_cutoff_hz if along_cutoff_hz is not None else cutoff_hz
        gains[1:] = [cutoff_hz if along_cutoff_hz is not None else None] * (nc - 1)  # (a fixed one: none)
    else:
        gains = [cutoff_hz] * nc
    filtered = any(g is not None for g in gains)
    g = np.array([1.0 if c is None else 1.0 - math.exp(-2.0 * math.pi * c * P) for c in gains])
    nf = nc if filtered else 0
    N = arm.n + m * npp + nf
    Pn = np.zeros((npp, N))
    Pn[:, :arm.n] = arm.Cp

    def past(i):
        Z = np.zeros((npp, N))
        Z[:, arm.n + (i - 1) * npp: arm.n + i * npp] = np.eye(npp)
        return Z

    # p(t - W): between updates j and j + 1 back (update 0 = now)
    pj = Pn if j == 0 else past(j)
    p_back = pj if frac <= 1e-12 else (1 - frac) * pj + frac * past(j + 1)
    chip_now = (keep[:, None] * U) @ ((T / W) * chip.chip_rows @ (Pn - p_back))  # (nc, N), in U's basis
    if filtered:
        F = np.zeros((nf, N))
        F[:, N - nf:] = np.eye(nf)
        chip_b = F + g[:, None] * (chip_now - F)  # the filter's new value, used now
    else:
        chip_b = chip_now
    chip_used = U.T @ chip_b  # back to the chip's coordinates
    W_row = chip.Kp @ Pn + (chip.Kf @ chip_used if coupled else 0.0)  # (nw, N): the wrench from the state
    out = np.zeros((N, N))
    out[:arm.n, :arm.n] = Phi
    out[:arm.n] += Gam @ W_row
    if m:  # the history shifts: update 1 back <- now, i + 1 <- i
        out[arm.n:arm.n + npp] = Pn
        for i in range(1, m):
            out[arm.n + i * npp: arm.n + (i + 1) * npp] = past(i)
    if nf:
        out[N - nf:] = chip_b
    return out


def spectral_radius(M):
    return float(np.max(np.abs(np.linalg.eigvals(M))))


def growth_rate_per_s(M, period_s):
    """ln(spectral radius) / period (1/s): the scheme's fastest growth
    (negative: its slowest decay)."""
    return math.log(spectral_radius(M)) / period_s


def largest_stable_step_s(stable_at, upper_s, lower_s=1e-6, resolution=1e-3):
    """The largest step in [lower_s, upper_s] (s) at which ``stable_at(h)``
    holds, by bisection on a log scale to the relative ``resolution``,
    assuming stability is lost once with the step growing; 0.0 when it
    fails at ``lower_s`` (unstable however small the step: the physics)."""
    if stable_at(upper_s):
        return float(upper_s)
    if not stable_at(lower_s):
        return 0.0
    lo, hi = math.log(lower_s), math.log(upper_s)
    while hi - lo > resolution:
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if stable_at(math.exp(mid)) else (lo, mid)
    return math.exp(lo)
