"""``robstiff plan-poses N``: a D-optimal measurement plan for the joint-
stiffness identification, compared with random poses of the same size."""

import numpy as np

from robstiff_drake.commands.options import parse_tool
from robstiff_drake.identification.stiffness.campaign import tool_header_line
from robstiff_drake.errors import InputError
from robstiff_drake.io import check_outputs, emit_json, staged_outputs, write_atomic
from robstiff_drake.model.robot import load_robot
from robstiff_drake.progress import wrote


def plan_csv(plan, *, robot, force_N, noise_mm, tool_m):
    from robstiff_drake.identification.stiffness.synth import command_line

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


def separation_csv(plan, *, robot, force_N, noise_mm, tool_m):
    from robstiff_drake.identification.stiffness.synth import command_line

    a, b = plan.effects
    lines = [
        f"# Measurement plan made by robstiff-drake (robstiff plan-poses --separate {a},{b}; greedy over the",
        f"# candidate poses x 26 load directions, smallest interval widths). Made with: {command_line()}",
        f"# Robot: {robot.name} ({robot.source}); q1..q6 in its controller's convention (deg).",
        f"# Tool point {np.round(np.asarray(tool_m) * 1e3, 3).tolist()} mm in the flange frame; loads {force_N:g} N.",
        tool_header_line(tool_m),
        f"# Predicted 95 % half-widths at {noise_mm:g} mm noise per component: " + "; ".join(
            f"{e} {name} +-{w:.3g} {unit}" for (e, name, unit), w in zip(plan.params, plan.half_width_after)),
        f"# Correlation of the estimates of {a} and {b} with these rows: {plan.correlation_after:+.2f}",
        "pose,seq,q1,q2,q3,q4,q5,q6,fx,fy,fz",
    ]
    ids = {p: i + 1 for i, p in enumerate(dict.fromkeys(plan.pose_index.tolist()))}
    order = np.argsort([ids[p] for p in plan.pose_index], kind="stable")
    for seq, i in enumerate(order, start=1):
        q = robot.controller_deg(plan.q_rad[i])
        lines.append(f"S{ids[plan.pose_index[i]]:03d},{seq}," + ",".join(f"{v:.4f}" for v in q) + ","
                     + ",".join(f"{v + 0.0:.2f}" for v in plan.force_N[i]))
    return "\n".join(lines) + "\n"


def _run_separate(*, n, separate, campaign_csv, candidates, force_N, noise_mm, tool, seed, out, json_out, robot):
    from robstiff_drake.identification.stiffness.campaign import read_stiffness_campaign
    from robstiff_drake.identification.stiffness.joint_stiffness import identify
    from robstiff_drake.identification.diagnosis.separation import parse_pair, plan_separation

    effects = parse_pair(separate)
    campaign, compliance = None, None
    tool_m = parse_tool(tool)
    if campaign_csv is not None:
        campaign = read_stiffness_campaign(campaign_csv, robot)
        if tool_m is None and campaign.tool_mm is not None:
            tool_m = np.asarray(campaign.tool_mm) / 1e3
    tool_m = robot.tool_point(tool_m, where="plan-poses")
    if campaign is not None:
        fit = identify(robot, campaign, tool_m=tool_m)
        c = fit.compliance_rad_per_Nm
        compliance = np.where(fit.identifiable & (c > 0), c, 1.0 / robot.joint_stiffness_Nm_per_rad)
    plan = plan_separation(robot, effects, n, campaign=campaign, compliance=compliance, n_candidate_poses=candidates,
                           force_N=force_N, noise_mm=noise_mm, tool_m=tool_m, seed=seed)
    with staged_outputs():  # the plan and the JSON, both or neither
        if out is not None:
            write_atomic(out, separation_csv(plan, robot=robot, force_N=force_N, noise_mm=noise_mm, tool_m=tool_m))
        rows = [{"effect": e, "parameter": name, "unit": unit,
                 "half_width_95_before": None if plan.half_width_before is None else float(plan.half_width_before[i]),
                 "half_width_95_after": float(plan.half_width_after[i])} for i, (e, name, unit) in enumerate(plan.params)]
        res = {"n": n, "separate": list(effects), "campaign": campaign_csv, "force_N": force_N, "noise_mm": noise_mm,
               "tool_mm": tool_m * 1e3, "parameters": rows, "correlation_before": plan.correlation_before,
               "correlation_after": plan.correlation_after,
               "rows": [{"q_deg": robot.controller_deg(q), "force_N": f} for q, f in zip(plan.q_rad, plan.force_N)],
               "warnings": []}
        if json_out is not None:
            emit_json(res, json_out)
    if json_out != "-":
        a, b = effects
        src = f"{campaign_csv} plus " if campaign_csv else ""
        print(f"plan to separate {a} and {b}: {src}{n} measurements at {len(set(plan.pose_index.tolist()))} poses, "
              f"{force_N:g} N loads; predicted 95 % half-width at {noise_mm:g} mm noise per component")
        print("effect                         parameter         " + ("campaign alone   " if campaign else "")
              + "with the plan")
        for r in rows:
            before = "" if r["half_width_95_before"] is None else f"{r['half_width_95_before']:10.3g} {r['unit']:5s}  "
            print(f"  {r['effect']:28s} {r['parameter']:16s} {before}{r['half_width_95_after']:10.3g} {r['unit']}")
        corr = ("" if plan.correlation_before is None else f"{plan.correlation_before:+.2f} with the campaign alone, ")
        print(f"correlation of the estimates of {a} and {b}: {corr}{plan.correlation_after:+.2f} with the plan"
              + (f"; plan written to {out}" if out else ""))
        print("rows (controller deg; load N, base frame):")
        for q, f in zip(plan.q_rad, plan.force_N):
            print("  q = [" + ", ".join(f"{v:8.2f}" for v in robot.controller_deg(q)) + "]  F = ["
                  + ", ".join(f"{v + 0.0:7.1f}" for v in f) + "]")
    return 0


def run(*, n, candidates=120, force_N=300.0, noise_mm=0.01, tool=None, seed=0, out=None, json_out=None,
        robot_yaml=None, separate=None, campaign=None):
    if n < 6:
        raise InputError(f"plan-poses: N must be at least 6 (one per joint compliance), got {n}")
    if candidates < 2:
        raise InputError(f"plan-poses: --candidates must be at least 2, got {candidates}")
    if not (force_N > 0 and noise_mm > 0):
        raise InputError("plan-poses: --force-N and --noise-mm must be > 0")
    check_outputs(inputs=[robot_yaml, campaign], files={"--out": out, "--json": json_out})
    from robstiff_drake.commands.synth import check_not_measurements

    check_not_measurements(out)  # a plan with its measurements added, or a measured campaign: not written over
    robot = load_robot(robot_yaml)
    if campaign is not None and separate is None:
        raise InputError("plan-poses: --campaign is used with --separate (the plan adds to that campaign)")
    if separate is not None:
        return _run_separate(n=n, separate=separate, campaign_csv=campaign, candidates=candidates, force_N=force_N,
                             noise_mm=noise_mm, tool=tool, seed=seed, out=out, json_out=json_out, robot=robot)
    tool_m = robot.tool_point(parse_tool(tool), where="plan-poses")
    from robstiff_drake.identification.stiffness.pose_planning import plan_poses  # scipy: after the checks

    plan = plan_poses(robot, n, n_candidate_poses=candidates, force_N=force_N, noise_mm=noise_mm, tool_m=tool_m,
                      seed=seed)
    with staged_outputs():  # the plan and the JSON, both or neither
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
