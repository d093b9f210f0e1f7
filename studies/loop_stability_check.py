"""Does `robstiff compensate`'s loop check (model/loop_check.py, the linear
loop model in numpy) call stable what the Drake cell keeps stable, and
unstable what diverges there?

The block test (diagrams/block_milling.yaml: IRB 6400, 4 ms period, one
period of transport delay, 250 Hz sensor, 5 % modal damping on the plant)
at three low-pass cutoffs.  For each:

* the arm without compensation (its own least damped mode, per period);
* the model at the path's first pose, at the plant's own damping (5 %) and
  at the check's margin (2 %), in air and cutting (the block pass's process
  stiffness at mid-pass, model/loop_model.process_stiffness: the check's
  NOMINAL_PROCESS_STIFFNESS_N_PER_M);
* Drake, in air: the cell held at the first pose and kicked
  (diagrams/hold_response.py), the envelope's growth rate against the
  model's ln(radius) / T;
* Drake, cutting: the whole compensated block pass (diagrams/sweep.run_one),
  diverged or not (a surface error above 3 mm or the correction saturated
  for good) and its largest surface error.

Run: python studies/loop_stability_check.py [--cutoffs 2,5,10] [--no-cut]
"""

import argparse
import math
import time

import numpy as np

from robstiff_drake.diagrams.hold_response import hold_response
from robstiff_drake.diagrams.loop_prediction import mid_pass_process_stiffness, scenario_loop_setup
from robstiff_drake.diagrams.scenario import load_scenario, scenario_robot
from robstiff_drake.diagrams.scenario_models import plant_damping_ratios
from robstiff_drake.model import loop_check
from robstiff_drake.model.filters import lowpass_coefficients
from robstiff_drake.paths import DIAGRAMS_DIR

SCENARIO = DIAGRAMS_DIR / "block_milling.yaml"


def model_rows(sc, robot, cutoffs):
    """{cutoff: {(damping label, mode): radius}} and the setup."""
    setup = scenario_loop_setup(sc, robot)
    modes = {"air": np.zeros((3, 3)), "cutting": mid_pass_process_stiffness(sc)}
    plant = plant_damping_ratios(sc)
    out = {}
    for f in cutoffs:
        ba = lowpass_coefficients(f, sc.sensor.rate_hz, sc.controller.filter.order)
        out[f] = {(d, m): setup.radius(ba, Kp, ratio) for d, ratio in (("plant", plant),
                                                                        ("margin", loop_check.MARGIN_DAMPING_RATIO))
                  for m, Kp in modes.items()}
    return setup, modes, out


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cutoffs", default="2,5,10", help="low-pass cutoffs, Hz (default: %(default)s)")
    ap.add_argument("--no-cut", action="store_true", help="leave out the Drake block passes")
    args = ap.parse_args()
    cutoffs = [float(c) for c in args.cutoffs.split(",")]
    sc = load_scenario(SCENARIO)
    robot = scenario_robot(sc, None)
    T = sc.controller.period_ms / 1e3
    setup, modes, radii = model_rows(sc, robot, cutoffs)
    print(f"scenario {SCENARIO.name}, robot {robot.name}, start pose {np.round(np.degrees(setup.q_rad), 2).tolist()} "
          f"deg; period {T * 1e3:g} ms, delay {sc.controller.delay_steps} period(s), sensor {sc.sensor.rate_hz:g} Hz; "
          f"plant damping {plant_damping_ratios(sc)[0]:.0%}, check margin {loop_check.MARGIN_DAMPING_RATIO:.0%}")
    print(f"cutting: K_p at mid-pass (N/mm) {np.round(modes['cutting'] / 1e3, 1).tolist()}")
    ba = lowpass_coefficients(cutoffs[0], sc.sensor.rate_hz, sc.controller.filter.order)
    print("without compensation (the arm and its drives): radius per period in air "
          f"{setup.radius(ba, modes['air'], plant_damping_ratios(sc), gain=0.0):.5f} at the plant's damping, "
          f"{setup.radius(ba, modes['air'], loop_check.MARGIN_DAMPING_RATIO, gain=0.0):.5f} at the margin's")
    print()
    print("cutoff | model radius per period, air / cutting    | check   | Drake, held in air and kicked          "
          "| Drake, block pass")
    print("  (Hz) | at 5 % (plant)      | at 2 % (margin)      | verdict | growth 1/s (model) | verdict       "
          "| verdict, max |error| mm")
    agree = []
    for f in cutoffs:
        r = radii[f]
        model_plant_unstable = max(r[("plant", "air")], r[("plant", "cutting")]) > loop_check.STABLE_RADIUS
        check = "refuse" if max(r[("margin", "air")], r[("margin", "cutting")]) > loop_check.STABLE_RADIUS else "pass"
        t0 = time.perf_counter()
        hold = hold_response(sc, robot, f)
        model_growth = math.log(r[("plant", "air")]) / T
        air_ok = hold.grows == (r[("plant", "air")] > loop_check.STABLE_RADIUS)
        agree.append(air_ok)
        cut = ""
        if not args.no_cut:
            from robstiff_drake.diagrams.sweep import run_one

            row = run_one(str(SCENARIO), {"period_ms": sc.controller.period_ms, "delay_steps": sc.controller.delay_steps,
                                          "cutoff_hz": f, "mode": "plain"}, predict=False)
            err = row.get("surface_error_mm", {}).get("max_abs", float("nan"))
            cut = f"{'stable' if row['stable'] else 'DIVERGED'}, {err:.3f}"
            agree.append(row["stable"] != model_plant_unstable)
        print(f"{f:6g} | {r[('plant', 'air')]:.5f} / {r[('plant', 'cutting')]:.5f} | "
              f"{r[('margin', 'air')]:.5f} / {r[('margin', 'cutting')]:.5f}    | {check:7s} | "
              f"{hold.growth_per_s:+6.2f} ({model_growth:+6.2f})    | {'grows' if hold.grows else 'decays':6s} "
              f"{'agrees' if air_ok else 'DISAGREES'} | {cut}   ({time.perf_counter() - t0:.0f} s)")
    print()
    print(f"model (at the plant's damping) and Drake agree in {sum(agree)} of {len(agree)} runs")


if __name__ == "__main__":
    main()
