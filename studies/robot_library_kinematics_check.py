"""How closely each library robot's kinematics agree with Drake's plant
(parsed from the URDF generated out of its robot file) and with
implementations that share no code with the package (tests/independent_dh.py:
the paper's Table 1; tests/independent_chains.py: the published URDF
descriptions with the manufacturers' joint conventions, and Craig's
modified DH for the FANUC), over random configurations inside the working
ranges (controller angles) and three tool points.

Prints the largest deviation of the tool point (m), of the rotation, and
of the Jacobian (m/rad or rad/rad; against Drake; against central
differences of the independent FK for the controller-angle Jacobian
J G).  docs/your_robot.md quotes `python3 studies/robot_library_kinematics_check.py`.
"""

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from independent_chains import FANUC_MDH, fanuc_theta_deg, fk_modified_dh, fk_urdf, jacobian_fd  # noqa: E402
from independent_dh import fk_mm as fk_table1  # noqa: E402

from robstiff_drake.model import kinematics as kin  # noqa: E402
from robstiff_drake.model.robot import load_robot  # noqa: E402
from robstiff_drake.paths import library_robots  # noqa: E402
from robstiff_drake.plant import make_robot_plant, tool_position_and_jacobian  # noqa: E402

TOOLS_MM = [(0.0, 0.0, 0.0), (0.0, 0.0, 350.0), (40.0, -25.0, 310.0)]
INDEPENDENT = {"irb6400": ("the paper's Table 1, typed again", fk_table1)}
for _name in ("irb6640", "kr240_r2900", "r2000ic_165f"):
    INDEPENDENT[_name] = ("published URDF, typed again", lambda q, t=(0.0, 0.0, 0.0), n=_name: fk_urdf(n, q, t))


def check(name, n, rng):
    robot = load_robot(name)
    plant, _ = make_robot_plant(robot)
    ctx = plant.CreateDefaultContext()
    label, fk = INDEPENDENT[name]
    worst = dict(drake_p=0.0, drake_J=0.0, ind_p=0.0, ind_R=0.0, ind_J=0.0, mdh_p=0.0)
    G = robot.joint_map.G
    for k, q_deg in enumerate(np.rad2deg(rng.uniform(robot.q_lower_rad, robot.q_upper_rad, size=(n, 6)))):
        q = robot.joint_rad(q_deg)
        for tool_mm in TOOLS_MM:
            tool = np.array(tool_mm) / 1e3
            p, J = tool_position_and_jacobian(plant, ctx, q, tool)
            worst["drake_p"] = max(worst["drake_p"], np.abs(kin.tool_position(robot.dh, q, tool) - p).max())
            worst["drake_J"] = max(worst["drake_J"], np.abs(kin.jacobian(robot.dh, q, tool) - J).max())
            p_ref, R_ref = fk(list(q_deg), tool_mm)
            T = kin.tool_pose(robot.dh, q, tool)
            worst["ind_p"] = max(worst["ind_p"], np.abs(T[:3, 3] - np.array(p_ref) / 1e3).max())
            worst["ind_R"] = max(worst["ind_R"], np.abs(T[:3, :3] - np.array(R_ref)).max())
            if name == "r2000ic_165f":
                p_m, _ = fk_modified_dh(FANUC_MDH, fanuc_theta_deg(list(q_deg)), tool_mm)
                worst["mdh_p"] = max(worst["mdh_p"], np.abs(T[:3, 3] - np.array(p_m) / 1e3).max())
        if k < 10:  # finite differences are slow in plain Python
            J_fd = np.array(jacobian_fd(fk, list(q_deg), TOOLS_MM[2]))
            worst["ind_J"] = max(worst["ind_J"], np.abs(kin.jacobian(robot.dh, q, np.array(TOOLS_MM[2]) / 1e3) @ G
                                                        - J_fd).max())
    return robot, label, worst


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=200, help="configurations per robot (default: %(default)s)")
    args = ap.parse_args()
    rng = np.random.default_rng(20260101)
    print(f"{args.n} random configurations per robot inside its working ranges, tool points {TOOLS_MM} mm")
    print("| robot | convention | vs Drake: tool point (m) | vs Drake: Jacobian | independent implementation "
          "| vs it: tool point (m) | vs it: rotation | J G vs its finite differences |")
    print("|---|---|---|---|---|---|---|---|")
    for name in library_robots():
        robot, label, w = check(name, args.n, rng)
        extra = f"; Craig's modified DH: {w['mdh_p']:.1e} m" if name == "r2000ic_165f" else ""
        print(f"| `{name}` | {robot.convention} | {w['drake_p']:.1e} | {w['drake_J']:.1e} | {label}{extra} | "
              f"{w['ind_p']:.1e} | {w['ind_R']:.1e} | {w['ind_J']:.1e} |")


if __name__ == "__main__":
    main()
