"""Which packaged scenarios would chatter?  diagrams/chatter_check.py (the
check `robstiff simulate` runs before a cut: the regenerative chip at every
sampled pose that cuts) on every packaged scenario, and its
wall time per scenario (the first call in this process builds the arm's
joints, which the station's run then reuses; the law's compiled kernels are
warmed first, as a run compiles them anyway).  A few seconds.

    python studies/chatter_check_scenarios.py
    python studies/chatter_check_scenarios.py --simulate-timing   # and a whole simulate call with and without it
    python studies/chatter_check_scenarios.py --dense             # and 3 poses against every sample (10 s)
    python studies/chatter_check_scenarios.py --slow-feed         # and block_milling at slower feeds (5 s)

The second table: for each warned scenario, the modal damping that would
make the cut stable (diagrams/chatter_damping.py: the involved modes alone,
and the same ratio on every mode, by bisection).

``--dense``: the check as it was before issue 29's step 3 (3 poses of
the largest force, a fifth of the cut apart, each refined) against the
check now (every one of the SAMPLES times that cuts, the REFINED_POSES of
the rightmost Pade roots refined): does a verdict or the worst growth
change?

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


def warm_up():
    sc = load_scenario(scenario_file("short_block"))
    _, law, wp = plant_cutting_setup(sc)
    law.average_wrench(np.array([1.6, 0.0, 0.7]), np.array([1.0, 0.0]), wp, law.feed_m_per_s)


def table():
    warm_up()
    checks = {}
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
        checks[name] = c
        if c is None:
            print(f"| {name} | {sc.cutting.mode} | not checked | | | | | | {ms:.0f} |")
            continue
        modes = ", ".join(f"{m['mode']} ({m['drives_closed_hz']:.1f})" for m in c["modes"] or [])
        depth = "" if c["largest_stable_depth_mm"] is None else f"{c['largest_stable_depth_mm']:.2f}"
        print(f"| {name} | {sc.cutting.mode} | {'yes' if c['stable'] else 'no'} | {c['growth_per_s']:+.2f} | "
              f"{c['frequency_hz']:.1f} | {c['t_s']:.2f}, {c['x_mm']:.0f}, {c['y_mm']:.0f} | {modes} | {depth} | "
              f"{ms:.0f} |", flush=True)
    return checks


def pct(v):
    return "not within 50" if v is None else f"{100 * v:.1f}"


def damping_table(checks):
    """The damping that would make each warned cut stable (its check's damping_to_stabilise)."""
    print("\n| scenario | growth (1/s) | frequency (Hz) | arm modes | their damping now (drives closed, %) | stable "
          "from, on these modes alone (drives closed, %) | stable from, the same stated on every mode (%) |")
    print("|---|---|---|---|---|---|---|")
    for name, c in checks.items():
        d = c and c.get("damping_to_stabilise")
        if not d:
            continue
        need = ("not within 50" if d["realised_on_these_modes"] is None else
                " / ".join(f"{100 * v:.2f}" for v in d["realised_on_these_modes"]))
        print(f"| {name} | {c['growth_per_s']:+.2f} | {c['frequency_hz']:.1f} | "
              f"{', '.join(str(m) for m in d['modes'])} | {' / '.join(f'{100 * v:.2f}' for v in d['ratio_now'])} | "
              f"{need} | {pct(d['on_every_mode'])} |")


FEW_POSES, FEW_SPACING = 3, 0.2  # the check's poses before: 3 of the largest force, a fifth of the cut apart


def dense_table():
    """The check at the FEW_POSES poses of the largest force against every in-cut sample (the default now)."""
    from robstiff_drake.diagrams import chatter_check as ch
    from robstiff_drake.diagrams.chatter_check import SAMPLES
    warm_up()
    print(f"\n| scenario | {FEW_POSES} poses of the largest force: stable, growth (1/s), Hz, t (s) | every in-cut "
          f"sample of {SAMPLES}: poses, stable, growth (1/s), Hz, t (s) | verdict changes | growth change (1/s) | "
          f"wall time (ms): {FEW_POSES} poses, every sample |")
    print("|---|---|---|---|---|---|")
    for name in packaged_scenarios():
        sc = load_scenario(scenario_file(name))
        robot = scenario_robot(sc)
        planned_path(sc, robot, robot.tool_point())
        t0 = time.perf_counter()
        refined, ch.REFINED_POSES = ch.REFINED_POSES, FEW_POSES  # (each of the 3 refined, as it was)
        few = chatter_check(sc, robot, max_poses=FEW_POSES, min_spacing=FEW_SPACING)
        ch.REFINED_POSES = refined
        t1 = time.perf_counter()
        every = chatter_check(sc, robot)
        t2 = time.perf_counter()
        if few is None:
            print(f"| {name} | not checked | | | | |")
            continue

        def row(c):
            return (f"{'yes' if c['stable'] else 'no'}, {c['growth_per_s']:+.2f}, {c['frequency_hz']:.1f}, "
                    f"{c['t_s']:.2f}")
        print(f"| {name} | {row(few)} | {every['poses_checked']}: {row(every)} | "
              f"{'YES' if few['stable'] != every['stable'] else 'no'} | "
              f"{every['growth_per_s'] - few['growth_per_s']:+.2f} | {(t1 - t0) * 1e3:.0f}, {(t2 - t1) * 1e3:.0f} |",
              flush=True)


def slow_feed_table(feeds_mm_per_s=(1.0, 2.0, 3.6, 5.0, 10.0, 20.0)):
    """block_milling at slower feeds: the check with the law linearised at
    the real chip (below MIN_CHIP_M too, as before) and at no less than
    the law's validity (the check now); at 1 mm/s the law's parts taken
    out one by one (which of them makes the root)."""
    import dataclasses

    from robstiff_drake.diagrams import chatter_check as ch
    from robstiff_drake.diagrams import scenario_models as sm
    from robstiff_drake.model.plant_cutting import PlantCuttingLaw
    warm_up()
    sc0 = load_scenario(scenario_file("block_milling"))
    robot = scenario_robot(sc0)
    floor = ch.min_chip_m

    def check(feed, extrapolated=False, **physics):
        sc = load_scenario(scenario_file("block_milling"))
        sc.path.feed_mm_per_s = feed
        setup = sm.plant_cutting_setup
        if physics:
            def altered(s):
                cutter, law, wp = setup(s)
                return cutter, PlantCuttingLaw(law.linear, dataclasses.replace(law.physics, **physics)), wp
            sm.plant_cutting_setup = altered
        ch.min_chip_m = (lambda law: 0.0) if extrapolated else floor
        try:
            c = ch.chatter_check(sc, robot)
        finally:
            sm.plant_cutting_setup, ch.min_chip_m = setup, floor
        return f"{c['growth_per_s']:+.2f} at {c['frequency_hz']:.1f} Hz"

    _, law, _ = sm.plant_cutting_setup(sc0)
    print(f"\nblock_milling at slower feeds (tooth pass {law.cutter.tooth_pass_hz:.0f} Hz; the law linearised "
          f"at a feed per tooth of at least {floor(law) * 1e6:.0f} um now):")
    print("| feed (mm/s) | feed per tooth (um) | the law linearised at the real chip: growth (1/s) at | at no less "
          "than its validity (now) |")
    print("|---|---|---|---|")
    for feed in feeds_mm_per_s:
        print(f"| {feed:g} | {law.cutter.feed_per_tooth_m(feed / 1e3) * 1e6:.1f} | {check(feed, True)} | "
              f"{check(feed)} |", flush=True)
    print("\nat 1 mm/s, linearised at the real chip, the law's parts taken out:")
    print("| law | growth (1/s) at |")
    print("|---|---|")
    for label, physics in (("the plant's law", {}), ("edge forces in full at any chip (no ramp)",
                                                     {"edge_ramp_chip_m": 0.0}),
                           ("no runout", {"runout_m": 0.0}), ("chip exponent 1 (no Kienzle)", {"chip_exponent": 1.0}),
                           ("no runout, no ramp, exponent 1", {"runout_m": 0.0, "edge_ramp_chip_m": 0.0,
                                                               "chip_exponent": 1.0})):
        print(f"| {label} | {check(1.0, True, **physics)} |", flush=True)


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--simulate-timing", action="store_true", help="a whole simulate call with and without the check")
    ap.add_argument("--dense", action="store_true", help="and the check at 3 poses of the largest force against every sample")
    ap.add_argument("--slow-feed", action="store_true", help="and block_milling at slower feeds (the chip's floor)")
    ap.add_argument("--one", nargs=2, metavar=("SCENARIO", "ON_OFF"), help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.one:
        print(f"{one_simulate(scenario_file(args.one[0]), args.one[1] == 'on'):.3f}")
        return
    damping_table(table())
    if args.dense:
        dense_table()
    if args.slow_feed:
        slow_feed_table()
    if args.simulate_timing:
        simulate_timing()


if __name__ == "__main__":
    main()
