"""model/chip_coupling.py against hand-checkable 1-DOF cases and against
simulations of the same linear systems written here (an explicit loop, not
the module's matrices)."""

import math

import numpy as np
import pytest

from robstiff_drake.model import chip_coupling as cc

M_KG, K_N_PER_M = 2.0, 100.0


def chip_1dof(Kf_N_per_m, T_s, Kp_N_per_m=0.0):
    return cc.LinearisedChip(Kp=np.array([[Kp_N_per_m]]), Kf=np.array([[Kf_N_per_m]]), tooth_period_s=T_s,
                             chip_rows=np.eye(1))


def test_velocity_law_gives_the_damped_oscillators_roots():
    """m x'' + k x = C x' with C = Kf T = -c: the roots of m s^2 + c s + k."""
    c, T = 3.0, 0.01
    arm = cc.mass_spring(M_KG, K_N_PER_M)
    lam = np.sort_complex(np.linalg.eigvals(cc.velocity_law_matrix(arm, chip_1dof(-c / T, T))))
    want = np.sort_complex(np.roots([M_KG, c, K_N_PER_M]))
    np.testing.assert_allclose(lam, want, rtol=1e-12)
    # a chip that pushes along the motion (C > 0) is a negative damping: growth c / 2m
    lam = np.linalg.eigvals(cc.velocity_law_matrix(arm, chip_1dof(+c / T, T)))
    assert cc.rightmost(lam).real == pytest.approx(c / (2 * M_KG), rel=1e-12)


def test_explicit_velocity_force_is_stable_below_c_h_over_m_2():
    """The force -c v_k from the step's start (the chip over the last
    step, p_k - p_(k-1) = h v_k in symplectic Euler) on a mass with a soft
    spring: the scheme's char. polynomial z^2 - (2 - hc/m - h^2 k/m) z +
    (1 - hc/m) is stable (Jury) while h c / m < 2 and 4 - 2 h c / m - h^2 k
    / m > 0: for k = 1 the second binds, h = 0.03999 s at c = 100, m = 2."""
    c, k = 100.0, 1.0
    arm = cc.mass_spring(M_KG, k)
    chip = chip_1dof(-c / 0.01, 0.01)

    def stable(h):
        return cc.spectral_radius(cc.scheme_map(arm, chip, h, window_s=h)) <= cc.STABLE_MARGIN

    a, b = k / M_KG, 2 * c / M_KG  # a h^2 + b h - 4 = 0
    want = (-b + math.sqrt(b * b + 16 * a)) / (2 * a)
    assert want < 2 * M_KG / c
    assert cc.largest_stable_step_s(stable, 0.1, resolution=1e-5) == pytest.approx(want, rel=1e-4)
    # without a spring the limit is c h / m = 2 itself
    arm0 = cc.mass_spring(M_KG, 0.0)
    got = cc.largest_stable_step_s(
        lambda h: cc.spectral_radius(cc.scheme_map(arm0, chip, h, window_s=h)) <= cc.STABLE_MARGIN, 0.1,
        resolution=1e-5)
    assert got == pytest.approx(2 * M_KG / c, rel=1e-4)


# the regenerative 1-DOF: m x'' + c0 x' + k x = Kf (x - x(t - T)), Kf < 0 (the chip's force opposes its growth)
W0 = 2 * math.pi * 20.0
# (T: a 21.8 Hz chatter root's regenerative phase between pi and 2 pi, where a chip above 2 k zeta (1 + zeta)
# = 644 N/m can chatter; [1/1] Pade gets its sign wrong)
REGEN = dict(m=1.0, k=W0 ** 2, c0=2 * 0.02 * W0, T=0.035)


def regen_arm():
    return cc.mass_spring(REGEN["m"], REGEN["k"], REGEN["c0"])


def characteristic(s, Kf):
    m, k, c0, T = REGEN["m"], REGEN["k"], REGEN["c0"], REGEN["T"]
    return m * s * s + c0 * s + k - Kf * (1 - np.exp(-s * T))


@pytest.mark.parametrize("Kf", [-300.0, -3000.0])
def test_exact_root_solves_the_characteristic_equation_and_pade_converges_to_it(Kf):
    arm, chip = regen_arm(), chip_1dof(Kf, REGEN["T"])
    s = cc.delay_roots(arm, chip, 8)[0]
    assert abs(characteristic(s, Kf)) < 1e-8 * REGEN["k"]
    # the rightmost Pade roots of growing order approach it
    err = [abs(cc.pade_roots(arm, chip, n)[0] - s) for n in (1, 2, 4, 8)]
    assert err[3] < err[2] < err[1] < err[0] and err[3] < 1e-4 * abs(s)


def simulate_dde(Kf, duration_s, n_per_delay=400):
    """RK4 on x'' = (Kf (x - x(t - T)) - c0 x' - k x) / m with x = 0 before
    t = 0 then a unit velocity kick, the delayed x read from the grid (the
    step divides T; at RK4's half steps from the midpoint of two grid values,
    a second-order error the test's tolerance absorbs)."""
    m, k, c0, T = REGEN["m"], REGEN["k"], REGEN["c0"], REGEN["T"]
    h = T / n_per_delay
    n = int(duration_s / h)
    x = np.zeros(n + 1)
    v = 0.0
    v_hist = 1.0

    def acc(xx, vv, xd):
        return (Kf * (xx - xd) - c0 * vv - k * xx) / m

    v = v_hist
    for i in range(n):
        d0 = x[i - n_per_delay] if i >= n_per_delay else 0.0
        d1 = x[i + 1 - n_per_delay] if i + 1 >= n_per_delay else 0.0
        dm = 0.5 * (d0 + d1)
        k1x, k1v = v, acc(x[i], v, d0)
        k2x, k2v = v + 0.5 * h * k1v, acc(x[i] + 0.5 * h * k1x, v + 0.5 * h * k1v, dm)
        k3x, k3v = v + 0.5 * h * k2v, acc(x[i] + 0.5 * h * k2x, v + 0.5 * h * k2v, dm)
        k4x, k4v = v + h * k3v, acc(x[i] + h * k3x, v + h * k3v, d1)
        x[i + 1] = x[i] + h / 6 * (k1x + 2 * k2x + 2 * k3x + k4x)
        v = v + h / 6 * (k1v + 2 * k2v + 2 * k3v + k4v)
    return np.arange(n + 1) * h, x


def envelope_growth(t, x, t0):
    """The slope of ln |peak| over the peaks after t0 (1/s) and their mean spacing's frequency (Hz)."""
    i = np.nonzero((x[1:-1] > x[:-2]) & (x[1:-1] >= x[2:]) & (t[1:-1] > t0))[0] + 1
    slope = np.polyfit(t[i], np.log(x[i]), 1)[0]
    return slope, 1.0 / np.mean(np.diff(t[i]))


@pytest.mark.parametrize("Kf", [-300.0, -3000.0])
def test_the_exact_root_is_what_a_simulation_of_the_delay_equation_grows_at(Kf):
    arm, chip = regen_arm(), chip_1dof(Kf, REGEN["T"])
    s = cc.delay_roots(arm, chip, 8)[0]
    t, x = simulate_dde(Kf, 1.5)
    growth, f = envelope_growth(t, x, 0.5)  # (after the other roots have died away)
    assert growth == pytest.approx(s.real, abs=0.1)
    assert f == pytest.approx(abs(s.imag) / (2 * math.pi), rel=0.01)
    assert (s.real > 0) == (Kf < -1000.0)  # the weak chip is stable, the strong one chatters


def simulate_scheme(Kf, h, W, n):
    """The plant's scheme written as a loop: each step the force from the
    displacement over the window W (interpolated in the history of steps),
    scaled to a tooth, then a symplectic Euler step of the spring (and its
    damping) explicit, the force held."""
    m, k, c0, T = REGEN["m"], REGEN["k"], REGEN["c0"], REGEN["T"]
    xs, x, v = [0.0], 0.0, 1.0
    for i in range(n):
        back = (i * h - W) / h  # the history's index of t - W
        if back <= 0:
            xb = 0.0
        else:
            j = int(math.floor(back))
            f = back - j
            xb = xs[j] + f * (xs[j + 1] - xs[j]) if f > 0 else xs[j]
        w = Kf * (T / W) * (x - xb)
        v = v + h / m * (w - k * x - c0 * v)
        x = x + h * v
        xs.append(x)
    return np.array(xs)


def test_the_schemes_map_is_what_the_scheme_simulated_grows_at():
    Kf, h = -3000.0, REGEN["T"] / 5.5  # a window of 5.5 steps: interpolated
    M = cc.scheme_map(regen_arm(), chip_1dof(Kf, REGEN["T"]), h)
    rho = cc.spectral_radius(M)
    xs = simulate_scheme(Kf, h, REGEN["T"], 6000)
    t = np.arange(len(xs)) * h
    growth, _ = envelope_growth(t, xs, 2000 * h)
    assert growth == pytest.approx(math.log(rho) / h, rel=0.02)
    # and the scheme approaches the continuous root as the step shrinks
    s = cc.delay_roots(regen_arm(), chip_1dof(Kf, REGEN["T"]), 8)[0]
    g = [math.log(cc.spectral_radius(cc.scheme_map(regen_arm(), chip_1dof(Kf, REGEN["T"]), REGEN["T"] / n)))
         / (REGEN["T"] / n) for n in (8, 16, 32)]
    assert abs(g[2] - s.real) < abs(g[1] - s.real) < abs(g[0] - s.real)


def test_a_filter_on_the_chip_or_no_chip_keeps_the_scheme_stable():
    """A chip low-passed far below the mode cannot feed it: stable where
    the unfiltered chip chatters."""
    arm, chip = regen_arm(), chip_1dof(-3000.0, REGEN["T"])
    assert cc.spectral_radius(cc.scheme_map(arm, chip, 1e-3)) > 1.0
    assert cc.spectral_radius(cc.scheme_map(arm, chip, 1e-3, cutoff_hz=0.5)) < 1.0
    assert cc.spectral_radius(cc.scheme_map(arm, chip, 1e-3, coupled=False)) < 1.0


def test_linearise_law_recovers_a_linear_laws_matrices():
    rng = np.random.default_rng(29)
    A, B, T = rng.normal(size=(6, 3)) * 1e5, rng.normal(size=(6, 2)) * 1e6, 1.0 / 360.0
    p0 = np.array([1.6, 0.0, 0.7])

    def wrench(p, u, feed):
        return A @ (np.asarray(p) - p0) + B @ (np.asarray(u) * feed * T)

    lin = cc.linearise_law(wrench, p0, (0.6, 0.8), 0.02, T)
    np.testing.assert_allclose(lin.Kp, A, rtol=1e-6)
    np.testing.assert_allclose(lin.Kf, B, rtol=1e-6)
    np.testing.assert_allclose(lin.velocity_coupling, B * T, rtol=1e-6)


def test_a_chip_below_the_minimum_is_linearised_at_the_minimum():
    """A law whose chip force is h^0.75 (stiffer as the chip thins) with a
    feed per tooth of 2.8 um: with ``min_chip_m`` = 10 um its chip slope is
    the law's at 10 um, not at 2.8 um (a thicker feed is left as it is);
    the engagement's slope Kp stays the law's at the real feed."""
    T, k = 1.0 / 360.0, 1e5  # N per m^0.75

    def wrench(p, u, feed):
        f = np.asarray(u) * feed * T
        h = np.linalg.norm(f)
        return np.r_[k * h ** 0.75 * f / h, 1e3 * feed * p[2], 0.0, 0.0, 0.0]

    def slope(h):  # d|F|/dh along the feed
        return 0.75 * k * h ** -0.25

    thin = 1e-3  # m/s: 2.8 um a tooth
    plain = cc.linearise_law(wrench, np.zeros(3), (1.0, 0.0), thin, T)
    floored = cc.linearise_law(wrench, np.zeros(3), (1.0, 0.0), thin, T, min_chip_m=10e-6)
    assert plain.Kf[0, 0] == pytest.approx(slope(thin * T), rel=1e-3)
    assert floored.Kf[0, 0] == pytest.approx(slope(10e-6), rel=1e-3)
    assert floored.Kf[0, 0] < 0.75 * plain.Kf[0, 0]
    assert floored.Kf[1, 1] == pytest.approx(k * 10e-6 ** 0.75 / 10e-6, rel=1e-3)  # the force turning with the chip
    np.testing.assert_allclose(floored.Kp, plain.Kp)
    assert floored.Kp[2, 2] == pytest.approx(1e3 * thin)
    thick = 0.02  # 55.6 um a tooth: above the minimum, unchanged
    np.testing.assert_allclose(cc.linearise_law(wrench, np.zeros(3), (1.0, 0.0), thick, T, min_chip_m=10e-6).Kf,
                               cc.linearise_law(wrench, np.zeros(3), (1.0, 0.0), thick, T).Kf)


def test_pade_matches_the_delay_at_low_frequency():
    T = 0.01
    for n in (1, 2, 4):
        a, b, c, d = cc.pade_delay(n, T)
        w = 1.0 / T  # omega T = 1
        H = (c @ np.linalg.solve(1j * w * np.eye(n) - a, b) + d).item()
        assert abs(H - np.exp(-1j * w * T)) < {1: 0.08, 2: 2e-3, 4: 1e-7}[n]
    with pytest.raises(ValueError, match="Pade order"):
        cc.pade_delay(0, T)


def planar_arm(m_kg=1.0, k_N_per_m=(1.0e4, 2.0e4)):
    """Two uncoupled mass-springs, x and y: a LinearArm with a 2-D tool point."""
    arms = [cc.mass_spring(m_kg, k) for k in k_N_per_m]
    A = np.zeros((4, 4))
    A[:2, :2], A[2:, 2:] = arms[0].A, arms[1].A
    Bw = np.zeros((4, 2))
    Bw[1, 0] = Bw[3, 1] = 1.0 / m_kg
    Cp = np.zeros((2, 4))
    Cp[0, 0] = Cp[1, 2] = 1.0

    def step(h):
        (P0, G0), (P1, G1) = (a.step(h) for a in arms)
        P, G = np.zeros((4, 4)), np.zeros((4, 2))
        P[:2, :2], P[2:, 2:], G[:2, 0], G[2:, 1] = P0, P1, G0[:, 0], G1[:, 0]
        return P, G

    return cc.LinearArm(A=A, Bw=Bw, Cp=Cp, step=step)


def test_the_programs_direction_leaves_the_cross_feed_chip_out_and_raw_keeps_it():
    arm = planar_arm()
    Kf = np.array([[-2.0e3, -5.0e3], [2.5e3, -2.0e2]])
    cross_off = Kf.copy()
    cross_off[:, 1] = 0.0
    chips = [cc.LinearisedChip(Kp=np.zeros((2, 2)), Kf=K, tooth_period_s=0.003, chip_rows=np.eye(2))
             for K in (Kf, cross_off)]
    kw = dict(window_s=0.016, period_steps=4)
    path = [cc.scheme_map(arm, c, 1e-3, along=(1.0, 0.0), cutoff_hz=2.0, **kw) for c in chips]
    np.testing.assert_array_equal(path[0], path[1])  # the program's direction: the chip across it never moves
    raw = [cc.scheme_map(arm, c, 1e-3, along=(1.0, 0.0), along_cutoff_hz=2.0, **kw) for c in chips]
    assert not np.allclose(raw[0], raw[1])
    # (without a cross term the two laws are one: their maps differ only in the unused cross state's row)
    assert cc.spectral_radius(raw[1]) == pytest.approx(cc.spectral_radius(path[1]), rel=1e-12)
    assert cc.spectral_radius(raw[0]) != pytest.approx(cc.spectral_radius(path[0]), rel=1e-6)
