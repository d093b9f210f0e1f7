"""``robstiff identify DATA.csv``: joint stiffness by least squares (Eq. 8)."""

import numpy as np

from robstiff_drake.commands.options import parse_tool
from robstiff_drake.io import Warnings, check_outputs, emit_json, save_figure_atomic, staged_outputs
from robstiff_drake.model.robot import load_robot
from robstiff_drake.progress import wrote


def fit_to_dict(fit, campaign, robot, tool_m, no_intervals=(), lack=None):
    """The result as JSON; ``no_intervals``: why the campaign's design cannot
    support its intervals (interval_support), which are then null; ``lack``:
    the test of the fit against the noise floor (stiffness/lack_of_fit.py)."""
    withheld = bool(no_intervals)
    return {
        "data": campaign.path,
        "robot": robot.name,
        "tool_mm": (np.asarray(tool_m) * 1e3).tolist(),
        "joint_stiffness_Nm_per_rad": fit.stiffness_Nm_per_rad,
        "joint_stiffness_std_Nm_per_rad": [None if withheld or np.isnan(v) else float(v)
                                           for v in fit.stiffness_std_Nm_per_rad],
        # null: not identifiable, unbounded (the compliance's interval reaches zero), or not available
        "joint_stiffness_ci95_Nm_per_rad": [[float(v) if np.isfinite(v) and not withheld else None for v in row]
                                            for row in fit.stiffness_ci95_Nm_per_rad],
        "intervals_available": not withheld,
        "intervals_not_available_because": list(no_intervals),
        "joint_stiffness_nominal_Nm_per_rad": robot.joint_stiffness_Nm_per_rad,
        "joint_compliance_rad_per_Nm": fit.compliance_rad_per_Nm,
        "identifiable": [bool(v) for v in fit.identifiable],
        "not_identifiable_reason": fit.reasons,
        "non_physical_joints": fit.non_physical,
        "rms_residual_mm": fit.rms_residual_mm,
        "sigma_mm": fit.sigma_mm,
        "lack_of_fit": lack,
        "n_measurements": fit.n_measurements,
        "dof": fit.dof,
        "condition_number": fit.condition_number,
        "robust": fit.robust,
        "outlier_lines": [int(campaign.lines[i]) for i in fit.outlier_rows],
        "residuals": [{"line": int(ln), "dx_mm": float(r[0]), "dy_mm": float(r[1]), "dz_mm": float(r[2])}
                      for ln, r in zip(campaign.lines, fit.residuals_mm)],
    }


def format_fit(fit, campaign, robot, no_intervals=(), lack=None):
    lines = [
        f"identified from {campaign.path}: {fit.n_measurements} measurements, "
        f"{'robust (Huber)' if fit.robust else 'least squares'}, "
        f"{'translations and rotations' if fit.residuals_rot_mrad is not None else 'translations only'}",
        "",
        "joint   stiffness N*m/rad   std error     95 % interval                 nominal    note",
    ]
    for j in range(6):
        k = fit.stiffness_Nm_per_rad[j]
        nom = robot.joint_stiffness_Nm_per_rad[j]
        if fit.identifiable[j] and no_intervals:
            lines.append(f"  {j + 1}     {k:12.4g}       {'n/a':>10}   {'not available':^26}   {nom:10.4g}    ")
        elif fit.identifiable[j]:
            lo, hi = fit.stiffness_ci95_Nm_per_rad[j]
            note = "NON-PHYSICAL (negative compliance)" if (j + 1) in fit.non_physical else ""
            lines.append(f"  {j + 1}     {k:12.4g}       {fit.stiffness_std_Nm_per_rad[j]:10.3g}   "
                         f"[{lo:10.4g}, {hi:10.4g}]   {nom:10.4g}    {note}")
        else:
            lines.append(f"  {j + 1}     {k:12.4g}       {'-':>10}   {'-':^26}   {nom:10.4g}    "
                         f"not identifiable, kept at nominal: {fit.reasons[j]}")
    lines += [
        "",
        f"residual RMS {fit.rms_residual_mm:.4f} mm (all components), noise estimate sigma {fit.sigma_mm:.4f} mm, "
        f"{fit.dof} degrees of freedom, condition number {fit.condition_number:.3g} (nominal-scaled columns)",
    ]
    if lack is not None and lack["residual_to_noise_ratio"] is not None:
        lines.append(f"noise floor {lack['noise_floor_mm']:.4f} mm, {lack['noise_floor_source']}: the fit's sigma is "
                     f"{lack['residual_to_noise_ratio']:.2f}x it"
                     + ("" if lack["explained_by_springs"] else
                        " (NOT explained by joint springs alone: the intervals assume the model is right)"))
    elif lack is not None:
        lines.append("no noise floor known (--noise-mm, a '# noise_mm:' line in the file, or replicate rows): the "
                     "residual is not tested against the instrument's noise")
    if no_intervals:
        lines.append("std errors and 95 % intervals not available: " + "; ".join(no_intervals))
    if fit.outlier_rows:
        lines.append("outliers (|residual| > 4 robust sigma) at lines: "
                     + ", ".join(str(campaign.lines[i]) for i in fit.outlier_rows))
    return "\n".join(line.rstrip() for line in lines)


# identify fits the six-spring law only: the gears' play is not in its model, so its --json has no lost_motion_* keys
# (those compensate --model and a scenario's model: block read: cell/play_note.py); diagnose fits it on the same file
PLAY_NOT_IDENTIFIED = ("play (lost motion) not identified: this fit is the six-spring law (Eq. 8) and its JSON has "
                       "no lost_motion_* keys; `robstiff diagnose DATA.csv` estimates it (effect lost_motion, b1-b3)")


def plot_fit(fit, campaign, robot, no_intervals=()):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(15, 4.5), constrained_layout=True)
    ax = axes[0]
    for i, (name, color) in enumerate(zip("xyz", ("C0", "C1", "C2"))):
        ax.plot(fit.predicted_mm[:, i], campaign.disp_mm[:, i], ".", color=color, label=f"d{name}")
    lim = np.max(np.abs(campaign.disp_mm)) * 1.05
    ax.plot([-lim, lim], [-lim, lim], "k-", lw=0.8)
    ax.set_xlabel("predicted by the identified model (mm)")
    ax.set_ylabel("measured (mm)")
    ax.set_title("measured against predicted")
    ax.legend()
    ax = axes[1]
    for i, name in enumerate("xyz"):
        ax.plot(campaign.lines, fit.residuals_mm[:, i], ".", label=f"d{name}")
    ax.axhline(0, color="k", lw=0.8)
    ax.set_xlabel("file line")
    ax.set_ylabel("residual (mm)")
    ax.set_title(f"residuals, RMS {fit.rms_residual_mm:.4f} mm")
    ax.legend()
    ax = axes[2]
    j = np.arange(1, 7)
    rel = fit.stiffness_Nm_per_rad / robot.joint_stiffness_Nm_per_rad
    ci = fit.stiffness_ci95_Nm_per_rad / robot.joint_stiffness_Nm_per_rad[:, None]
    ok = fit.identifiable
    if no_intervals:
        ax.plot(j[ok], rel[ok], "o", label="identified (intervals not available)")
    else:
        ax.errorbar(j[ok], rel[ok], yerr=np.abs(np.vstack([rel[ok] - ci[ok, 0], np.minimum(ci[ok, 1], 10) - rel[ok]])),
                    fmt="o", capsize=4, label="identified, 95 % interval")
    ax.plot(j[~ok], rel[~ok], "x", color="grey", ms=10, label="not identifiable (nominal)")
    ax.axhline(1.0, color="k", lw=0.8)
    ax.set_xticks(j)
    ax.set_xlabel("joint")
    ax.set_ylabel("stiffness / nominal")
    ax.set_title("joint stiffness")
    ax.legend()
    return fig


def fit_warnings(fit, robot, campaign):
    """What the six-spring fit of the campaign as written says of the file
    (identify's and diagnose's): check_signs' refusal or warnings, and every
    identified joint off the robot file's stiffness by a unit's factor
    (identification/stiffness/unit_scale.py); one line each."""
    from robstiff_drake.identification.stiffness.joint_stiffness import check_signs
    from robstiff_drake.identification.stiffness.unit_scale import unit_scale_note

    note = unit_scale_note(fit.stiffness_Nm_per_rad, robot.joint_stiffness_Nm_per_rad, fit.identifiable,
                           campaign.path, robot.source or robot.name)
    return list(check_signs(fit, campaign)) + ([note] if note else [])


def campaign_warnings(campaign):
    """Warnings about a campaign file that was read (copies set aside)."""
    if not campaign.copies:
        return []
    shown = ", ".join(f"{a} (= line {b})" for a, b in campaign.copies[:6])
    more = f" and {len(campaign.copies) - 6} more" if len(campaign.copies) > 6 else ""
    return [f"{campaign.path}: {len(campaign.copies)} row(s) repeat an earlier row in every measured value and are "
            f"counted once, as copies, not as new measurements: lines {shown}{more} (real repeats differ by their "
            "noise; add a seq column if these are repeats at a coarse resolution)"]


def _run_tracker(data, robot, tool_m, json_out, warnings):
    """identify on an absolute-position campaign: the joint stiffness the
    sag under the arm's weight gives, with the kinematic errors and the
    registration fitted with it (the tracker diagnosis's model)."""
    from robstiff_drake.commands.diagnose_tracker import format_report
    from robstiff_drake.identification.tracker.campaign import read_tracker_campaign
    from robstiff_drake.identification.tracker.diagnosis import diagnose_tracker

    d = diagnose_tracker(robot, read_tracker_campaign(data, robot), tool_m=tool_m, warnings=warnings,
                         residual_map=False)
    rep = d.report
    comp = next((t for t in rep["effects"] if t["name"] == "joint_compliance"), None)
    k = np.array(rep["joint_stiffness_Nm_per_rad"], dtype=float)
    ident = np.zeros(6, dtype=bool)
    ci = [[None, None] for _ in range(6)]
    if comp is not None:
        c_nom = 1.0 / robot.joint_stiffness_Nm_per_rad
        for (name, (lo, hi)) in comp["ci95"].items():
            j = int(name.split()[0][1:]) - 1
            ident[j] = True
            ci[j] = [float(1 / (hi * c_nom[j])) if hi > 0 else None, float(1 / (lo * c_nom[j])) if lo > 0 else None]
    if not ident.any():
        warnings.add("the campaign identifies no joint's stiffness: the sag under the arm's weight did not earn its "
                     "place (see robstiff diagnose)")
    res = {"data": data, "robot": robot.name, "kind": "absolute", "joint_stiffness_Nm_per_rad": k,
           "joint_stiffness_ci95_Nm_per_rad": ci, "identifiable": ident.tolist(),
           "joint_stiffness_nominal_Nm_per_rad": robot.joint_stiffness_Nm_per_rad, "tracker": rep,
           "warnings": list(warnings)}
    if json_out is not None:
        emit_json(res, json_out)
    if json_out != "-":
        print(f"identified from {data} (absolute positions): the joints' sag under the arm's weight")
        for j in range(6):
            note = (f"[{ci[j][0]:.4g}, {ci[j][1] if ci[j][1] is not None else float('inf'):.4g}]"
                    if ident[j] else "not identified (nominal)")
            print(f"  joint {j + 1}: {k[j]:12.4g} N*m/rad   {note}")
        print()
        print(format_report(rep))
        print(PLAY_NOT_IDENTIFIED)
    return 0


def run(*, data, tool=None, json_out=None, plot=None, robust=False, robot_yaml=None, noise_mm=None):
    from robstiff_drake.identification.tracker.campaign import is_tracker_file

    check_outputs(inputs=[data, robot_yaml], files={"--json": json_out, "--plot": plot})
    robot = load_robot(robot_yaml)
    tool_arg = parse_tool(tool)
    # scipy comes with these: after the checks of the arguments
    from robstiff_drake.identification.stiffness.campaign import campaign_tool_m, read_stiffness_campaign
    from robstiff_drake.identification.stiffness.joint_stiffness import check_angle_units, identify
    from robstiff_drake.identification.stiffness.interval_support import interval_support
    from robstiff_drake.identification.stiffness.lack_of_fit import lack_of_fit, lack_of_fit_warning, noise_floor

    warnings = Warnings()
    if is_tracker_file(data):
        if plot is not None or robust or noise_mm is not None:
            from robstiff_drake.errors import InputError

            raise InputError("--plot, --robust and --noise-mm are for stiffness campaigns; an absolute-position "
                             "campaign's views and noise floor are `robstiff diagnose DATA.csv --plots DIR --noise-mm "
                             "SIGMA`")
        return _run_tracker(data, robot, tool_arg, json_out, warnings)
    campaign = read_stiffness_campaign(data, robot)
    floor_mm, floor_source = noise_floor(campaign, noise_mm)  # (a malformed '# noise_mm:' line: before the fit)
    tool_m = campaign_tool_m(campaign, robot, tool_arg, warnings)
    warnings.extend_from(campaign_warnings(campaign))
    check_angle_units(robot, campaign, tool_m)
    fit = identify(robot, campaign, tool_m=tool_m, robust=robust)
    warnings.extend_from(fit.input_warnings)
    warnings.extend_from(fit_warnings(fit, robot, campaign))
    if fit.condition_number > 1e4:
        warnings.add(f"condition number {fit.condition_number:.3g}: the poses and loads barely separate the joints; "
                     "plan the campaign with `robstiff plan-poses`")
    lack = lack_of_fit(fit, floor_mm, floor_source)
    warnings.extend_from([lack_of_fit_warning(lack, campaign.path)] if lack["explained_by_springs"] is False else [])
    no_intervals = interval_support(campaign, tool_m, int(np.sum(fit.identifiable)))
    if no_intervals:
        warnings.add(f"{campaign.path}: 95 % intervals not available, the campaign's design cannot support them: "
                     + "; ".join(no_intervals))
    with staged_outputs():  # both files or neither (a full disk at the plot leaves no JSON behind)
        if json_out is not None:
            emit_json(dict(fit_to_dict(fit, campaign, robot, tool_m, no_intervals, lack), warnings=list(warnings)),
                      json_out)
        if plot is not None:
            save_figure_atomic(plot_fit(fit, campaign, robot, no_intervals), plot, dpi=100)
    if json_out != "-":
        print(format_fit(fit, campaign, robot, no_intervals, lack))
        print(PLAY_NOT_IDENTIFIED)
    wrote(json_out, "the identified model (compensate --model, a scenario's model.identified_json)",
          to_stderr=json_out == "-")
    wrote(plot, to_stderr=json_out == "-")
    return 0
