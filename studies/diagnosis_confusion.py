"""How often `robstiff diagnose` names the effect that a campaign carries,
and how often it invents one.

Cases: for each effect of the candidate library, and for campaigns with no
effect, CASES campaigns from `robstiff synth` (120 measurements, 30 poses x 4
loads of 300 N, CMM noise 0.01 mm), each with its own random poses, loads and
seed, the effect's parameters drawn in its physical pattern and its size
drawn uniformly in 0.02-0.06 mm RMS (of the part the six-spring model cannot
absorb by refitting).  The effect is not told to diagnose.

Prints the confusion table (rows: the effect present; columns: the first
effect named), the attribution and false-positive rates, and the held-out
RMS after the diagnosis against the noise.  The README's figures come from
`python3 studies/diagnosis_confusion.py` (default 30 cases per row).
"""

import argparse
import collections
import time

import numpy as np

from robstiff_drake.identification import synth
from robstiff_drake.identification.diagnosis import CANDIDATES, diagnose
from robstiff_drake.model.robot import load_robot

NOISE_MM = 0.01


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", type=int, default=30)
    ap.add_argument("--min-mm", type=float, default=0.02, help="smallest effect size (RMS beyond the springs)")
    ap.add_argument("--max-mm", type=float, default=0.06)
    args = ap.parse_args()
    robot = load_robot()
    truths = ["none"] + list(CANDIDATES)
    table = {t: collections.Counter() for t in truths}
    after, times = collections.defaultdict(list), []
    rng = np.random.default_rng(2026)
    for t_i, truth in enumerate(truths):
        for k in range(args.cases):
            seed = 100_000 * (t_i + 1) + k
            size = float(rng.uniform(args.min_mm, args.max_mm))
            effects = None if truth == "none" else {truth: size}
            c = synth.stiffness_campaign(robot, n=120, noise_mm=NOISE_MM, seed=seed, effects=effects)
            t0 = time.perf_counter()
            d = diagnose(robot, c.to_campaign())
            times.append(time.perf_counter() - t0)
            table[truth][d.selected[0] if d.selected else "none"] += 1
            after[truth].append(d.rms_after_mm)
    cols = truths
    short = {n: n.replace("_stiffness", "").replace("force_frame_rotation", "frame_rot") for n in cols}
    print(f"{args.cases} campaigns per row, effects of {args.min_mm:g}-{args.max_mm:g} mm RMS beyond the springs, "
          f"noise {NOISE_MM:g} mm; first effect named by `diagnose` (columns)")
    print("| present \\ named | " + " | ".join(short[c] for c in cols) + " | held-out RMS after / noise |")
    print("|---" * (len(cols) + 2) + "|")
    for t in truths:
        ratio = np.median(after[t]) / NOISE_MM
        print(f"| {short[t]} | " + " | ".join(str(table[t][c]) for c in cols) + f" | {ratio:.2f} (median) |")
    correct = sum(table[t][t] for t in truths if t != "none")
    total = args.cases * (len(truths) - 1)
    fp = args.cases - table["none"]["none"]
    within = np.mean([a <= 1.25 * NOISE_MM for t in truths for a in after[t]])
    print(f"\nattribution rate: {correct}/{total} = {100 * correct / total:.1f} % of campaigns with an effect had it "
          "named first")
    print(f"false-positive rate: {fp}/{args.cases} = {100 * fp / args.cases:.1f} % of campaigns without one got one")
    print(f"held-out RMS after within 25 % of the noise: {100 * within:.1f} % of all campaigns")
    print(f"diagnose time per 120-row campaign: median {1e3 * np.median(times):.0f} ms, max {1e3 * np.max(times):.0f} ms")


if __name__ == "__main__":
    main()
