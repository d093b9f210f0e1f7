"""How much the compensator's stiffness model matters on the paper's block
test: the plant's true joint stiffness is off the nominal values (by
-15, +10, -10, +20, -20, 0 %), and the compensator holds either the exact
model, the nominal one, or one identified by `robstiff identify` from a
noisy synthetic campaign of that plant (120 measurements, 0.01 mm noise,
tool point at the spindle's (0, 0, 350) mm).

Prints a table of the surface error (mm) for each case; docs/results.md
quotes `python3 studies/compensation_model_error.py`.
"""

import copy

import numpy as np

from robstiff_drake.diagrams.experiment import run_cut
from robstiff_drake.diagrams.scenario import load_scenario
from robstiff_drake.identification.stiffness import synth
from robstiff_drake.identification.stiffness.joint_stiffness import identify
from robstiff_drake.model.robot import load_robot
from robstiff_drake.paths import DIAGRAMS_DIR

OFFSET = np.array([0.85, 1.10, 0.90, 1.20, 0.80, 1.00])


def main():
    robot = load_robot()
    k_true = robot.joint_stiffness_Nm_per_rad * OFFSET
    tool = robot.payload.tool_point_m
    c = synth.stiffness_campaign(robot, n=120, noise_mm=0.01, seed=7, tool_m=tool, true_stiffness_Nm_per_rad=k_true)
    fit = identify(robot, c.to_campaign(), tool_m=tool)
    base = load_scenario(DIAGRAMS_DIR / "block_milling.yaml")
    base.plant.joint_stiffness_Nm_per_rad = list(k_true)
    rows = []
    for label, k_model, comp in (("uncompensated", None, False),
                                 ("exact model", k_true, True),
                                 ("identified model", fit.stiffness_Nm_per_rad, True),
                                 ("nominal model", robot.joint_stiffness_Nm_per_rad, True)):
        sc = copy.deepcopy(base)
        if k_model is not None:
            sc.model.joint_stiffness_Nm_per_rad = list(k_model)
        res = run_cut(sc, robot, compensation=comp)
        rows.append((label, res.surface_error_mm))
    print("plant stiffness / nominal:", OFFSET.tolist())
    print("identified / true:", np.round(fit.stiffness_Nm_per_rad / k_true, 4).tolist(),
          "(joint 6 not identifiable: kept nominal)" if not fit.identifiable[5] else "")
    print("| compensator | mean (mm) | rms (mm) | max abs (mm) | PV (mm) |")
    print("|---|---|---|---|---|")
    for label, s in rows:
        print(f"| {label} | {s['mean']:+.4f} | {s['rms']:.4f} | {s['max_abs']:.4f} | {s['pv']:.4f} |")


if __name__ == "__main__":
    main()
