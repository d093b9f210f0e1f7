"""Which packaged scenarios would chatter?  diagrams/chatter_check.py (the
check `robstiff simulate` runs before a cut: the regenerative chip at up to
3 poses of the largest planned force) on every packaged scenario, and its
wall time per scenario (the first call in this process builds the arm's
joints, which the station's run then reuses; the law's compiled kernels are
warmed first, as a run compiles them anyway).  A few seconds.

    python studies/chatter_check_scenarios.py
    python studies/chatter_check_scenarios.py --simulate-timing   # and a whole simulate call with and without it

``--simulate-timing``: `simulate` of block_milling (both runs) in fresh
processes, alternately with the check and with it replaced by one that
returns None, three of each (about 30 s): the check's cost in a whole call
against the run-to-run spread.
"""

import argparse
import subprocess
import sys
import time

import numpy as np

from robstiff_drake.diagrams.chatter_check import chatter_check
from robstiff_drake.diagrams.path_references import planned_path
from robstiff_drake.diagrams.scenario import load_scenario, scenario_robot
from robstiff_drake.diagrams.scenario_models import plant_cutting_setup
from robstiff_drake.paths import packaged_scenarios, scenario_file


def one_simulate(scenario, check):
    """Wall time (s) of one simulate call in this process, the check on or off."""
    from robstiff_drake.commands import simulate as sim
    from robstiff_drake.diagrams import chatter_check as ch
    from robstiff_drake.io import Warnings
    if not check:
        ch.chatter_check = lambda *a, **k: None
    t0 = time.perf_counter()
    sim.simulate(scenario=scenario, compensation="both", warnings=Warnings(quiet=True))
    return time.perf_counter() - t0


def simulate_timing(scenario="block_milling", repeats=3):
    print(f"\nsimulate {scenario} (both runs), wall time (s) of the call in a fresh process:")
    print("| check | " + " | ".join(f"run {i + 1}" for i in range(repeats)) + " |")
    print("|---|" + "---|" * repeats)
    times = {True: [], False: []}
    for _ in range(repeats):
        for check in (True, False):
            out = subprocess.run([sys.executable, __file__, "--one", scenario, "on" if check else "off"],
                                 capture_output=True, text=True, check=True).stdout
            times[check].append(float(out.split()[-1]))
    for check in (True, False):
        print(f"| {'with' if check else 'without'} | " + " | ".join(f"{t:.2f}" for t in times[check]) + " |")


def table():
    sc = load_scenario(scenario_file("short_block"))
    _, law, wp = plant_cutting_setup(sc)
    law.average_wrench(np.array([1.6, 0.0, 0.7]), np.array([1.0, 0.0]), wp, law.feed_m_per_s)
    print("| scenario | cutting mode | stable | growth (1/s) | frequency (Hz) | where: t (s), x, y (mm) | arm modes "
          "(drives closed, Hz) | largest stable depth (mm) | check's wall time (ms) |")
    print("|---|---|---|---|---|---|---|---|---|")
    for name in packaged_scenarios():
        sc = load_scenario(scenario_file(name))
        robot = scenario_robot(sc)
        planned_path(sc, robot, robot.tool_point())  # (simulate has the path before the check)
        t0 = time.perf_counter()
        c = chatter_check(sc, robot)
        ms = (time.perf_counter() - t0) * 1e3
        if c is None:
            print(f"| {name} | {sc.cutting.mode} | not checked | | | | | | {ms:.0f} |")
            continue
        modes = ", ".join(f"{m['mode']} ({m['drives_closed_hz']:.1f})" for m in c["modes"] or [])
        depth = "" if c["largest_stable_depth_mm"] is None else f"{c['largest_stable_depth_mm']:.2f}"
        print(f"| {name} | {sc.cutting.mode} | {'yes' if c['stable'] else 'no'} | {c['growth_per_s']:+.2f} | "
              f"{c['frequency_hz']:.1f} | {c['t_s']:.2f}, {c['x_mm']:.0f}, {c['y_mm']:.0f} | {modes} | {depth} | "
              f"{ms:.0f} |", flush=True)


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--simulate-timing", action="store_true", help="a whole simulate call with and without the check")
    ap.add_argument("--one", nargs=2, metavar=("SCENARIO", "ON_OFF"), help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.one:
        print(f"{one_simulate(scenario_file(args.one[0]), args.one[1] == 'on'):.3f}")
        return
    table()
    if args.simulate_timing:
        simulate_timing()


if __name__ == "__main__":
    main()
