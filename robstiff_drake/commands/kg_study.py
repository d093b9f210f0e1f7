"""``robstiff kg-study``: is the CCT term K_g negligible for the IRB6400, as
the paper claims?  For a grid of machining poses (tool point in the workspace
box of the robot file, spindle axis down) and two loads, the relative change
that K_g makes to the predicted tool-point deflection, and how far each linear
model is from the large-deflection equilibrium of the same joint springs."""

import numpy as np

from robstiff_drake.errors import InputError
from robstiff_drake.io import check_outputs, emit_json
from robstiff_drake.model import ik
from robstiff_drake.model import stiffness as st
from robstiff_drake.model.robot import load_robot
from robstiff_drake.progress import progress, wrote

G_M_PER_S2 = 9.81


def _directions():
    """14 unit directions: the six axes and the eight cube diagonals."""
    axes = np.vstack([np.eye(3), -np.eye(3)])
    diag = np.array([[sx, sy, sz] for sx in (1, -1) for sy in (1, -1) for sz in (1, -1)]) / np.sqrt(3)
    return np.vstack([axes, diag])


def study(robot, *, grid=5, force_N=500.0, payload_kg=150.0, show_progress=None):
    """The study's numbers as a dict (see module docstring); a progress bar
    over the cases (``show_progress``: as progress.progress's ``enabled``)."""
    tool = robot.tool_point(where="kg-study")
    with progress(grid**3, show_progress, "kg-study: the workspace's poses (IK)", unit="points") as ik_bar:
        points, qs = ik.workspace_poses(robot, grid, tool, on_point=lambda: ik_bar.update(1))
    if len(qs) == 0:
        raise InputError("kg-study: no pose of the workspace box is reachable")
    cases = {
        f"{force_N:g} N at the tool (14 directions)": [force_N * d for d in _directions()],
        f"{payload_kg:g} kg payload at the tool (gravity)": [np.array([0.0, 0.0, -payload_kg * G_M_PER_S2])],
    }
    results = []
    bar = progress(len(qs) * sum(len(f) for f in cases.values()), show_progress, "kg-study", unit="cases")
    for label, forces in cases.items():
        rel, abs_um, conv_err, cct_err, defl, where = [], [], [], [], [], []
        for p, q in zip(points, qs):
            bar.update(len(forces))
            for f in forces:
                e = st.kg_effect(robot.dh, q, robot.joint_stiffness_Nm_per_rad, np.concatenate([f, np.zeros(3)]), tool)
                rel.append(e["relative_change"])
                abs_um.append(np.linalg.norm(e["dp_cct"] - e["dp_conventional"]) * 1e6)
                conv_err.append(e["conventional_error"])
                cct_err.append(e["cct_error"])
                defl.append(np.linalg.norm(e["dp_conventional"]))
                where.append((p, f))
        i = int(np.argmax(rel))  # the case of the largest relative change
        k = int(np.argmax(abs_um))  # the case of the largest absolute change (not the same case in general)
        results.append({
            "load": label,
            "n_cases": len(rel),
            "max_relative_change": float(np.max(rel)),
            "median_relative_change": float(np.median(rel)),
            "max_abs_change_um": float(abs_um[k]),
            "deflection_at_max_abs_mm": defl[k] * 1e3,
            "relative_change_at_max_abs": float(rel[k]),
            "change_at_max_relative_um": float(abs_um[i]),
            "max_at_tool_point_mm": (where[i][0] * 1e3).tolist(),
            "max_at_force_N": where[i][1].tolist(),
            "deflection_at_max_mm": defl[i] * 1e3,
            "max_deflection_mm": float(np.max(defl)) * 1e3,
            "max_conventional_error_vs_exact": float(np.max(conv_err)),
            "max_cct_error_vs_exact": float(np.max(cct_err)),
        })
    bar.close()
    return {
        "robot": robot.name,
        "n_poses": int(len(qs)),
        "grid_per_axis": grid,
        "workspace_mm": {k: [v * 1e3 for v in getattr(robot.workspace, k[:1] + "_m")] for k in ("x_mm", "y_mm", "z_mm")},
        "tool_point_mm": (tool * 1e3).tolist(),
        "joint_stiffness_Nm_per_rad": robot.joint_stiffness_Nm_per_rad.tolist(),
        "cases": results,
        "warnings": ([f"only {len(qs)} of {grid ** 3} grid points are reachable with the spindle down: the study "
                      "covers part of the box"] if len(qs) < 0.5 * grid ** 3 else []),
    }


def format_table(res):
    lines = [
        f"K_g study, {res['robot']}: {res['n_poses']} machining poses (tool point on a {res['grid_per_axis']}^3 grid "
        f"of x {res['workspace_mm']['x_mm']}, y {res['workspace_mm']['y_mm']}, z {res['workspace_mm']['z_mm']} mm, "
        f"spindle axis down, tool point {res['tool_point_mm']} mm in the flange frame)",
        "",
        "| load | cases | median change by K_g | largest relative change (of the deflection there) "
        "| largest absolute change (on the deflection there) | conventional vs exact (max) | CCT vs exact (max) |",
        "|---|---|---|---|---|---|---|",
    ]
    for c in res["cases"]:
        lines.append(
            f"| {c['load']} | {c['n_cases']} | {100 * c['median_relative_change']:.3f} % | "
            f"{100 * c['max_relative_change']:.3f} % of {c['deflection_at_max_mm']:.3f} mm = "
            f"{c['change_at_max_relative_um']:.1f} um | "
            f"{c['max_abs_change_um']:.1f} um on {c['deflection_at_max_abs_mm']:.3f} mm "
            f"({100 * c['relative_change_at_max_abs']:.3f} %) | "
            f"{100 * c['max_conventional_error_vs_exact']:.3f} % | {100 * c['max_cct_error_vs_exact']:.4f} % |"
        )
    lines.append("")
    lines.append("change by K_g = |dp_CCT - dp_conventional| / |dp_conventional|; 'exact' = large-deflection "
                 "equilibrium K_q dq = J(q + dq)^T F of the same joint springs.")
    return "\n".join(lines)


def run(*, grid=5, force_N=500.0, payload_kg=150.0, json_out=None, robot_yaml=None, show_progress=None):
    if grid < 1:
        raise InputError(f"kg-study: --grid must be >= 1, got {grid}")
    if not (force_N > 0 and payload_kg > 0):
        raise InputError("kg-study: --force-N and --payload-kg must be > 0")
    check_outputs(inputs=[robot_yaml], files={"--json": json_out})
    res = study(load_robot(robot_yaml), grid=grid, force_N=force_N, payload_kg=payload_kg,
                show_progress=show_progress)
    if json_out is not None:
        emit_json(res, json_out)
    if json_out != "-":
        print(format_table(res))
    wrote(json_out, to_stderr=json_out == "-")
    return 0
