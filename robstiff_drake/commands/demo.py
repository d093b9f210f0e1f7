"""``robstiff demo``: the project's main job.

Until the closed-loop milling simulation exists, the demo shows the stiffness
model at the seed's machining set-up: the configuration that puts the spindle
at the reference tool point (IK), the stiffness table there, the check of the
seed's claim that K_g is negligible at that pose, and the stiffness map.
Outputs go to ``out`` (default ./robstiff-out/)."""

from pathlib import Path

import numpy as np

from robstiff_drake.commands import stiffness, stiffness_map
from robstiff_drake.io import emit_json, save_figure_atomic
from robstiff_drake.model import ik
from robstiff_drake.model import stiffness as st
from robstiff_drake.model.robot import load_robot


def run(*, out="robstiff-out"):
    out = Path(out)
    robot = load_robot()
    tool = robot.payload.tool_point_m
    p_ref = robot.workspace.reference_tool_point_m
    q = ik.solve_ik(robot.dh, ik.tool_down_pose(p_ref), tool,
                    q_lower_rad=robot.q_lower_rad, q_upper_rad=robot.q_upper_rad)
    q_deg = np.rad2deg(q)
    print(f"== reference machining pose: tool point {np.round(p_ref * 1e3, 1).tolist()} mm, spindle axis down ==")
    rep = stiffness.pose_report(robot, q_deg, tool)
    print(stiffness.format_report(rep, robot))

    print("\n== does the CCT term K_g matter here?  500 N at the tool, six axis directions ==")
    print("   force (N)                 conventional dp (mm)          change by K_g")
    kg = []
    for f in np.vstack([np.eye(3), -np.eye(3)]) * 500.0 + 0.0:  # + 0.0: no "-0" in the table
        e = st.kg_effect(robot.dh, q, robot.joint_stiffness_Nm_per_rad, np.concatenate([f, np.zeros(3)]), tool)
        kg.append({"force_N": f.tolist(), "dp_conventional_mm": (e["dp_conventional"] * 1e3).tolist(),
                   "relative_change": e["relative_change"]})
        d = e["dp_conventional"] * 1e3 + 0.0
        print(f"   ({f[0]:+5.0f}, {f[1]:+5.0f}, {f[2]:+5.0f})   ({d[0]:+.3f}, {d[1]:+.3f}, {d[2]:+.3f})"
              f"        {100 * e['relative_change']:.3f} %")
    print("   (the workspace-wide figures: `robstiff kg-study`)")

    fig, _ = stiffness_map.make_map(robot, tool_m=tool)
    map_path = out / "stiffness_map.png"
    save_figure_atomic(fig, map_path, dpi=110)
    emit_json({"reference_pose": rep, "kg_check": kg}, out / "demo.json")
    print(f"\nwrote {map_path} and {out / 'demo.json'}")
    return 0
