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


def main():
    stability()
    print()
    robot = load_robot()
    convergence(robot)
    print()
    sampling_delay(robot)


if __name__ == "__main__":
    main()
