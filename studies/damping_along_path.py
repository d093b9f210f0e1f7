"""The arm's damping where the arm is: the drives-closed damping ratio of
each arm mode (what a modal test with the drives on measures:
model/joint_dynamics.JointModel.arm_modes) at poses along a scenario's path
(default: the face-and-contour job, diagrams/face_and_contour.yaml), for

- before: the ratio stated on the motors-held modes at the path's first
  pose, the drives' integral corner at the stated 7.5 Hz (how the plant
  was built before);
- start pose: stated on the drives-closed modes, realised at the first
  pose, the corner chosen below the first antiresonance (model/servo.py);
- path fit: as the station builds it, one gears' damping fitted over the
  path's poses (diagrams/compliant_arm.arm_joints).

And the loop check (model/loop_check.py, 2 % margin damping on the
drives-closed modes, the scenario's filter) at 12 poses along the path,
its worst pose: diagrams/loop_prediction.path_loop_margins.  No
simulation: the station's linear joints at each pose (about 10 s).

    python3 studies/damping_along_path.py [SCENARIO.yaml] [--samples N]
"""

import argparse
import dataclasses

import numpy as np

from robstiff_drake.diagrams.compensator import filter_coefficients
from robstiff_drake.diagrams.compliant_arm import arm_joints, mass_and_weight_stiffness, path_poses
from robstiff_drake.diagrams.loop_prediction import path_loop_margins
from robstiff_drake.diagrams.milling_cell import planned_path
from robstiff_drake.diagrams.scenario import load_scenario, scenario_robot
from robstiff_drake.diagrams.scenario_models import cutting_setup, plant_damping_ratios, plant_stiffness
from robstiff_drake.diagrams.station import controller_model, servo_parameters
from robstiff_drake.model import joint_dynamics as jd
from robstiff_drake.paths import DIAGRAMS_DIR


def ranges(sc, samples=64):
    """{case: (corner Hz, min (6,), max (6,)) of the drives-closed ratios
    at ``samples`` poses along the path}."""
    robot = scenario_robot(sc)
    _, _, q_ref = planned_path(sc, robot, robot.tool_point())
    ctrl = controller_model(robot)
    K = jd.stiffness_matrix(plant_stiffness(sc, robot), sc.plant.coupling_c23_rad_per_Nm)
    ratios = plant_damping_ratios(sc)
    poses = [mass_and_weight_stiffness(ctrl, q) for q in path_poses(q_ref, samples)]
    servo = servo_parameters(sc)
    cases = {"before (motors held at the first pose, 7.5 Hz corner)":
             arm_joints(ctrl, robot, q_ref[0], K, ratios, dataclasses.replace(servo, integral_rule="stated",
                                                                              velocity_integral_hz=7.5), "motors_held"),
             "drives closed at the first pose, corner below the antiresonance":
             arm_joints(ctrl, robot, q_ref[0], K, ratios, servo, "drives_closed"),
             "drives closed, fitted along the path (the station's)":
             arm_joints(ctrl, robot, path_poses(q_ref), K, ratios, servo, "drives_closed")}
    out = {}
    for name, jm in cases.items():
        Z = np.array([jm.at_pose(M, G).arm_modes()[1] for M, G in poses])
        out[name] = (jm.servo.velocity_integral_hz, Z.min(axis=0), Z.max(axis=0))
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("scenario", nargs="?", default=str(DIAGRAMS_DIR / "face_and_contour.yaml"))
    ap.add_argument("--samples", type=int, default=64)
    a = ap.parse_args()
    sc = load_scenario(a.scenario)
    print(f"{sc.name}: drives-closed damping ratio of each arm mode at {a.samples} poses along the path, "
          f"min-max (stated: {', '.join(f'{z:.1%}' for z in np.unique(plant_damping_ratios(sc)))})")
    print("| plant | integral corner Hz | mode 1 | mode 2 | mode 3 | mode 4 | mode 5 | mode 6 | first three |")
    print("|---|---|---|---|---|---|---|---|---|")
    for name, (fi, lo, hi) in ranges(sc, a.samples).items():
        print(f"| {name} | {fi:.2f} | " + " | ".join(f"{a_ * 100:.1f}-{b_ * 100:.1f} %" for a_, b_ in zip(lo, hi))
              + f" | {lo[:3].min() * 100:.1f}-{hi[:3].max() * 100:.1f} % |")
    robot = scenario_robot(sc)
    ctl = sc.controller
    ba = filter_coefficients(ctl.filter, sc.sensor.rate_hz, cutting_setup(sc)[0].spindle_rpm)
    rows = path_loop_margins(sc, robot, ba)
    worst = max(rows, key=lambda r: max(r["spectral_radius"].values()))
    first = rows[0]["spectral_radius"]
    print(f"loop check along the path ({len(rows)} poses, {ctl.filter.kind} {ctl.filter.cutoff_hz:g} Hz, "
          f"{ctl.period_ms:g} ms period, 2 % margin damping): first pose {first['air']:.4f} in air, "
          f"{first['cutting']:.4f} cutting; worst at row {worst['row']} (t = {worst['t_s']:.2f} s): "
          f"{worst['spectral_radius']['air']:.4f} in air, {worst['spectral_radius']['cutting']:.4f} cutting")


if __name__ == "__main__":
    main()
