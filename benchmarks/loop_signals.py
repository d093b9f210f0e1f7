"""Every logged signal of the closed-loop block pass, for checking that a
speed change changes no figure: ``dump`` runs the block pass
(diagrams/block_milling.yaml) plain, predictive, uncompensated and
tooth-resolved (plant 0.25 ms, sensor 1 kHz: bench_closed_loop.py's) and
writes every logger's times and samples and each scan line's machined
surface to an .npz; ``compare`` prints each array that differs between
two dumps (largest absolute and relative difference, NaNs placed
differently) and the largest relative difference of all, and exits 1 when
any array differs by more than ``--tolerance`` (relative; default 0: bit
for bit).  Run the dump on main and on the change (e.g. main's tree from
``git archive main`` with PYTHONPATH set to it), then compare:

    python benchmarks/loop_signals.py dump main.npz      # (main's tree)
    python benchmarks/loop_signals.py dump change.npz
    python benchmarks/loop_signals.py compare main.npz change.npz

About 2 minutes per dump on a quiet 2-core machine (the tooth-resolved
pass is most of it).  No target: figures only.
"""

import argparse
import copy
import sys
from pathlib import Path

import numpy as np

CASES = ("plain", "predictive", "uncompensated", "tooth")


def scenarios(base):
    """(name, scenario, compensation) of each pass."""
    out = [("plain", copy.deepcopy(base), True)]
    sc = copy.deepcopy(base)
    sc.controller.mode = "predictive"
    out.append(("predictive", sc, True))
    out.append(("uncompensated", copy.deepcopy(base), False))
    sc = copy.deepcopy(base)
    sc.cutting.mode = "tooth"
    sc.plant_config.time_step, sc.sensor.rate_hz = 0.00025, 1000.0
    out.append(("tooth", sc, True))
    return out


def dump(path, only):
    from robstiff_drake.diagrams.experiment import run_cut
    from robstiff_drake.diagrams.scenario import load_scenario
    from robstiff_drake.model.robot import load_robot
    from robstiff_drake.paths import DIAGRAMS_DIR

    robot = load_robot()
    arrays = {}
    for name, sc, compensation in scenarios(load_scenario(DIAGRAMS_DIR / "block_milling.yaml")):
        if only and name not in only:
            continue
        res = run_cut(sc, robot, compensation=compensation)
        for key, (t, x) in res.logs.items():
            arrays[f"{name}/{key}/t"] = np.asarray(t)
            arrays[f"{name}/{key}/x"] = np.asarray(x)
        for i, line in enumerate(res.scans):
            arrays[f"{name}/scan{i}/machined_m"] = np.asarray(line.machined_m)
        print(f"{name}: {len(res.logs)} logged signals, {len(res.scans)} scan lines", flush=True)
    np.savez(path, **arrays)
    print(f"wrote {path}")
    return 0


def compare(path_a, path_b, tolerance):
    a, b = np.load(path_a), np.load(path_b)
    ok = True
    for key in sorted(set(a.files) ^ set(b.files)):
        print(f"  {key}: in one dump only")
        ok = False
    worst = 0.0
    common = sorted(set(a.files) & set(b.files))
    for key in common:
        x, y = a[key], b[key]
        if x.shape != y.shape:
            print(f"  {key}: shape {x.shape} against {y.shape}")
            ok = False
            continue
        nan_moved = bool(np.any(np.isnan(x) != np.isnan(y)))
        d = float(np.nanmax(np.abs(x - y))) if x.size and not np.all(np.isnan(x - y)) else 0.0
        scale = float(np.nanmax(np.abs(x))) if x.size and not np.all(np.isnan(x)) else 0.0
        rel = d / scale if scale else d
        worst = max(worst, rel)
        if d or nan_moved:
            print(f"  {key}: largest difference {d:.3e} (relative {rel:.3e}){'; NaNs moved' if nan_moved else ''}")
        ok &= rel <= tolerance and not nan_moved
    print(f"{len(common)} arrays compared; largest relative difference {worst:.3e}: "
          f"{'the same' if ok else 'DIFFERENT'} (tolerance {tolerance:g})")
    return 0 if ok else 1


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    d = sub.add_parser("dump", help="run the passes, write their signals to an .npz")
    d.add_argument("out", help="the .npz to write")
    d.add_argument("--only", nargs="*", choices=CASES, default=None, help="these passes only")
    c = sub.add_parser("compare", help="compare two dumps")
    c.add_argument("a")
    c.add_argument("b")
    c.add_argument("--tolerance", type=float, default=0.0, help="largest relative difference allowed (default 0)")
    args = parser.parse_args(argv)
    if args.command == "dump":
        if not args.out.endswith(".npz"):
            parser.exit(2, f"loop_signals: dump: {args.out}: the output must end in .npz\n")
        return dump(args.out, args.only)
    for p in (args.a, args.b):
        if not Path(p).is_file():
            parser.exit(2, f"loop_signals: compare: {p}: no such file\n")
    if not args.tolerance >= 0:
        parser.exit(2, f"loop_signals: compare: --tolerance {args.tolerance}: must be >= 0\n")
    return compare(args.a, args.b, args.tolerance)


if __name__ == "__main__":
    sys.exit(main())
