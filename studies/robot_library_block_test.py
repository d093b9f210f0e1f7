"""The paper's block-milling test (Table 3) on every robot of the library,
without and with compensation: the surface error of each robot at a
comparable machining pose (diagrams/block_milling.yaml for the IRB6400,
diagrams/block_milling_<robot>.yaml for the others: the same block, pass,
spindle, sensor and controller at the same share of the wrist's reach and
200 mm below the shoulder).

Prints a Markdown table; docs/your_robot.md quotes
`python3 studies/robot_library_block_test.py`.  Each robot takes two
closed-loop runs (a few seconds each).
"""

import numpy as np

from robstiff_drake.commands.demo import block_scenario
from robstiff_drake.commands.simulate import simulate
from robstiff_drake.model import kinematics as kin
from robstiff_drake.model import stiffness as st
from robstiff_drake.paths import library_robots


def compliance_zx_um_per_N(res):
    """C_zx and C_zz (um/N) of the conventional model at the mid-pass pose."""
    robot, cell = res.cell.robot, res.cell
    ts, x = res.logs["state"]
    q = x[len(ts) // 2, :6]
    C = st.translational_compliance(kin.jacobian(robot.dh, q, cell.tool_m), robot.joint_stiffness_Nm_per_rad)
    return C[2, 0] * 1e6, C[2, 2] * 1e6


def main():
    print("| robot | reference point (mm) | first mode (Hz) | C_zx, C_zz (um/N) | uncompensated mean / PV (mm) "
          "| compensated mean / PV (mm) | compensated max abs (mm) |")
    print("|---|---|---|---|---|---|---|")
    for name in library_robots():
        sc, (off, on) = simulate(scenario=block_scenario(name), compensation="both", robot_yaml=name)
        robot = off.cell.robot
        p = np.round(robot.workspace.reference_tool_point_m * 1e3).astype(int).tolist()
        czx, czz = compliance_zx_um_per_N(off)
        u, c = off.surface_error_mm, on.surface_error_mm
        print(f"| {robot.manufacturer} {robot.model} (`{name}`) | ({p[0]}, {p[1]}, {p[2]}) | "
              f"{off.cell.natural_frequencies_hz[0]:.1f} | {czx:.2f}, {czz:.2f} | {u['mean']:+.3f} / {u['pv']:.3f} | "
              f"{c['mean']:+.4f} / {c['pv']:.3f} | {c['max_abs']:.3f} |")


if __name__ == "__main__":
    main()
