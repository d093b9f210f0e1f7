"""``robstiff plan-poses N``: a D-optimal measurement plan for the joint-
stiffness identification, compared with random poses of the same size."""

import numpy as np

from robstiff_drake.commands.main import parse_tool
from robstiff_drake.identification.campaign import tool_header_line
from robstiff_drake.errors import InputError
from robstiff_drake.io import check_outputs, emit_json, write_atomic
from robstiff_drake.model.robot import load_robot
from robstiff_drake.progress import wrote


def plan_csv(plan, *, robot, force_N, noise_mm, tool_m):
    from robstiff_drake.identification.synth import command_line

    lines = [
        "# Measurement plan made by robstiff-drake (robstiff plan-poses; D-optimal over candidate poses x 26 load",
        f"# directions). Made with: {command_line()}",
        f"# Robot: {robot.name} ({robot.source}); q1..q6 in its controller's convention (deg).",
        f"# Tool point {np.round(np.asarray(tool_m) * 1e3, 3).tolist()} mm in the flange frame; loads {force_N:g} N.",
        "# The tool point the displacements must be measured at (identify and diagnose read this line):",
        tool_header_line(tool_m),
        "# Measure dx,dy,dz (mm, base frame, loaded minus unloaded) for each row, add the three columns, and",
        "# run `robstiff identify` on the file.",
        f"# Predicted relative standard error of each joint's stiffness at {noise_mm:g} mm CMM noise: "
        + ", ".join("n/a" if np.isnan(v) else f"{100 * v:.2f} %" for v in plan.rel_std_planned),
        "pose,seq,q1,q2,q3,q4,q5,q6,fx,fy,fz",
    ]
    ids = {p: i + 1 for i, p in enumerate(dict.fromkeys(plan.pose_index.tolist()))}
    order = np.argsort([ids[p] for p in plan.pose_index], kind="stable")
    for seq, i in enumerate(order, start=1):
        q = robot.controller_deg(plan.q_rad[i])
        f = plan.force_N[i] + 0.0
        lines.append(f"P{ids[plan.pose_index[i]]:03d},{seq}," + ",".join(f"{v:.4f}" for v in q) + ","
                     + ",".join(f"{v:.2f}" for v in f))
    return "\n".join(lines) + "\n"


def run(*, n, candidates=120, force_N=300.0, noise_mm=0.01, tool=None, seed=0, out=None, json_out=None,
        robot_yaml=None):
    if n < 6:
        raise InputError(f"plan-poses: N must be at least 6 (one per joint compliance), got {n}")
    if candidates < 2:
        raise InputError(f"plan-poses: --candidates must be at least 2, got {candidates}")
    if not (force_N > 0 and noise_mm > 0):
        raise InputError("plan-poses: --force-N and --noise-mm must be > 0")
    check_outputs(inputs=[robot_yaml], files={"--out": out, "--json": json_out})
    robot = load_robot(robot_yaml)
    tool_m = robot.tool_point(parse_tool(tool), where="plan-poses")
    from robstiff_drake.identification.pose_planning import plan_poses  # scipy: after the checks

    plan = plan_poses(robot, n, n_candidate_poses=candidates, force_N=force_N, noise_mm=noise_mm, tool_m=tool_m,
                      seed=seed)
    if out is not None:
        write_atomic(out, plan_csv(plan, robot=robot, force_N=force_N, noise_mm=noise_mm, tool_m=tool_m))
    res = {
        "n": n, "n_poses": int(len(set(plan.pose_index.tolist()))), "force_N": force_N, "noise_mm": noise_mm,
        "tool_mm": tool_m * 1e3, "identifiable": plan.identifiable.tolist(),
        "rel_std_planned": [None if np.isnan(v) else float(v) for v in plan.rel_std_planned],
        "rel_std_random_median": [None if np.isnan(v) else float(v) for v in plan.rel_std_random],
        "d_efficiency_gain": float(np.exp((plan.logdet_planned - plan.logdet_random) / plan.identifiable.sum())),
        "warnings": [f"joint {j + 1} is not identifiable with this tool point (the loads give it no torque); "
                     "use a tool point off the flange axis or apply moments" for j in range(6)
                     if not plan.identifiable[j]],
    }
    if json_out is not None:
        emit_json(res, json_out)
    if json_out != "-":
        print(f"plan: {n} measurements at {res['n_poses']} poses, {force_N:g} N loads, tool "
              f"{np.round(tool_m * 1e3, 1).tolist()} mm; predicted standard error at {noise_mm:g} mm noise")
        print("joint   planned      random (median of 30)   improvement")
        for j in range(6):
            if not plan.identifiable[j]:
                print(f"  {j + 1}     not identifiable with this tool point (the loads give it no torque)")
                continue
            a, b = plan.rel_std_planned[j], plan.rel_std_random[j]
            print(f"  {j + 1}     {100 * a:7.3f} %    {100 * b:7.3f} %               {b / a:5.2f}x")
        print(f"D-efficiency gain over random: {res['d_efficiency_gain']:.2f}x")
    wrote(out, f"the plan ({n} measurements at {res['n_poses']} poses; measure dx, dy, dz for each row)",
          to_stderr=json_out == "-")
    wrote(json_out, to_stderr=json_out == "-")
    return 0
