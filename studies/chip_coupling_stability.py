"""Is the divergence of a plant whose chip follows the tool's own motion
physics (regenerative / mode-coupling chatter of the arm at the block's
pose with the paper's forces) or numerics (a velocity-dependent force
applied explicitly)?  Issue 29; model/chip_coupling.py (its docstring:
the linearisation, the Pade approximation, the scheme's map).

The arm: the station's linear joints (drives tuned and damping fitted
along the path, as diagrams/compliant_arm.arm_joints builds them) at the
pose of the tool point; the chip: the plant's law (model/plant_cutting.py,
paper_reproduction's block, draw 0) linearised there by finite differences.
No simulation: eigenvalues of linear models (a few seconds a pose).

    python studies/chip_coupling_stability.py                      # the block (about a minute)
    python studies/chip_coupling_stability.py --face-and-contour   # and face_and_contour's cut
    python studies/chip_coupling_stability.py --drake              # and the station's run (about 5 minutes more)
    python studies/chip_coupling_stability.py --drake-play         # the same with the gears' play
"""

import argparse
import math
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "studies"))

import paper_reproduction as pr  # noqa: E402
from robstiff_drake.diagrams.compliant_arm import mass_and_weight_stiffness  # noqa: E402
from robstiff_drake.diagrams.path_references import planned_path  # noqa: E402
from robstiff_drake.diagrams.scenario import load_scenario  # noqa: E402
from robstiff_drake.diagrams.scenario_models import (plant_cutting_setup, plant_damping_ratios,  # noqa: E402
                                                     plant_stiffness)
from robstiff_drake.diagrams.station import arm_joints, controller_model, path_poses, servo_parameters  # noqa: E402
from robstiff_drake.model import chip_coupling as cc  # noqa: E402
from robstiff_drake.model import ik, joint_dynamics as jd  # noqa: E402
from robstiff_drake.model import kinematics as kin  # noqa: E402
from robstiff_drake.model.robot import load_robot  # noqa: E402
from robstiff_drake.systems.milling_force import FEED_CUTOFF_HZ, chip_window_s  # noqa: E402

PADE_ORDERS = (1, 2, 3, 4, 8)
MAX_HZ = 400.0  # the roots searched up to this frequency (the arm's highest mode 126 Hz; the tooth pass 360 Hz)
TOP_MM = 703.0  # the block's top (diagrams/block_milling.yaml)


class Cut:
    """A scenario's arm (its station's linear joints) and plant law."""

    def __init__(self, sc, robot):
        self.robot, self.tool = robot, robot.tool_point()
        self.cutter, self.law, self.wp = plant_cutting_setup(sc)
        self.path, _, q_ref = planned_path(sc, robot, self.tool)
        self.plant = controller_model(robot)
        K = jd.stiffness_matrix(plant_stiffness(sc, robot), sc.plant.coupling_c23_rad_per_Nm)
        self.jm = arm_joints(self.plant, robot, path_poses(q_ref), K, plant_damping_ratios(sc), servo_parameters(sc),
                             sc.plant.damping_on)
        self.T = 1.0 / self.cutter.tooth_pass_hz
        self._arms, self._chips = {}, {}

    def arm(self, p_m, yaw_rad=0.0):
        """The LinearArm with the tool at p (m), spindle down."""
        key = tuple(np.round(p_m, 9))
        if key not in self._arms:
            q = ik.solve_ik(self.robot.dh, ik.tool_down_pose(np.asarray(p_m), yaw_rad), self.tool)
            jm = self.jm.at_pose(*mass_and_weight_stiffness(self.plant, q))
            self._arms[key] = (cc.arm_from_joint_model(jm, kin.jacobian(self.robot.dh, q, self.tool)), jm)
        return self._arms[key]

    def chip(self, p_m, u=(1.0, 0.0)):
        key = tuple(np.round(p_m, 9)) + tuple(np.round(u, 9))
        if key not in self._chips:
            self._chips[key] = cc.linearise_law(lambda p, d, f: self.law.average_wrench(p, d, self.wp, f), p_m, u,
                                                self.law.feed_m_per_s, self.T)
        return self._chips[key]

    def wrench(self, p_m, u=(1.0, 0.0)):
        return self.law.average_wrench(p_m, u, self.wp, self.law.feed_m_per_s)


def exact_rightmost(arm, chip, order=4):
    """The rightmost exact root of the delay law (Pade's roots refined)."""
    return cc.delay_roots(arm, chip, order, max_hz=MAX_HZ)[0]


def fmt(s):
    f, z = cc.mode_of(s)
    return f"{s.real:+.2f} | {f:.1f} | {z:+.3f}"


def continuous_table(cut, xs_mm):
    print("Continuous time (the physics): the rightmost root s of the coupled arm (growth 1/s, > 0 unstable; "
          "frequency Hz; damping ratio)")
    print("| tool at x (mm) | force (N) | model | growth (1/s) | frequency (Hz) | damping ratio |")
    print("|---|---|---|---|---|---|")
    for x in xs_mm:
        p = np.array([x / 1e3, 0.0, 0.700])
        arm, _ = cut.arm(p)
        chip = cut.chip(p)
        F = cut.wrench(p)[:3]
        rows = [("the arm alone", cc.rightmost(np.linalg.eigvals(arm.A))),
                ("engagement only (Kp: the plant's law today, its chip along the program)",
                 cc.rightmost(np.linalg.eigvals(arm.A + arm.Bw @ chip.Kp @ arm.Cp))),
                ("chip as a velocity coupling C = Kf T (low-frequency limit)",
                 cc.rightmost(np.linalg.eigvals(cc.velocity_law_matrix(arm, chip))))]
        for n in PADE_ORDERS:
            rows.append((f"regenerative chip, Pade [{n}/{n}]", cc.pade_roots(arm, chip, n, MAX_HZ)[0]))
        rows.append(("regenerative chip, exact (Newton on det(sI - A0 - A1 e^-sT))", exact_rightmost(arm, chip)))
        for name, s in rows:
            print(f"| {x:.0f} | ({F[0]:.0f}, {F[1]:.0f}, {F[2]:.0f}) | {name} | {fmt(s)} |")
    print()


def scheme_table(cut, x_mm):
    """The plant's schemes (studies/chip_direction.py's laws) at x."""
    p = np.array([x_mm / 1e3, 0.0, 0.700])
    arm, jm = cut.arm(p)
    chip = cut.chip(p)
    rev = chip_window_s(cut.cutter)
    four = 8  # 4 ms force period at the 0.5 ms plant step (diagrams/station.AVERAGED_FORCE_PERIOD_S)
    laws = [("path (the plant's: the feed along the program, 2 Hz)", dict(window_s=rev, along=(1.0, 0.0),
                                                                          cutoff_hz=FEED_CUTOFF_HZ), 0.5e-3, four),
            ("vector:2", dict(window_s=rev, cutoff_hz=2.0), 0.5e-3, four),
            ("vector:5", dict(window_s=rev, cutoff_hz=5.0), 0.5e-3, four),
            ("vector:10", dict(window_s=rev, cutoff_hz=10.0), 0.5e-3, four),
            ("raw (over a revolution: the direction unfiltered, the feed at 2 Hz)",
             dict(window_s=rev, along=(1.0, 0.0), along_cutoff_hz=FEED_CUTOFF_HZ), 0.5e-3, four),
            ("tooth (the same over a tooth, the force every step)",
             dict(along=(1.0, 0.0), along_cutoff_hz=FEED_CUTOFF_HZ), 0.5e-3, 1)]
    laws += [(f"vtooth (over a tooth, feed and direction unfiltered, every step) at {h * 1e3:g} ms", {}, h, 1)
             for h in (0.5e-3, 0.25e-3, 0.125e-3, 0.0625e-3)]
    print(f"The plant's discrete scheme at x = {x_mm:.0f} mm (the force source's map over its period; growth "
          "= ln(spectral radius) / period)")
    print("| chip law | plant step (ms) | force period (ms) | spectral radius | growth (1/s) | frequency (Hz) |")
    print("|---|---|---|---|---|---|")
    for name, kw, h, r in laws:
        M = cc.scheme_map(arm, chip, h, period_steps=r, **kw)
        lam = np.linalg.eigvals(M)
        z = lam[np.argmax(np.abs(lam))]
        s = np.log(z) / (h * r)
        print(f"| {name} | {h * 1e3:g} | {h * r * 1e3:g} | {abs(z):.5f} | {s.real:+.2f} | "
              f"{abs(s.imag) / (2 * np.pi):.1f} |")
    print(f"| (continuous, exact) | 0 | 0 | | {exact_rightmost(arm, chip).real:+.2f} | "
          f"{cc.mode_of(exact_rightmost(arm, chip))[0]:.1f} |")

    def tooth_stable(h):
        return cc.spectral_radius(cc.scheme_map(arm, chip, h)) <= cc.STABLE_MARGIN
    h_tooth = cc.largest_stable_step_s(tooth_stable, cut.T, lower_s=2e-5)
    print(f"\nThe chip over a tooth every step (vtooth): largest stable step "
          + (f"{h_tooth * 1e3:.3f} ms" if h_tooth else f"none from {2e-5 * 1e3:g} ms to a tooth period "
                                                          f"({cut.T * 1e3:.2f} ms)"))

    # the numerical question alone: the velocity law (stable in continuous time) taken explicitly, the
    # tool's velocity as its displacement over the last step
    def vel_stable(h):
        return cc.spectral_radius(cc.scheme_map(arm, chip, h, window_s=h)) <= cc.STABLE_MARGIN
    Jv = arm.Cp[:, :6]
    m_app = 1.0 / np.linalg.eigvalsh(Jv @ np.linalg.inv(jm.M) @ Jv.T)[::-1][:2]
    c = np.abs(np.linalg.eigvals(chip.velocity_coupling[:2])).max()
    print(f"The velocity law taken explicitly (the chip from the tool's last step): largest stable step "
          f"{cc.largest_stable_step_s(vel_stable, 4e-3) * 1e3:.3f} ms; the tool's in-plane apparent masses "
          f"(links, 1 / eig(J M^-1 J^T)) {m_app[0]:.0f}, {m_app[1]:.0f} kg and the coupling's largest |eigenvalue| "
          f"{c:.0f} N*s/m: 2 m / c = {2 * m_app.min() / c * 1e3:.1f} ms.")
    print()


def unstable_mode(cut, x_mm):
    """Which of the arm's modes the unstable root is made of."""
    p = np.array([x_mm / 1e3, 0.0, 0.700])
    arm, jm = cut.arm(p)
    chip = cut.chip(p)
    s = exact_rightmost(arm, chip)
    v, share, f_closed = cc.root_modes(jm, arm, chip, s)
    w = jd.held_modes(jm.M, jm.K, jm.G)[0]  # (motors held, rad/s)
    tool = arm.Cp @ v
    tool = tool / np.abs(tool).max()
    K, C = chip.Kf[:3] / 1e6, chip.velocity_coupling[:3]
    print(f"The chip's law at x = {x_mm:.0f} mm: the force per chip vector Kf (MN/m; rows F_x, F_y, F_z, columns "
          f"the chip's x, y): " + "; ".join(f"({a:+.2f}, {b:+.2f})" for a, b in K)
          + "; its low-frequency limit C = Kf T (N*s/m): " + "; ".join(f"({a:+.0f}, {b:+.0f})" for a, b in C))
    print(f"The unstable root at x = {x_mm:.0f} mm: s = {s.real:+.2f} {s.imag:+.2f}j 1/s ({fmt(s)}): "
          "its links' motion over the arm's modes (mass-weighted share; the motors-held mode, its drives-closed "
          "frequency):")
    print("| arm mode | motors held (Hz) | drives closed (Hz) | share |")
    print("|---|---|---|---|")
    for i in np.argsort(-share)[:4]:
        print(f"| {i + 1} | {w[i] / (2 * np.pi):.1f} | {f_closed[i]:.1f} | {share[i]:.2f} |")
    print(f"Its tool motion (x, y, z; magnitude relative, phase deg): "
          + ", ".join(f"{abs(c):.2f} at {math.degrees(np.angle(c)):+.0f}" for c in tool) + "\n")


def rotated(chip, psi):
    """The chip law of the same cut turned by psi about the vertical (the
    block and the feed turned together; the arm's pose unchanged)."""
    c, s = math.cos(psi), math.sin(psi)
    R3 = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    R6 = np.kron(np.eye(2), R3)
    return cc.LinearisedChip(Kp=R6 @ chip.Kp @ R3.T, Kf=R6 @ chip.Kf @ R3[:2, :2].T,
                             tooth_period_s=chip.tooth_period_s, chip_rows=chip.chip_rows)


def at_spindle_speed(chip, rpm, n_teeth):
    """The chip law at another spindle speed, the feed per tooth kept (Kf
    per chip unchanged; the cutting coefficients taken as speed-independent):
    only the tooth period changes."""
    return cc.LinearisedChip(Kp=chip.Kp, Kf=chip.Kf, tooth_period_s=60.0 / (rpm * n_teeth), chip_rows=chip.chip_rows)


def limit_depth_mm(cut, x_mm, change=None, lo=0.05, hi=3.0):
    """The largest depth of cut (mm) in [lo, hi] the delay law keeps stable
    (the tool raised or lowered in the block, the law linearised there and
    changed by ``change(chip)``; the arm at the 3 mm pose), by bisection to
    0.01 mm; lo if even it is not."""
    arm = cut.arm(np.array([x_mm / 1e3, 0.0, 0.700]))[0]

    def growth(a):
        chip = cut.chip(np.array([x_mm / 1e3, 0.0, (TOP_MM - a) / 1e3]))
        return exact_rightmost(arm, change(chip) if change else chip).real
    if growth(hi) < 0:
        return hi
    if growth(lo) >= 0:
        return lo
    while hi - lo > 0.01:
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if growth(mid) < 0 else (lo, mid)
    return lo


def onset_table(cut, xs_mm):
    print("Along the block's entry (the cutter's front reaches the block at x = 1487.5 mm, is fully engaged from "
          "about x = 1525 mm): the exact rightmost root")
    print("| tool at x (mm) | force (N) | growth (1/s) | frequency (Hz) | damping ratio |")
    print("|---|---|---|---|---|")
    for x in xs_mm:
        p = np.array([x / 1e3, 0.0, 0.700])
        F = cut.wrench(p)[:3]
        s = exact_rightmost(cut.arm(p)[0], cut.chip(p))
        print(f"| {x:.1f} | ({F[0]:.0f}, {F[1]:.0f}, {F[2]:.0f}) | {fmt(s)} |")
    print()


def depth_and_direction(cut, x_mm):
    arm, _ = cut.arm(np.array([x_mm / 1e3, 0.0, 0.700]))
    print(f"What would be stable at x = {x_mm:.0f} mm (the arm's pose kept; the depth: the tool raised in the "
          "block; the feed direction: the cut turned about the spindle by psi from +x)")
    print("| feed direction psi (deg) | rightmost root at 3 mm: growth (1/s) | frequency (Hz) | damping ratio | "
          "largest stable depth (mm, searched up to 3) |")
    print("|---|---|---|---|---|")
    chip = cut.chip(np.array([x_mm / 1e3, 0.0, 0.700]))
    for deg in range(0, 360, 45):
        s = exact_rightmost(arm, rotated(chip, math.radians(deg)))
        limit = limit_depth_mm(cut, x_mm, lambda c, r=math.radians(deg): rotated(c, r))
        print(f"| {deg} | {fmt(s)} | {limit:.2f} |")
    print()
    n = cut.cutter.n_teeth
    print(f"The spindle speed (the feed per tooth kept, the feed direction +x), x = {x_mm:.0f} mm:")
    print("| spindle (rpm) | tooth pass (Hz) | rightmost root at 3 mm: growth (1/s) | frequency (Hz) | "
          "damping ratio | largest stable depth (mm, searched up to 3) |")
    print("|---|---|---|---|---|---|")
    for rpm in (1800, 2400, 3000, 3600, 4200, 4800, 6000, 7200, 9000, 12000):
        s = exact_rightmost(arm, at_spindle_speed(chip, rpm, n))
        limit = limit_depth_mm(cut, x_mm, lambda c, r=rpm: at_spindle_speed(c, r, n))
        print(f"| {rpm} | {rpm * n / 60:.0f} | {fmt(s)} | {limit:.2f} |")
    print()


def own_forces(robot, x_mm=1600.0):
    """The block at diagrams/block_milling.yaml's own forces: the root, the
    largest stable depth and the scheme's largest stable step with the
    chip over a tooth every plant step (what a plant whose chip follows the
    tool would need there)."""
    cut = Cut(load_scenario(ROOT / "diagrams" / "block_milling.yaml"), robot)
    p = np.array([x_mm / 1e3, 0.0, 0.700])
    arm, _ = cut.arm(p)
    chip = cut.chip(p)
    s = exact_rightmost(arm, chip)
    h = cc.largest_stable_step_s(lambda h: cc.spectral_radius(cc.scheme_map(arm, chip, h)) <= cc.STABLE_MARGIN,
                                 cut.T)
    F = cut.wrench(p)[:3]
    print(f"The block at its own forces (diagrams/block_milling.yaml, within the spindle's rating), x = {x_mm:.0f} "
          f"mm, force ({F[0]:.0f}, {F[1]:.0f}, {F[2]:.0f}) N: rightmost root {fmt(s)}; largest stable depth "
          f"{limit_depth_mm(cut, x_mm, hi=10.0):.2f} mm (searched up to 10); the chip over a tooth every plant "
          f"step is stable up to a step of {h * 1e3:.3f} ms\n")


def face_and_contour(robot):
    sc = load_scenario(ROOT / "diagrams" / "face_and_contour.yaml")
    cut = Cut(sc, robot)
    path = cut.path
    print("face_and_contour (its own forces, the plant's law) along its cut: the rightmost exact root where the "
          "tool cuts")
    print("| t (s) | tool (mm) | feed direction (deg) | force (N) | growth (1/s) | frequency (Hz) | damping ratio |")
    print("|---|---|---|---|---|---|---|")
    for t in np.linspace(path.dwell_s, path.duration_s - path.dwell_s, 13):
        p = np.asarray(path.position(t), dtype=float)
        u = np.asarray(path.feed_direction(t), dtype=float)
        F = cut.law.average_wrench(p, u, cut.wp, cut.law.feed_m_per_s)[:3]
        if np.linalg.norm(F) < 1.0:  # (not cutting)
            continue
        arm, _ = cut.arm(p)
        s = exact_rightmost(arm, cut.chip(p, u))
        print(f"| {t:.1f} | ({p[0] * 1e3:.0f}, {p[1] * 1e3:.0f}, {p[2] * 1e3:.0f}) | "
              f"{math.degrees(math.atan2(u[1], u[0])):+.0f} | ({F[0]:.0f}, {F[1]:.0f}, {F[2]:.0f}) | {fmt(s)} |",
              flush=True)
    print()


def drake_run(robot, play=False, step_s=0.5e-3):
    """The independent check: the station (Drake) on the paper's block with
    the chip over a tooth, feed and direction, every plant step
    (studies/chip_direction.py's ``vtooth`` force source), no play (or
    paper_reproduction's on every joint, ``play``): where
    the cross-feed force starts to oscillate, at what frequency and how
    fast it grows (windows of the force's part off its 50 ms mean)."""
    import chip_direction as cd
    sc = pr.paper_scenario("block", robot, 0)
    sc.plant_config.time_step = step_s
    if not play:
        sc.plant.lost_motion_rad = [0.0] * 6
    try:
        cd.run("vtooth", sc, robot)
    except Exception as e:  # (a diverged run may stop on the arm's checks: its log is still there)
        print(f"(the run stopped: {type(e).__name__})")
    log = np.array(cd.ToolMotionChip.log)
    t, Fy, x = log[:, 0], log[:, 5], log[:, 7] * 1e3
    dt = t[1] - t[0]
    k = int(round(0.05 / dt))
    osc = Fy - np.convolve(Fy, np.ones(k) / k, mode="same")
    print(f"The station (Drake), the chip over a tooth every plant step, {'play on every joint' if play else 'no play'}"
          f", {step_s * 1e3:g} ms: the "
          "cross-feed force's oscillation (off its 50 ms mean)")
    print("| t (s) | tool at x (mm) | largest (N) | frequency (Hz) | growth (1/s) |")
    print("|---|---|---|---|---|")
    for a in np.concatenate([np.arange(0.70, 0.85, 0.05), np.arange(1.90, 2.45, 0.05)]):  # the entry; the onset
        m = (t >= a) & (t < a + 0.1)
        y = osc[m]
        spec = np.abs(np.fft.rfft(y * np.hanning(len(y)), 16 * len(y)))
        f = np.fft.rfftfreq(16 * len(y), dt)
        nb = int(round(0.02 / dt))
        peaks = [np.abs(y[i:i + nb]).max() for i in range(0, len(y) - nb + 1, nb)]
        g = np.polyfit(np.arange(len(peaks)) * 0.02, np.log(peaks), 1)[0]
        print(f"| {a:.2f}-{a + 0.1:.2f} | {x[m][0]:.1f}-{x[m][-1]:.1f} | {np.abs(y).max():.2f} | "
              f"{f[np.argmax(spec[5:]) + 5]:.1f} | {g:+.1f} |", flush=True)
    print()


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--face-and-contour", action="store_true", help="also face_and_contour's cut")
    ap.add_argument("--drake", action="store_true", help="also the station's run with the chip over a tooth "
                                                         "(about 5 minutes)")
    ap.add_argument("--drake-play", action="store_true", help="the same with the gears' play (about 5 minutes)")
    args = ap.parse_args(argv)
    robot = load_robot()
    cut = Cut(pr.paper_scenario("block", robot, 0), robot)
    print(f"The paper's block (draw 0, the paper's forces): tooth period {cut.T * 1e3:.3f} ms, feed "
          f"{cut.law.feed_m_per_s * 1e3:.0f} mm/s, depth 3 mm\n")
    continuous_table(cut, (1600.0, 1640.0))
    onset_table(cut, np.arange(1490.0, 1531.0, 2.5))
    scheme_table(cut, 1600.0)
    unstable_mode(cut, 1600.0)
    depth_and_direction(cut, 1600.0)
    own_forces(robot)
    if args.face_and_contour:
        face_and_contour(robot)
    if args.drake:
        drake_run(robot)
    if args.drake_play:
        drake_run(robot, play=True)


if __name__ == "__main__":
    main()
