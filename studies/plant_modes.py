"""The plant's modes at the start of each library robot's block test
(diagrams/block_milling*.yaml: the pose the station sets its damping and
tunes its drives at): the natural frequencies with the motors held (the
links on their gears), with the motors free (no drive: the gears' modes),
and with the drives' loops closed (frequency and damping ratio of each
oscillating mode), and the damping ratio each motors-held mode gets
(model/joint_dynamics.py).  No simulation: the station's linear joints.

    python3 studies/plant_modes.py
"""

import numpy as np

from robstiff_drake.diagrams.milling_cell import planned_path
from robstiff_drake.diagrams.scenario import load_scenario, scenario_robot
from robstiff_drake.diagrams.scenario_models import plant_damping_ratios, plant_stiffness
from robstiff_drake.diagrams.station import controller_model, joint_model, servo_parameters
from robstiff_drake.model import joint_dynamics as jd
from robstiff_drake.paths import DIAGRAMS_DIR, library_robots


def modes(sc):
    robot = scenario_robot(sc)
    _, _, q_ref = planned_path(sc, robot, robot.tool_point())
    K = jd.stiffness_matrix(plant_stiffness(sc, robot), sc.plant.coupling_c23_rad_per_Nm)
    jm = joint_model(controller_model(robot), robot, q_ref[0], K, plant_damping_ratios(sc), servo_parameters(sc))
    w, Phi = jd.held_modes(jm.M, jm.K, jm.G)
    zeta_held = np.diag(Phi.T @ jm.D @ Phi) / (2 * w)
    return robot, w / (2 * np.pi), zeta_held, jd.free_modes_hz(jm.M, jm.K, jm.G, jm.motor_inertia_kgm2), \
        *jm.closed_loop_modes()


def main():
    print("| robot | motors held: Hz (damping ratio) | motors free: Hz | drives closed: Hz (damping ratio) |")
    print("|---|---|---|---|")
    for name in library_robots():
        path = DIAGRAMS_DIR / ("block_milling.yaml" if name == "irb6400" else f"block_milling_{name}.yaml")
        robot, held, zh, free, closed, zc = modes(load_scenario(path))
        print(f"| {name} | " + ", ".join(f"{f:.1f} ({z:.0%})" for f, z in zip(held, zh)) + " | "
              + ", ".join(f"{f:.1f}" for f in free) + " | "
              + ", ".join(f"{f:.1f} ({z:.1%})" for f, z in zip(closed, zc)) + " |")


if __name__ == "__main__":
    main()
