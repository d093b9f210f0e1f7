"""Identification accuracy for every robot of the library, with campaigns
written in each robot's controller convention (KUKA's A1..A6 with their
sign flips and offset, FANUC's J1..J6 with the J2/J3 interaction) and read
back from the file as `robstiff identify` reads it.

For each robot and each of N seeds: a synthetic campaign of 120
measurements (30 poses x 4 loads of 300 N in random directions, CMM noise
0.01 mm, the robot file's tool point, recorded in the file's `# tool_mm:`
line), made with joint stiffnesses that are NOT the nominal ones (the
nominal times the same fixed factors for every robot), written to a CSV
file, read back and identified.  Prints, per robot and joint, the RMS and
the largest relative error and the 95 % interval coverage; the IRB6400's
row is the reference.  docs/your_robot.md quotes
`python3 studies/robot_library_identification.py` (default 200 seeds).
"""

import argparse
import tempfile
from pathlib import Path

import numpy as np

from robstiff_drake.identification.stiffness import synth
from robstiff_drake.identification.stiffness.campaign import campaign_tool_m, read_stiffness_campaign
from robstiff_drake.identification.stiffness.joint_stiffness import identify
from robstiff_drake.model.robot import load_robot
from robstiff_drake.paths import library_robots

# true = nominal x these (the factors of studies/identification_accuracy.py's K_TRUE on the IRB6400)
FACTORS = np.array([1.3 / 1.5, 1.2 / 1.1, 0.7 / 0.8, 3.5 / 3.0, 2.5 / 3.0, 1.0])


def accuracy(name, seeds, noise_mm=0.01, folder=None):
    """(relative errors (seeds, 6), NaN where not identifiable; interval hits (6,); counted (6,))."""
    robot = load_robot(name)
    k_true = robot.joint_stiffness_Nm_per_rad * FACTORS
    tool = robot.payload.tool_point_m
    errs, hits, counted = [], np.zeros(6), np.zeros(6)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(folder or tmp) / f"{name}.csv"
        for seed in range(seeds):
            c = synth.stiffness_campaign(robot, n=120, noise_mm=noise_mm, seed=20_000 + seed, tool_m=tool,
                                         true_stiffness_Nm_per_rad=k_true)
            path.write_text(synth.stiffness_csv(c, robot=robot, noise_mm=noise_mm, seed=20_000 + seed,
                                                force_N=300.0, tool_m=tool, how="studies/robot_library_identification.py"))
            campaign = read_stiffness_campaign(path, robot)
            fit = identify(robot, campaign, tool_m=campaign_tool_m(campaign, robot))
            errs.append(np.where(fit.identifiable, fit.stiffness_Nm_per_rad / k_true - 1, np.nan))
            for j in np.flatnonzero(fit.identifiable):
                lo, hi = fit.stiffness_ci95_Nm_per_rad[j]
                hits[j] += lo <= k_true[j] <= hi
                counted[j] += 1
    return np.array(errs), hits, counted


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=200)
    args = ap.parse_args()
    print(f"{args.seeds} synthetic campaigns per robot, 120 measurements, 0.01 mm noise, tool point (0, 0, 350) mm, "
          "in each robot's controller convention")
    print("| robot | joint | identified in | RMS rel. error | max abs rel. error | 95 % interval coverage |")
    print("|---|---|---|---|---|---|")
    for name in library_robots():
        errs, hits, counted = accuracy(name, args.seeds)
        for j in range(6):
            if counted[j] == 0:
                print(f"| {name} | {j + 1} | 0 % (flagged: the loads give it no torque) | - | - | - |")
                continue
            e = errs[:, j][~np.isnan(errs[:, j])]
            print(f"| {name} | {j + 1} | {100 * counted[j] / args.seeds:.0f} % | {100 * np.sqrt(np.mean(e ** 2)):.2f} % "
                  f"| {100 * np.max(np.abs(e)):.2f} % | {100 * hits[j] / counted[j]:.1f} % |")


if __name__ == "__main__":
    main()
