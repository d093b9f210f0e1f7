"""Does the loop model's stability test agree with where the simulation
diverges?  The sweep of diagrams/interrupted_cut_low_damping.yaml (3 % modal
damping on every mode): periods 4-48 ms x cutoffs 5-50 Hz x delays 0 and 2 periods, plain
compensation, each run simulated and predicted.

A run counts as divergent in simulation when it went unstable (non-finite,
saturated for good, surface error above 3 mm) or oscillated beyond 1 mm; in
the model when its worst pole would grow more than 10x over the engaged
time.  Prints the confusion and the disagreements; without --from-json it
writes the runs to docs/sweep_low_damping_boundary.json, with --plot it draws
them as `robstiff sweep --plot` does.
Run: python3 studies/stability_boundary.py [--from-json docs/sweep_low_damping_boundary.json]
     [--plot docs/sweep_low_damping_boundary.png]
"""

import argparse
import json

from robstiff_drake.commands.sweep import plot
from robstiff_drake.diagrams.sweep import combinations, run_sweep
from robstiff_drake.io import emit_json
from robstiff_drake.paths import DIAGRAMS_DIR, REPO_ROOT


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--from-json", help="read the runs from a sweep JSON instead of running them")
    ap.add_argument("--plot", metavar="OUT.png", help="draw the runs (error against period, simulated and model)")
    ap.add_argument("--json", metavar="OUT.json", default=str(REPO_ROOT / "docs" / "sweep_low_damping_boundary.json"),
                    help="where the runs go (default docs/sweep_low_damping_boundary.json)")
    args = ap.parse_args()
    if args.from_json:
        rows = json.loads(open(args.from_json).read())["runs"]
    else:
        combos = combinations([4, 8, 12, 16, 24, 32, 48], [0, 2], [5, 10, 20, 50], ["plain"])
        rows = run_sweep(DIAGRAMS_DIR / "interrupted_cut_low_damping.yaml", combos)
        emit_json({"scenario": "diagrams/interrupted_cut_low_damping.yaml", "n_runs": len(rows), "complete": True,
                   "runs": rows}, args.json)
    if args.plot:
        plot(rows, args.plot)
    table = {}
    for r in rows:
        sim = (not r["stable"]) or r["surface_error_mm"]["max_abs"] > 1.0
        model = not r["predicted"]["stable"]
        table[(sim, model)] = table.get((sim, model), 0) + 1
    print("| | model: divergent | model: stable |")
    print("|---|---|---|")
    print(f"| simulation: divergent or > 1 mm | {table.get((True, True), 0)} | {table.get((True, False), 0)} |")
    print(f"| simulation: stable | {table.get((False, True), 0)} | {table.get((False, False), 0)} |")
    print("\ndisagreements (period ms, delay, cutoff Hz: simulated max |error| mm, model growth over the cut):")
    for r in rows:
        sim = (not r["stable"]) or r["surface_error_mm"]["max_abs"] > 1.0
        model = not r["predicted"]["stable"]
        if sim != model:
            p = r["predicted"]
            print(f"  {r['period_ms']:g}, {r['delay_steps']}, {r['cutoff_hz']:g}: "
                  f"{r['surface_error_mm']['max_abs']:.2f} mm, x{2.718281828 ** (p['growth_per_s'] * p['engaged_s']):.0f}")


if __name__ == "__main__":
    main()
