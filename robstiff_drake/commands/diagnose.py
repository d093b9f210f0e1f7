"""``robstiff diagnose DATA.csv``: find what the six-spring model gets wrong
in a stiffness campaign, trace it to an effect of the candidate library, add
it, and report the held-out error before and after."""

import numpy as np

from robstiff_drake.commands.identify import campaign_warnings
from robstiff_drake.commands.main import parse_tool
from robstiff_drake.identification.campaign import campaign_tool_m, read_stiffness_campaign
from robstiff_drake.identification.diagnosis import ALPHA, CANDIDATES, MIN_GAIN, diagnose
from robstiff_drake.identification.joint_stiffness import check_angle_units, check_signs, identify
from robstiff_drake.io import RunFolder, Warnings, check_outputs, emit_json, write_atomic
from robstiff_drake.model.robot import load_robot


def to_dict(d, campaign):
    first = {r.name: r for r in d.rounds[0]} if d.rounds else {}
    return {
        "data": campaign.path,
        "n_measurements": len(campaign),
        "rms_before_mm": d.rms_before_mm,
        "rms_after_mm": d.rms_after_mm,
        "selected_effects": d.selected,
        "selection_rule": f"p < {ALPHA:g} (nested F-test) and held-out RMS down by >= {100 * MIN_GAIN:.0f} %",
        "candidates": [{"name": r.name, "status": r.status, "reason": r.reason, "rms_mm": r.rms_mm,
                        "f_stat": r.f_stat, "p_value": r.p_value, "delta_bic": r.delta_bic, "params": r.params}
                       for r in first.values()],
        "rounds": [[{"name": r.name, "status": r.status, "rms_mm": r.rms_mm, "p_value": r.p_value}
                    for r in rnd] for rnd in d.rounds],
        "final_params": d.final_params,
        "joint_stiffness_Nm_per_rad": d.joint_stiffness_Nm_per_rad,
        "identifiable": [bool(v) for v in d.identifiable],
    }


def format_report(d, campaign, markdown=False):
    lines = [f"# Residual diagnosis of {campaign.path}" if markdown else f"diagnosis of {campaign.path}",
             "",
             f"{len(campaign)} measurements; held-out RMS (grouped {'' if campaign.pose is not None else 'by row, '}"
             f"{'by pose, ' if campaign.pose is not None else ''}5-fold) of all displacement components:",
             f"  six-spring model: {d.rms_before_mm:.4f} mm; after the diagnosis: {d.rms_after_mm:.4f} mm",
             "",
             "effects added: " + (", ".join(d.selected) if d.selected else "none (the six-spring model explains "
                                  "the data as far as the test can tell)"),
             ""]
    if markdown:
        lines += ["| candidate (first round) | held-out RMS (mm) | F | p | dBIC | status |", "|---|---|---|---|---|---|"]
    else:
        lines.append("candidate (first round)         held-out RMS      F          p        dBIC    status")
    for r in (d.rounds[0] if d.rounds else []):
        status = r.status if r.status == "ok" else f"{r.status}: {r.reason}"
        if markdown:
            lines.append(f"| {r.name} | {r.rms_mm:.4f} | {r.f_stat:.3g} | {r.p_value:.2g} | {r.delta_bic:.1f} | {status} |")
        else:
            lines.append(f"  {r.name:28s} {r.rms_mm:9.4f} mm  {r.f_stat:9.3g}  {r.p_value:9.2g}  {r.delta_bic:8.1f}   "
                         f"{status}")
    if d.final_params:
        lines += ["", "fitted parameters of the added effects:"]
        for name, params in d.final_params.items():
            lines.append(f"  {name}: " + ", ".join(f"{k} = {v:.4g}" for k, v in params.items()))
    lines += ["", "joint stiffness of the final model (N*m/rad): "
              + ", ".join(f"{k:.4g}" + ("" if ok else " (nominal)")
                          for k, ok in zip(d.joint_stiffness_Nm_per_rad, d.identifiable))]
    return "\n".join(lines)


def residual_views(d, campaign, robot, folder):
    """One PNG per view of the base model's residual (what the trace reads),
    into ``folder`` (an io.RunFolder)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    r = d.residual_before_mm
    F = campaign.force_N
    mag = np.linalg.norm(F, axis=1)
    u = F / np.maximum(mag, 1e-12)[:, None]
    along = np.sum(r * u, axis=1)
    written = []

    def save(fig, name):
        folder.save_figure(name, fig, dpi=90)
        written.append(name)

    fig, ax = plt.subplots(1, 3, figsize=(12, 3.5), constrained_layout=True)
    for k, a in enumerate("xyz"):
        s = np.sign(F[:, k])
        ax[k].plot(s + np.random.default_rng(k).uniform(-0.1, 0.1, len(s)), r[:, k], ".", alpha=0.6)
        ax[k].set_xticks([-1, 0, 1])
        ax[k].set_xlabel(f"sign of f{a}")
        ax[k].set_ylabel(f"residual d{a} (mm)")
    fig.suptitle("residual against load sign (lost motion shows as a step)")
    save(fig, "residual_vs_load_sign.png")

    fig, ax = plt.subplots(figsize=(6, 4), constrained_layout=True)
    ax.plot(mag, along, ".")
    ax.set_xlabel("load magnitude (N)")
    ax.set_ylabel("residual along the load (mm)")
    ax.set_title("residual against load magnitude")
    save(fig, "residual_vs_load_magnitude.png")

    fig, axes = plt.subplots(2, 3, figsize=(12, 6), constrained_layout=True)
    for j, ax in enumerate(axes.ravel()):
        ax.plot(campaign.q_deg[:, j], along, ".")
        ax.set_xlabel(f"q{j + 1} (deg)")
        ax.set_ylabel("residual along the load (mm)")
    fig.suptitle("residual against each joint angle")
    save(fig, "residual_vs_joint_angles.png")

    order = campaign.seq if campaign.seq is not None else np.arange(1, len(campaign) + 1)
    fig, ax = plt.subplots(figsize=(8, 4), constrained_layout=True)
    for k, a in enumerate("xyz"):
        ax.plot(order, r[:, k], ".", label=f"d{a}")
    ax.set_xlabel("measurement order" + ("" if campaign.seq is not None else " (row; no seq column)"))
    ax.set_ylabel("residual (mm)")
    ax.legend()
    ax.set_title("residual against measurement order (drift shows as a trend)")
    save(fig, "residual_vs_order.png")

    y = r.reshape(-1)
    A = d.base_X
    for name, C in d.columns.items():
        # added-variable view: the candidate's columns with the six-spring
        # model's part taken out, fitted to the model's residual
        Xp = C.X - A @ np.linalg.lstsq(A, C.X, rcond=None)[0]
        theta, *_ = np.linalg.lstsq(Xp, y * 1e-3, rcond=None)
        pred = (Xp @ theta) * 1e3
        fig, ax = plt.subplots(figsize=(5, 4), constrained_layout=True)
        ax.plot(pred, y, ".", alpha=0.5)
        lim = max(np.abs(y).max(), 1e-6)
        ax.plot([-lim, lim], [-lim, lim], "k-", lw=0.6)
        ax.set_xlabel(f"{name}: its fit to the residual,\nbeyond the springs (mm)")
        ax.set_ylabel("residual of the six-spring model (mm)")
        tag = " (selected)" if name in d.selected else ""
        ax.set_title(f"{name}{tag}")
        save(fig, f"candidate_{name}.png")
    return written


def run(*, data, tool=None, json_out=None, report=None, plots=None, robot_yaml=None):
    check_outputs(inputs=[data, robot_yaml], files={"--json": json_out, "--report": report},
                  folders={"--plots": plots})
    robot = load_robot(robot_yaml)
    warnings = Warnings()
    campaign = read_stiffness_campaign(data, robot)
    tool_m = campaign_tool_m(campaign, robot, parse_tool(tool), warnings)
    warnings.extend_from(campaign_warnings(campaign))
    check_angle_units(robot, campaign, tool_m)
    warnings.extend_from(check_signs(identify(robot, campaign, tool_m=tool_m), campaign))
    d = diagnose(robot, campaign, tool_m=tool_m)
    if json_out is not None:
        emit_json(dict(to_dict(d, campaign), warnings=list(warnings)), json_out)
    if report is not None:
        write_atomic(report, format_report(d, campaign, markdown=True) + "\n")
    if plots is not None:
        with RunFolder(plots) as folder:
            residual_views(d, campaign, robot, folder)
    if json_out != "-":
        print(format_report(d, campaign))
    return 0


__all__ = ["run", "CANDIDATES"]
