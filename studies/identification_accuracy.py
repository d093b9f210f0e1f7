"""How well `robstiff identify` recovers joint stiffness from synthetic
campaigns, and whether its 95 % intervals are honest.

For each of N seeds: a 120-measurement campaign (30 poses x 4 loads of 300 N
in random directions, CMM noise 0.01 mm, tool point at the flange origin),
made with joint stiffnesses that are NOT the nominal ones, then identified.
Prints, per joint: the largest and RMS relative error, and the fraction of
95 % intervals that contain the true value.  The README's figures come from
`python3 studies/identification_accuracy.py` (default 500 seeds).
"""

import argparse

import numpy as np

from robstiff_drake.identification.stiffness import synth
from robstiff_drake.identification.stiffness.joint_stiffness import identify
from robstiff_drake.model.robot import load_robot

K_TRUE = np.array([1.3e6, 1.2e6, 0.7e6, 3.5e5, 2.5e5, 2.0e5])


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=500)
    ap.add_argument("--noise-mm", type=float, default=0.01)
    args = ap.parse_args()
    robot = load_robot()
    errs, hits, counted = [], np.zeros(6), np.zeros(6)
    for seed in range(args.seeds):
        c = synth.stiffness_campaign(robot, n=120, noise_mm=args.noise_mm, seed=10_000 + seed,
                                     true_stiffness_Nm_per_rad=K_TRUE)
        fit = identify(robot, c.to_campaign())
        rel = np.where(fit.identifiable, fit.stiffness_Nm_per_rad / K_TRUE - 1, np.nan)
        errs.append(rel)
        for j in np.flatnonzero(fit.identifiable):
            lo, hi = fit.stiffness_ci95_Nm_per_rad[j]
            hits[j] += lo <= K_TRUE[j] <= hi
            counted[j] += 1
    errs = np.array(errs)
    print(f"{args.seeds} synthetic campaigns, 120 measurements, {args.noise_mm:g} mm noise, true K = {K_TRUE.tolist()}")
    print("| joint | identified in | max abs rel. error | RMS rel. error | 95 % interval coverage |")
    print("|---|---|---|---|---|")
    for j in range(6):
        if counted[j] == 0:
            print(f"| {j + 1} | 0 % (flagged: force on its axis) | - | - | - |")
            continue
        e = errs[:, j][~np.isnan(errs[:, j])]
        print(f"| {j + 1} | {100 * counted[j] / args.seeds:.0f} % | {100 * np.max(np.abs(e)):.2f} % | "
              f"{100 * np.sqrt(np.mean(e**2)):.2f} % | {100 * hits[j] / counted[j]:.1f} % |")


if __name__ == "__main__":
    main()
