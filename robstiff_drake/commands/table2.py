"""``robstiff table2``: the paper's Table 2 (data/seed_table2.csv) analysed as
the measured evidence it is: linearity in load, the offset at zero load and
repeatability, per assumed pose group.  The table and plot in the README come
from ``robstiff table2 --plot docs/table2.png``.

The grouping of the rows by pose is an assumption: see
identification/stiffness/table2_grouping.py (printed by ``robstiff table2 --help``).
"""

import numpy as np

from robstiff_drake.errors import InputError
from robstiff_drake.identification.stiffness.campaign import D_COLS, F_COLS
from robstiff_drake.identification.stiffness.measurement_table import read_table
from robstiff_drake.identification.stiffness.linearity import analyse_group, cartesian_diagnosis, pooled_offset
from robstiff_drake.identification.stiffness.table2_grouping import GROUPS, SPLIT_A
from robstiff_drake.io import check_outputs, emit_json, save_figure_atomic, staged_outputs
from robstiff_drake.paths import DATA_DIR
from robstiff_drake.progress import wrote

TABLE2_CSV = DATA_DIR / "seed_table2.csv"


def analyse(path=TABLE2_CSV, groups=None):
    t = read_table(path, required=("row",) + F_COLS + D_COLS)
    rows = t.numeric["row"].astype(int).tolist()
    F = np.column_stack([t.numeric[c] for c in F_COLS])
    D = np.column_stack([t.numeric[c] for c in D_COLS])
    out = []
    for name, members in (groups or {**GROUPS, **SPLIT_A}).items():
        missing = [m for m in members if m not in rows]
        if missing:
            raise InputError(f"{path}: group {name} needs rows {missing}, not in the file")
        idx = [rows.index(m) for m in members]
        out.append(analyse_group(name, members, F[idx], D[idx]))
    return out, F, D, rows


def along_load(results, F, D, rows):
    """Offset along the load direction per two-level primary group (A, B), pooled."""
    two_level = [g for g in results if g.components and g.name in GROUPS]
    idx = {g.name: [rows.index(m) for m in g.rows] for g in two_level}
    per, pooled, std, p = pooled_offset(two_level, {k: F[v] for k, v in idx.items()},
                                        {k: D[v] for k, v in idx.items()})
    return {"per_group_mm": {k: {"offset_mm": v, "std_mm": s} for k, (v, s) in per.items()},
            "pooled_mm": pooled, "pooled_std_mm": std, "p_value": p}


def diagnosis(results, F, D, rows):
    """The residual diagnosis per two-level primary group (A, B)."""
    out = {}
    for g in results:
        if g.components and g.name in GROUPS:
            idx = [rows.index(m) for m in g.rows]
            out[g.name] = cartesian_diagnosis(g.rows, F[idx], D[idx])
    return out


def diagnosis_markdown(diag):
    lines = ["| group | model | leave-one-out RMS (mm) | fit RMS (mm) | F | p |", "|---|---|---|---|---|---|"]
    for g, models in diag.items():
        for name, e in models.items():
            f = f"{e['f_stat']:.2f}" if "f_stat" in e else "-"
            p = f"{e['p_value']:.3g}" if "p_value" in e else "-"
            lines.append(f"| {g} | {name} | {e['loo_rms_mm']:.4f} | {e['fit_rms_mm']:.4f} | {f} | {p} |")
    return "\n".join(lines)


def to_dict(results):
    out = []
    for g in results:
        out.append({
            "group": g.name, "rows": g.rows, "load_direction": g.direction, "loads_N": g.loads_N,
            "compliance_um_per_N_through_origin": g.compliance_um_per_N,
            "repeatability_mm": g.repeatability_mm, "repeatability_dof": g.n_repeat_dof,
            "components": [None if not g.components else {
                "axis": ax, "slope_through_origin_um_per_N": c.slope0_mm_per_N * 1e3,
                "slope_um_per_N": c.slope_mm_per_N * 1e3, "offset_at_zero_load_mm": c.intercept_mm,
                "offset_std_mm": c.intercept_std_mm, "f_stat": c.f_stat, "p_value": c.p_value,
                "displacement_ratio": c.disp_ratio, "load_ratio": c.load_ratio,
                "rms_through_origin_mm": c.rms_origin_mm, "rms_with_offset_mm": c.rms_intercept_mm,
            } for ax, c in zip("xyz", g.components or [None] * 3)],
        })
    return out


def markdown(results):
    lines = [
        "| group | rows | loads (N) | axis | d(360)/d(180) | offset at 0 N (mm) | p (offset = 0) "
        "| RMS through origin / with offset (mm) | repeatability sigma (mm) |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for g in results:
        loads = "/".join(f"{v:g}" for v in g.loads_N)
        if g.components:
            for ax, c, rep in zip("xyz", g.components, g.repeatability_mm):
                lines.append(f"| {g.name} | {','.join(map(str, g.rows))} | {loads} | {ax} | {c.disp_ratio:.3f} | "
                             f"{c.intercept_mm:+.4f} +- {c.intercept_std_mm:.4f} | {c.p_value:.3g} | "
                             f"{c.rms_origin_mm:.4f} / {c.rms_intercept_mm:.4f} | {rep:.4f} |")
        else:
            rep = ", ".join(f"{v:.4f}" for v in g.repeatability_mm)
            comp = ", ".join(f"{v:.2f}" for v in g.compliance_um_per_N)
            lines.append(f"| {g.name} | {','.join(map(str, g.rows))} | {loads} | - | single load: d / load = ({comp}) "
                         f"um/N | - | - | - | ({rep}) |")
    return "\n".join(lines)


def plot(results, F, D, rows):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    shown = [g for g in results if g.name in ("A", "B")]
    fig, axes = plt.subplots(1, len(shown), figsize=(6 * len(shown), 4.5), constrained_layout=True)
    for ax, g in zip(np.atleast_1d(axes), shown):
        idx = [rows.index(m) for m in g.rows]
        mag = np.linalg.norm(F[idx], axis=1)
        x = np.linspace(0, mag.max() * 1.05, 50)
        for i, (name, color) in enumerate(zip("xyz", ("C0", "C1", "C2"))):
            c = g.components[i]
            ax.plot(mag, D[idx, i], "o", color=color, label=f"d{name} measured")
            ax.plot(x, c.slope0_mm_per_N * x, "--", color=color, lw=1, label=f"d{name} line through 0")
            ax.plot(x, c.slope_mm_per_N * x + c.intercept_mm, "-", color=color, lw=1,
                    label=f"d{name} with offset {c.intercept_mm:+.3f} mm")
        ax.axhline(0, color="k", lw=0.6)
        ax.set_xlim(0, None)
        ax.set_xlabel("load |F| (N)")
        ax.set_ylabel("displacement (mm)")
        ax.set_title(f"the paper's Table 2, group {g.name} (rows {','.join(map(str, g.rows))})")
        ax.legend(fontsize=7)
    return fig


def run(*, json_out=None, plot_out=None, data=None):
    check_outputs(inputs=[data or TABLE2_CSV], files={"--json": json_out, "--plot": plot_out})
    results, F, D, rows = analyse(data or TABLE2_CSV)
    pooled = along_load(results, F, D, rows)
    diag = diagnosis(results, F, D, rows)
    with staged_outputs():  # the JSON and the plot, both or neither
        if json_out is not None:
            emit_json({"data": str(data or TABLE2_CSV), "groups": to_dict(results), "offset_along_load": pooled,
                       "diagnosis": diag, "warnings": []}, json_out)
        if plot_out is not None:
            save_figure_atomic(plot(results, F, D, rows), plot_out, dpi=100)
    if json_out != "-":
        print("the paper's Table 2: linearity in load, offset at zero load, repeatability (grouping of the rows by pose: "
              "see `robstiff table2 --help`)")
        print(markdown(results))
        print()
        print("offset at zero load along the load direction (positive: the tool moved further along the load "
              "than a line through the origin explains):")
        for k, v in pooled["per_group_mm"].items():
            print(f"  group {k}: {v['offset_mm']:+.4f} +- {v['std_mm']:.4f} mm")
        print(f"  pooled:  {pooled['pooled_mm']:+.4f} +- {pooled['pooled_std_mm']:.4f} mm "
              f"(two-sided p = {pooled['p_value']:.3g})")
        print()
        print("residual diagnosis without joint angles (per group: a line through the origin per component, "
              "and the extensions that can show):")
        print(diagnosis_markdown(diag))
    wrote(json_out, to_stderr=json_out == "-")
    wrote(plot_out, to_stderr=json_out == "-")
    return 0
