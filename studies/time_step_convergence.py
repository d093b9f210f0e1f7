"""Is the block test converged in the plant's time step and the sensor's
rate?  The paper's block pass (diagrams/block_milling.yaml) and the
cylinder-head pass (diagrams/cylinder_head.yaml), without and with
compensation, for plant steps of 1, 2 and 4 ms and the sensor read at 1 kHz
or once per 4 ms controller cycle (250 Hz).  Prints the surface error (mean,
PV, um) of each run.

Then two cases of the sampling-delay study (diagrams/interrupted_cut.yaml,
plain compensation, one period of delay: 2 ms period with a 5 Hz filter, and
16 ms with 20 Hz) at plant steps of 2, 1 and 0.5 ms: the worst entry/exit
error (mm).

The scenarios use 4 ms and 250 Hz; docs/results.md quotes
`python3 studies/time_step_convergence.py`.
"""

import copy

from robstiff_drake.diagrams.experiment import run_cut
from robstiff_drake.diagrams.scenario import load_scenario
from robstiff_drake.model.robot import load_robot
from robstiff_drake.paths import DIAGRAMS_DIR

SETTINGS = ((1.0, 1000.0), (2.0, 1000.0), (2.0, 250.0), (4.0, 1000.0), (4.0, 250.0))  # (plant step ms, sensor Hz)


def main():
    robot = load_robot()
    print("| scenario | plant step (ms) | sensor (Hz) | uncompensated mean / PV (um) | compensated mean / PV (um) |")
    print("|---|---|---|---|---|")
    for name in ("block_milling", "cylinder_head"):
        base = load_scenario(DIAGRAMS_DIR / f"{name}.yaml")
        for step_ms, rate_hz in SETTINGS:
            sc = copy.deepcopy(base)
            sc.plant_config.time_step, sc.sensor.rate_hz = step_ms / 1e3, rate_hz
            off, on = (run_cut(sc, robot, compensation=c) for c in (False, True))
            a, b = off.surface_error_mm, on.surface_error_mm
            print(f"| {name} | {step_ms:g} | {rate_hz:g} | {a['mean'] * 1e3:+.1f} / {a['pv'] * 1e3:.1f} | "
                  f"{b['mean'] * 1e3:+.2f} / {b['pv'] * 1e3:.1f} |")
    print()
    print("| interrupted_cut, plain | plant 2 ms | 1 ms | 0.5 ms |")
    print("|---|---|---|---|")
    base = load_scenario(DIAGRAMS_DIR / "interrupted_cut.yaml")
    for period_ms, cutoff_hz in ((2.0, 5.0), (16.0, 20.0)):
        cells = []
        for step_ms in (2.0, 1.0, 0.5):
            sc = copy.deepcopy(base)
            sc.plant_config.time_step, sc.controller.period_ms = step_ms / 1e3, period_ms
            sc.controller.filter.cutoff_hz, sc.controller.delay_steps = cutoff_hz, 1
            e = run_cut(sc, robot, compensation=True).surface_error_mm
            cells.append(f"{max(e['entry_max_abs'], e['exit_max_abs']):.3f}")
        print(f"| {period_ms:g} ms, {cutoff_hz:g} Hz | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
