"""``robstiff diagnose DATA.csv``: find what the six-spring model gets wrong
in a stiffness campaign, trace it to a physical effect (the named library or
the open dictionary), add it, report the held-out error before and after and
whether the result explains the data against the noise floor."""

import numpy as np

from robstiff_drake.commands.identify import campaign_warnings, fit_warnings
from robstiff_drake.commands.options import parse_tool
from robstiff_drake.errors import InputError
from robstiff_drake.identification.stiffness.campaign import campaign_tool_m, read_stiffness_campaign
from robstiff_drake.identification.diagnosis.confounding import CONFOUNDED_MIN
from robstiff_drake.identification.diagnosis.campaign_diagnosis import CANDIDATES, DICTIONARY, diagnose
from robstiff_drake.identification.diagnosis.findings import describe_alternatives
from robstiff_drake.identification.diagnosis.fold_spread import describe as describe_spread
from robstiff_drake.identification.stiffness.joint_stiffness import check_angle_units, identify
from robstiff_drake.identification.stiffness.lack_of_fit import stated_noise
from robstiff_drake.identification.diagnosis.selection import ALPHA_ROUND, MIN_GAIN
from robstiff_drake.io import RunFolder, Warnings, check_outputs, emit_json, staged_outputs, write_atomic
from robstiff_drake.model.robot import load_robot
from robstiff_drake.progress import wrote

MAX_NOISE_MM = 10.0
CLUSTERED_P_NOTE = ("(clustered p: '-' when the held-out gain is too small for the candidate to qualify, or the poses "
                    "are too few for the model's parameters)")


def _finite(obj):
    """NaN (a candidate that was not tested) -> None, before emit_json sees it."""
    if isinstance(obj, float) and not np.isfinite(obj):
        return None
    if isinstance(obj, dict):
        return {k: _finite(v) for k, v in obj.items()}
    if isinstance(obj, list):
        return [_finite(v) for v in obj]
    return obj


def to_dict(d, campaign):
    first = d.rounds[0] if d.rounds else []
    f, lof = d.floor, d.lack_of_fit
    return _finite({
        "data": campaign.path,
        "n_measurements": len(campaign),
        "n_used": int(len(d.rows_used)),
        "rms_before_mm": d.rms_before_mm,
        "rms_after_mm": d.rms_after_mm,
        "noise_floor_mm": f.sigma_mm,
        "noise_source": f.source,
        "noise_floor_source": f.source_text,
        "noise_floor_stated_mm": f.stated_mm,
        "noise_floor_replicates_mm": f.replicate_mm,
        "replicate_dof": f.replicate_dof,
        "explains_data": d.explains_data,
        "verdict": d.verdict,
        "lack_of_fit": None if lof is None else {"p_value": lof.p_value, "statistic": lof.statistic, "dof": lof.dof,
                                                 "test": lof.test},
        "unexplained_mm": d.unexplained_mm,
        "outliers": d.outliers,
        "joint_stiffness_with_outliers_Nm_per_rad": d.stiffness_with_outliers_Nm_per_rad,
        "selected_effects": d.selected,
        "discovered": [{k: t[k] for k in ("name", "description", "params", "ci95", "rms_gain_mm", "plausible",
                                          "plausibility", "prior_size", "beyond_typical", "finding") if k in t}
                       for t in d.discovered],
        "terms": d.terms,
        "dropped": d.dropped,
        "residual_structure": d.residual_structure,
        "n_hypotheses": d.n_hypotheses,
        "thresholds": d.thresholds,
        "selection_rule": ("pose-clustered test (CR2 sandwich, Bell-McCaffrey t per contrast, Bonferroni over "
                           "its parameters) "
                           f"p < {ALPHA_ROUND:g} / (candidates tried in the round) and "
                           f"held-out RMS down by >= {100 * MIN_GAIN['library']:.0f} % (named) or "
                           f"{100 * MIN_GAIN['dictionary']:.0f} % (dictionary)"),
        "candidates": [{"name": r.name, "status": r.status, "reason": r.reason, "rms_mm": r.rms_mm,
                        "f_stat": r.f_stat, "p_value": r.p_value, "delta_bic": r.delta_bic,
                        "p_grouped": r.p_grouped, "params": r.params} for r in first if r.source == "library"],
        "rounds": [[{"name": r.name, "source": r.source, "status": r.status, "rms_mm": r.rms_mm,
                     "p_grouped": r.p_grouped} for r in rnd] for rnd in d.rounds],
        "final_params": d.final_params,
        "joint_stiffness_Nm_per_rad": d.joint_stiffness_Nm_per_rad,
        "identifiable": [bool(v) for v in d.identifiable],
        "non_physical_joints": d.non_physical,
        "leads": d.leads,
        "confounded": d.confounded,
        "alternatives": d.alternatives,
        "misreadings": d.misreadings,
        "floor_check": d.floor_check,
        "fold_spread": d.fold_spread,
        "warnings": list(d.warnings),
    })


def _g(v, fmt):
    return "-" if v is None or not np.isfinite(v) else format(v, fmt)


def _fmt_params(params):
    return ", ".join(f"{k} = {v:.4g}" for k, v in params.items())


def format_report(d, campaign, markdown=False):
    f = d.floor
    h = "## " if markdown else ""
    n_out = len(d.outliers)
    lines = [f"# Residual diagnosis of {campaign.path}" if markdown else f"diagnosis of {campaign.path}", "",
             f"{len(campaign)} measurements" + (f" ({n_out} gross outlier row(s) left out, below)" if n_out else "")
             + "; held-out RMS (5-fold, grouped by pose) of all displacement components:",
             f"  six-spring model: {d.rms_before_mm:.4f} mm; final model: {d.rms_after_mm:.4f} mm"]
    if d.fold_spread is not None:
        lines.append(f"  {describe_spread(d.fold_spread)}")
    floor = ("none stated or measured" if f.sigma_mm is None else f"{f.sigma_mm:.4f} mm, {f.source_text}")
    if f.replicate_mm is not None and f.source != "replicates":
        floor += f"; replicate rows scatter by {f.replicate_mm:.4f} mm ({f.replicate_sets} sets, {f.replicate_dof} dof)"
    lines += [f"noise floor: {floor}", "", f"{h}verdict" if markdown else "verdict:", d.verdict, ""]
    if d.misreadings:
        lines.append("the file read another way (setup findings; check these first):")
        lines += [f"  {r['name']}: {r['text']}" for r in d.misreadings] + [""]
    lines.append("effects added from the named library: " + (", ".join(d.selected) if d.selected else "none"))
    for t in d.terms:
        if t["source"] == "library":
            lines.append(f"  {t['name']}: {t['description']}; " + (
                f"typical size: {t['plausibility']}" if not t["beyond_typical"] else
                f"BEYOND its typical size, {t['prior_size']}; kept on decisive evidence: {t['plausibility']}"))
    setup = [t for t in d.terms if t["beyond_typical"]]
    if setup:
        lines.append("setup findings (what a size beyond the typical implies; check these first):")
        lines += [f"  {t['name']}: {t['finding']}" for t in setup]
    lines.append("terms discovered beyond the library: " + ("none" if not d.discovered else ""))
    for t in d.discovered:
        ci = "; ".join(f"{k} in [{lo:.4g}, {hi:.4g}]" for k, (lo, hi) in t["ci95"].items())
        lines += [f"  {t['name']}: {t['description']}",
                  f"    95 % interval (pose-clustered): {ci}",
                  f"    {'typical size' if t['plausible'] else 'BEYOND its typical size'}: {t['plausibility']}; "
                  f"held-out RMS {t['rms_gain_mm']:.4f} mm lower with it"]
    if d.dropped:
        lines.append("dropped by the backward check: " + ", ".join(d.dropped))
    if d.leads:
        lines.append("fit the residual but not added (a sign physics forbids, or a size beyond the typical without "
                     "decisive evidence):")
        lines += [f"  {r['name']} (round {r['round']}, held-out {r['rms_mm']:.4f} mm): {r['reason']}" for r in d.leads]
    lines.append("confounded (correlation of the estimates, fitted together; |r| >= "
                 f"{CONFOUNDED_MIN:g}): " + ("none" if not d.confounded else ", ".join(
                     f"{a} / {b} {r:+.2f}" for (a, b), r in ((c["terms"], c["correlation"]) for c in d.confounded))))
    if d.confounded:
        a, b = d.confounded[0]["terms"]
        lines.append(f"  to separate them: robstiff plan-poses N --separate {a},{b} [--campaign DATA.csv]")
    lines += describe_alternatives(d.alternatives)
    where = [s for s in d.residual_structure if s["strength"] > 0.02][:5]
    lines.append("where the remaining residual lives: " + (", ".join(
        f"{s['variable']} ({100 * s['strength']:.0f} % of it, {s['rms_mm']:.4f} mm)" for s in where)
        if where else "no variable explains more than 2 % of it"))
    if d.outliers:
        lines += ["", "gross outlier rows (left out of the fit):"]
        lines += [f"  line {o['line']}" + (f" (pose {o['pose']})" if o["pose"] is not None else "")
                  + f": residual {o['residual_mm']:.4f} mm" for o in d.outliers]
        lines.append("  joint stiffness with them (N*m/rad): " + ", ".join(
            f"{k:.4g}" for k in d.stiffness_with_outliers_Nm_per_rad))
    lines.append("")
    first = d.rounds[0] if d.rounds else []
    lib = [r for r in first if r.source == "library"]
    dic = sorted([r for r in first if r.source == "dictionary" and r.status == "ok"], key=lambda r: r.rms_mm)[:5]
    if markdown:
        lines += [CLUSTERED_P_NOTE, "",
                  "| candidate (first round) | held-out RMS (mm) | clustered p | F | p (rows indep.) | dBIC | status |",
                  "|---|---|---|---|---|---|---|"]
    else:
        lines.append(CLUSTERED_P_NOTE)
        lines.append("candidate (first round)             held-out RMS  clustered p      F     p (rows)    dBIC   "
                     "status")
    for r in lib + dic:
        status = r.status if r.status == "ok" else f"{r.status}: {r.reason}"
        name = r.name + (" (dictionary)" if r.source == "dictionary" else "")
        if markdown:
            lines.append(f"| {name} | {_g(r.rms_mm, '.4f')} | {_g(r.p_grouped, '.2g')} | {_g(r.f_stat, '.3g')} | "
                         f"{_g(r.p_value, '.2g')} | {_g(r.delta_bic, '.1f')} | {status} |")
        else:
            lines.append(f"  {name:34s} {_g(r.rms_mm, '8.4f')} mm {_g(r.p_grouped, '9.2g'):>9} "
                         f"{_g(r.f_stat, '9.3g'):>9} {_g(r.p_value, '9.2g'):>9} {_g(r.delta_bic, '8.1f'):>8}   "
                         f"{status}")
    th = d.thresholds
    lines += ["", f"tests: {d.n_hypotheses} hypotheses tried in {len(d.rounds)} round(s) ({len(CANDIDATES)} named, "
              f"{len(DICTIONARY)} in the dictionary); a term is added when its pose-clustered test (CR2 sandwich, "
              "Bell-McCaffrey t per contrast, Bonferroni over its parameters; on more poses than the model has "
              "parameters) passes at "
              f"{th['alpha_per_round']:g} / (candidates tried in the round) and it lowers the held-out RMS by "
              f"{100 * th['min_gain_library']:.0f} % (named) or {100 * th['min_gain_dictionary']:.0f} % (dictionary); "
              f"lack of fit at {th['alpha_lack_of_fit']:g}; outliers at {th['alpha_outlier']:g} over all rows; "
              f"folds seeded {th['fold_seed']}"]
    if d.final_params:
        lines += ["", "fitted parameters of the named effects added:"]
        lines += [f"  {name}: {_fmt_params(p)}" for name, p in d.final_params.items()]
    lines += ["", "joint stiffness of the final model (N*m/rad): "
              + ", ".join(f"{k:.4g}" + ("" if ok else " (nominal)")
                          for k, ok in zip(d.joint_stiffness_Nm_per_rad, d.identifiable))]
    return "\n".join(lines)


def residual_views(d, campaign, robot, folder, tool_m=None):
    """One PNG per view of the six-spring model's residual (what the trace
    reads), into ``folder`` (an io.RunFolder)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from robstiff_drake.model import kinematics as kin

    r = d.residual_before_mm
    used = np.zeros(len(campaign), dtype=bool)
    used[d.rows_used] = True
    F = campaign.force_N
    mag = np.linalg.norm(F, axis=1)
    u = F / np.maximum(mag, 1e-12)[:, None]
    along = np.sum(r * u, axis=1)
    written = []

    def save(fig, name):
        folder.save_figure(name, fig, dpi=90)
        written.append(name)

    q = robot.joint_rad(campaign.q_deg)
    J = kin.jacobian(robot.dh, q, tool_m)
    tau = np.einsum("nrj,nr->nj", J, campaign.wrench)
    fig, axes = plt.subplots(2, 3, figsize=(12, 6.5), constrained_layout=True)
    for j, ax in enumerate(axes.ravel()):
        v = J[:, :3, j]
        n = np.linalg.norm(v, axis=1)
        ok = used & (n > 1e-9)
        proj = np.sum(r * v, axis=1) / np.maximum(n, 1e-12)
        ax.plot(tau[ok, j], proj[ok], ".", alpha=0.6)
        if not np.any(ok) or np.ptp(tau[ok, j]) == 0:
            ax.text(0.5, 0.5, "no torque from these loads", transform=ax.transAxes, ha="center")
        ax.axvline(0, color="k", lw=0.6)
        ax.set_xlabel(f"torque of joint {j + 1} (N*m)")
        ax.set_ylabel(f"residual along joint {j + 1}'s motion (mm)")
    fig.suptitle("six-spring residual along the direction each joint moves the tool point, against that joint's "
                 "torque\n"
                 "(lost motion in a joint shows as a step at zero torque; the springs' refit tilts it)")
    save(fig, "residual_vs_joint_torque.png")

    fig, ax = plt.subplots(figsize=(6, 4), constrained_layout=True)
    ax.plot(mag[used], along[used], ".")
    ax.set_xlabel("load magnitude (N)")
    ax.set_ylabel("residual along the load (mm)")
    ax.set_title("residual against load magnitude")
    save(fig, "residual_vs_load_magnitude.png")

    fig, axes = plt.subplots(2, 3, figsize=(12, 6), constrained_layout=True)
    for j, ax in enumerate(axes.ravel()):
        ax.plot(campaign.q_deg[used, j], along[used], ".")
        ax.set_xlabel(f"q{j + 1} (deg)")
        ax.set_ylabel("residual along the load (mm)")
    fig.suptitle("residual against each joint angle")
    save(fig, "residual_vs_joint_angles.png")

    order = campaign.seq if campaign.seq is not None else np.arange(1, len(campaign) + 1)
    fig, ax = plt.subplots(figsize=(8, 4), constrained_layout=True)
    for k, a in enumerate("xyz"):
        ax.plot(order[used], r[used, k], ".", label=f"d{a}")
    ax.set_xlabel("measurement order" + ("" if campaign.seq is not None else " (row; no seq column)"))
    ax.set_ylabel("residual (mm)")
    ax.legend()
    ax.set_title("residual against measurement order (drift shows as a trend)")
    save(fig, "residual_vs_order.png")

    eq = (3 * d.rows_used[:, None] + np.arange(3)).ravel()
    y = r.reshape(-1)[eq]
    A = d.base_X[eq]
    for name, X in d.columns.items():
        # added-variable view: the candidate's columns with the six-spring
        # model's part taken out, fitted to the model's residual
        Xc = X[eq]
        Xp = Xc - A @ np.linalg.lstsq(A, Xc, rcond=None)[0]
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


def run(*, data, tool=None, json_out=None, report=None, plots=None, robot_yaml=None, noise_mm=None, validate=None,
        write_robot=None):
    from robstiff_drake.commands import diagnose_tracker
    from robstiff_drake.identification.tracker.campaign import is_tracker_file

    check_outputs(inputs=[data, robot_yaml, validate], files={"--json": json_out, "--report": report,
                                                              "--write-robot": write_robot},
                  folders={"--plots": plots})
    if noise_mm is not None and not 0 < noise_mm <= MAX_NOISE_MM:
        raise InputError(f"--noise-mm {noise_mm:g}: the noise of one displacement component must be in "
                         f"(0, {MAX_NOISE_MM:g}] mm")
    tracker = is_tracker_file(data)
    diagnose_tracker.check_tracker_options(tracker, validate, write_robot)
    robot = load_robot(robot_yaml)
    if write_robot is not None:
        check_outputs(inputs=[robot.source], files={"--write-robot": write_robot})
    warnings = Warnings()
    if tracker:
        return diagnose_tracker.run(data=data, tool_m=parse_tool(tool), noise_mm=noise_mm, robot=robot,
                                    json_out=json_out, report=report, plots_dir=plots, validate=validate,
                                    write_robot=write_robot, warnings=warnings, robot_given=robot_yaml is not None)
    campaign = read_stiffness_campaign(data, robot)
    # the stated floor as identify reads it: --noise-mm, else the file's '# noise_mm:' line (else replicate rows)
    noise_mm, noise_by = stated_noise(campaign, noise_mm)
    tool_m = campaign_tool_m(campaign, robot, parse_tool(tool), warnings)
    warnings.extend_from(campaign_warnings(campaign))
    check_angle_units(robot, campaign, tool_m)
    springs = identify(robot, campaign, tool_m=tool_m)  # six springs on every row: the warnings and the search's start
    warnings.extend_from(fit_warnings(springs, robot, campaign))
    d = diagnose(robot, campaign, tool_m=tool_m, noise_mm=noise_mm, noise_by=noise_by, warnings=warnings,
                 base_all=springs)
    with staged_outputs():  # the JSON, the report and the views, all or none
        if json_out is not None:
            emit_json(to_dict(d, campaign), json_out)
        if report is not None:
            write_atomic(report, format_report(d, campaign, markdown=True) + "\n")
        if plots is not None:
            with RunFolder(plots) as folder:
                residual_views(d, campaign, robot, folder, tool_m)
    if json_out != "-":
        print(format_report(d, campaign))
    stderr = json_out == "-"
    wrote(json_out, to_stderr=stderr)
    wrote(report, "the report (Markdown)", to_stderr=stderr)
    wrote(plots, "the residual views, one PNG each", folder=True, to_stderr=stderr)
    return 0


__all__ = ["run", "CANDIDATES"]
