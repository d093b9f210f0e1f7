"""The step the results need.

1. Stability: the station's step is symplectic Euler for the links with
   the gears' torque explicit and the drives exact over the step
   (model/joint_dynamics.py): stable while omega h < 2 in every mode,
   whatever the damping.  For each library robot at its reference pose:
   the stiffest modes and the largest stable step (the scheme's spectral
   radius), at the scenarios' 5 % modal damping; a step past it is refused
   before the run, naming the step that would do.

2. Convergence: the paper's block pass (diagrams/block_milling.yaml) and
   the cylinder-head pass (diagrams/cylinder_head.yaml), without and with
   compensation, at plant steps of 2 ms (the scenarios'), 1 ms and 0.5 ms,
   the sensor at 250 Hz (the scenarios') or 1 kHz, and at 1 ms with the
   revolution-averaged cutting force updated every plant step instead of
   every 4 ms (diagrams/station.AVERAGED_FORCE_PERIOD_S).  Surface error
   mean / PV (um).

3. Two cases of the sampling-delay study (diagrams/interrupted_cut.yaml,
   plain compensation, one period of delay: 24 ms with a 5 Hz filter, the
   scenario's, and 2 ms with 5 Hz) at plant steps of 2, 1 and 0.5 ms: the
   worst entry/exit error (mm).

4. Play and teeth (``--play-and-teeth`` runs this part alone, a few
   minutes): joint 6 of the IRB 6400 with 0.29 mrad of play, released from
   6-10 N*m on a flank (diagrams/gear_impacts.py, no friction in the play):
   each impact's coefficient of restitution, the flank crossings and the
   rattle's duration against the plant step, and the same with the
   plant's friction in the play; the 360 Hz tooth-pass torque on joint 6
   handed to the plant as the milling force source does
   (diagrams/tooth_response.py): the twist per N*m against the continuous
   joints' response, and the wrist mode the step makes of the 126 Hz one
   (JointModel.step_modes); the compensator's lost-motion law identified
   from a play campaign (diagrams/play_campaign.py) against the 50 N*m
   take-up; and the steps the station asks for (it refuses coarser ones),
   and the "default step" rows: the step it takes for a scenario with that
   play, or a tooth-resolved force, that gives no plant_config.time_step.

docs/results.md quotes `python3 studies/time_step_convergence.py`.
"""

import copy

import numpy as np

from robstiff_drake.diagrams import station
from robstiff_drake.diagrams.experiment import run_cut
from robstiff_drake.diagrams.scenario import load_scenario
from robstiff_drake.model import ik, joint_dynamics
from robstiff_drake.model.robot import load_robot
from robstiff_drake.model.servo import ServoParameters
from robstiff_drake.paths import DIAGRAMS_DIR, library_robots

SETTINGS = ((2.0, 250.0, True), (2.0, 1000.0, True), (1.0, 250.0, True), (1.0, 1000.0, True),
            (1.0, 1000.0, False), (0.5, 1000.0, True))  # (plant step ms, sensor Hz, force every 4 ms)


def stability():
    servo = ServoParameters(60.0, 30.0, 1.0, 0.012)  # the scenarios' servo
    print("| robot | stiffest modes, servo closed (Hz) | largest stable step (ms) | omega h at 2 ms |")
    print("|---|---|---|---|")
    for name in library_robots():
        robot = load_robot(name)
        q = ik.solve_ik(robot.dh, ik.tool_down_pose(robot.workspace.reference_tool_point_m),
                        robot.payload.tool_point_m)
        K = joint_dynamics.stiffness_matrix(robot.joint_stiffness_Nm_per_rad)
        jm = station.joint_model(station.controller_model(robot), robot, q, K,
                                 joint_dynamics.DEFAULT_MODAL_DAMPING_RATIO, servo)
        f = jm.closed_loop_modes()[0]
        h = jm.largest_stable_step_s(0.01)
        print(f"| {name} | {', '.join(f'{v:.0f}' for v in f[-3:])} | {h * 1e3:.2f} | "
              f"{2 * np.pi * f[-1] * 0.002:.2f} |")


def convergence(robot):
    print("| scenario | plant step (ms) | sensor (Hz) | cutting force updated | uncompensated mean / PV (um) | "
          "compensated mean / PV (um) |")
    print("|---|---|---|---|---|---|")
    for name in ("block_milling", "cylinder_head"):
        base = load_scenario(DIAGRAMS_DIR / f"{name}.yaml")
        for step_ms, rate_hz, every_4ms in SETTINGS:
            sc = copy.deepcopy(base)
            sc.plant_config.time_step, sc.sensor.rate_hz = step_ms / 1e3, rate_hz
            station.AVERAGED_FORCE_PERIOD_S = 0.004 if every_4ms else 0.0
            try:
                off, on = (run_cut(sc, robot, compensation=c) for c in (False, True))
            finally:
                station.AVERAGED_FORCE_PERIOD_S = 0.004
            a, b = off.surface_error_mm, on.surface_error_mm
            print(f"| {name} | {step_ms:g} | {rate_hz:g} | {'every 4 ms' if every_4ms else 'every step'} | "
                  f"{a['mean'] * 1e3:+.1f} / {a['pv'] * 1e3:.1f} | {b['mean'] * 1e3:+.2f} / {b['pv'] * 1e3:.1f} |",
                  flush=True)


def sampling_delay(robot):
    print("| interrupted_cut, plain | plant 2 ms | 1 ms | 0.5 ms |")
    print("|---|---|---|---|")
    base = load_scenario(DIAGRAMS_DIR / "interrupted_cut.yaml")
    for period_ms, cutoff_hz in ((24.0, 5.0), (2.0, 5.0)):
        cells = []
        for step_ms in (2.0, 1.0, 0.5):
            sc = copy.deepcopy(base)
            sc.plant_config.time_step, sc.controller.period_ms = step_ms / 1e3, period_ms
            sc.controller.filter.cutoff_hz, sc.controller.delay_steps = cutoff_hz, 1
            e = run_cut(sc, robot, compensation=True).surface_error_mm
            cells.append(f"{max(e['entry_max_abs'], e['exit_max_abs']):.3f}")
        print(f"| {period_ms:g} ms, {cutoff_hz:g} Hz | " + " | ".join(cells) + " |", flush=True)


B6_RAD = 2.9e-4  # 1 arc-minute (the paper reproduction's play)
LOADS_NM = np.linspace(6.0, 10.0, 9)  # the release's load: the impacts' phases on the step's grid differ


def _release(robot, q, servo, h, friction, duration_s):
    from robstiff_drake.diagrams import gear_impacts

    e, n, d = [], [], []
    for load in LOADS_NM:
        t, phi, rate = gear_impacts.release_run(robot, q, step_s=h, play_rad=np.r_[np.zeros(5), B6_RAD], joint=5,
                                                load_Nm=load, release_s=0.05, duration_s=duration_s, servo=servo,
                                                gap_friction_Nm=friction)
        ei, ni, di = gear_impacts.impacts(t, phi, rate, B6_RAD, 0.05)
        e.extend(ei[:2])
        n.append(ni)
        d.append(di)
    return np.array(e), n, d


_DEFAULT = " (the default step)"  # the row of the step the station takes when the scenario gives none


def play_and_teeth():
    from robstiff_drake.diagrams import compliant_arm, plant_step, tooth_response
    from robstiff_drake.diagrams.play_campaign import play_campaign
    from robstiff_drake.identification.stiffness.play_law import fit_play_law
    from robstiff_drake.model import transmission

    robot = load_robot()
    servo = ServoParameters(60.0, 30.0, 1.0, 0.012)
    q = ik.solve_ik(robot.dh, ik.tool_down_pose(robot.workspace.reference_tool_point_m), robot.payload.tool_point_m)
    K = joint_dynamics.stiffness_matrix(robot.joint_stiffness_Nm_per_rad)
    jm = station.joint_model(station.controller_model(robot), robot, q, K, 0.05, servo)
    play = np.r_[np.zeros(5), B6_RAD]
    f_c = compliant_arm.contact_frequencies_hz(jm)[5]
    converged = float(np.median(_release(robot, q, servo, 1.25e-4, np.zeros(6), 0.3)[0]))
    print(f"Joint 6, {B6_RAD * 1e3:g} mrad of play, contact mode {f_c:.0f} Hz, released from "
          f"{LOADS_NM[0]:g}-{LOADS_NM[-1]:g} N*m ({len(LOADS_NM)} loads, the first two impacts each); converged "
          f"restitution (median at 0.125 ms) {converged:.3f}, exp(-pi zeta / sqrt(1 - zeta^2)) at 5 %: "
          f"{np.exp(-np.pi * 0.05 / np.sqrt(1 - 0.05 ** 2)):.3f}")
    print("| plant step (ms) | omega_c h | restitution min - max | worst off the converged | flank crossings | "
          "rattle after the release (s) |")
    print("|---|---|---|---|---|---|")
    h_play = plant_step.chosen_step(jm, play)[0]  # the step a scenario with this play and no step given gets
    for h in sorted({2e-3, 1e-3, 5e-4, 2.5e-4, h_play}, reverse=True):
        e, n, d = _release(robot, q, servo, h, np.zeros(6), 1.2)
        print(f"| {h * 1e3:g}{_DEFAULT if abs(h - h_play) < 1e-12 else ''} | {2 * np.pi * f_c * h:.2f} | "
              f"{e.min():.3f} - {e.max():.3f} | {np.max(np.abs(e / converged - 1.0)):.1%} | {min(n)}-{max(n)} | {min(d):.2f}-{max(d):.2f} |",
              flush=True)
    fr = transmission.gap_friction_Nm(K)[5]
    for h in (2e-3, 5e-4):
        _, n, d = _release(robot, q, servo, h, None, 1.2)
        print(f"| {h * 1e3:g}, friction in the play ({fr:.1f} N*m) | | | | {min(n)}-{max(n)} | "
              f"{min(d):.3f}-{max(d):.3f} |", flush=True)
    print()
    A, B = jm.continuous()
    x = np.linalg.solve(2j * np.pi * 360.0 * np.eye(30) - A, B[:, 18 + 5])
    exact = abs(x[12 + 5] - x[5])
    f0, z0 = jm.closed_loop_modes()
    print(f"Joint 6 under a 360 Hz tooth-pass torque, the step's mean handed to the plant; continuous joints: "
          f"{exact:.3e} rad/(N*m), wrist mode {f0[-1]:.1f} Hz / {z0[-1]:.1%}")
    print("| plant step (ms) | twist per N*m (rad/(N*m)) | against the continuous | wrist mode the step makes |")
    print("|---|---|---|---|")
    h_tooth = plant_step.chosen_step(jm, None, 360.0)[0]  # a tooth-resolved scenario's with no step given
    for h in sorted({2e-3, 1e-3, 5e-4, 2.5e-4, h_tooth}, reverse=True):
        tw = tooth_response.twist_per_Nm(robot, q, step_s=h, servo=servo)
        fs, zs = jm.step_modes(h)
        print(f"| {h * 1e3:g}{_DEFAULT if abs(h - h_tooth) < 1e-12 else ''} | {tw:.3e} | {tw / exact - 1.0:+.1%} | "
              f"{fs[-1]:.1f} Hz / {zs[-1]:.1%} |", flush=True)
    print()
    c = 1.0 / robot.joint_stiffness_Nm_per_rad[5]
    tau, phi = play_campaign(robot, q, joint=5, play_rad=play, step_s=5e-4, servo=servo)
    law = fit_play_law(tau, phi, c)
    plant = c * 8.0 + B6_RAD
    print(f"The compensator's lost-motion law, joint 6 at 8 N*m (the plant twists {plant:.3e} rad):")
    print("| take-up torque | b (mrad) | tau_b (N*m) | predicted twist (rad) |")
    print("|---|---|---|---|")
    rows = (("50 N*m for every joint (before)", B6_RAD, transmission.TAU_B_NM),
            ("fallback: 1.5 % of the rated torque", B6_RAD, transmission.fallback_take_up_Nm(c)),
            (f"identified from a play campaign ({law.n} loads, +-0.5 to 32 N*m)", law.lost_motion_rad,
             law.take_up_Nm))
    for label, b, tb in rows:
        print(f"| {label} | {b * 1e3:.3f} | {tb:.2f} | {c * 8.0 + b * np.tanh(8.0 / tb):.3e} |")
    print()
    print(f"Steps the station asks for: play on joint 6 {compliant_arm.resolving_step_s(jm, play) * 1e3:g} ms, "
          f"tooth-resolved 360 Hz {compliant_arm.tooth_resolving_step_s(jm, 360.0) * 1e3:g} ms; at 2 ms:")
    print("  " + compliant_arm.under_resolved_play_message(jm, play, 2e-3))
    print("  " + compliant_arm.unresolved_tooth_message(jm, 360.0, 2e-3))
    print("With no plant_config.time_step given (diagrams/plant_step.chosen_step):")
    print("  " + plant_step.chosen_step(jm, play)[1])
    print("  " + plant_step.chosen_step(jm, None, 360.0)[1])


def main():
    import sys

    if "--play-and-teeth" in sys.argv[1:]:
        play_and_teeth()
        return
    stability()
    print()
    robot = load_robot()
    convergence(robot)
    print()
    sampling_delay(robot)
    print()
    play_and_teeth()


if __name__ == "__main__":
    main()
