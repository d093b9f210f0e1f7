"""Every plot the project writes reads at a glance: axes labelled with
units, no legend over data, titles inside the figure (tests/figure_checks.py
measures the drawn artists' extents).  Each plot function is rendered with
small inputs; the commands whose plot functions change often (diagnose) are
run through the CLI and their figures checked as they are saved.
``test_every_figure_writer_is_checked`` fails when a module that writes a
figure is not covered here."""

import re
from pathlib import Path
from types import SimpleNamespace

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
from figure_checks import problems  # noqa: E402

from robstiff_drake.commands.main import main  # noqa: E402
from robstiff_drake.model.robot import load_robot  # noqa: E402

PACKAGE = Path(__file__).resolve().parents[1] / "robstiff_drake"

# module -> the test(s) below that render its figures
CHECKED = {
    "commands/stiffness_map.py": "test_stiffness_map",
    "commands/demo.py": "test_stiffness_map (demo saves stiffness_map.make_map's figure)",
    "commands/sweep.py": "test_sweep_plot_*",
    "commands/simulate.py": "test_surface_plot_legend_covers_no_pad",
    "commands/table2.py": "test_table2_plot",
    "commands/identify.py": "test_identify_plot",
    "commands/diagnose.py": "test_diagnose_views",
    "commands/diagnose_run.py": "test_diagnose_run_plot",
    "commands/diagnose_tracker.py": "test_diagnose_tracker_views",
}


def check(fig):
    found = problems(fig)
    plt.close(fig)
    assert not found, "\n".join(found)


def test_every_figure_writer_is_checked():
    writers = set()
    for path in PACKAGE.rglob("*.py"):
        rel = str(path.relative_to(PACKAGE))
        if rel == "io.py":  # the writer itself
            continue
        if re.search(r"\bsavefig\(|save_figure(_atomic)?\(", path.read_text()):
            writers.add(rel)
    assert writers == set(CHECKED), f"not checked here: {sorted(writers - set(CHECKED))}; " \
                                    f"no longer writing figures: {sorted(set(CHECKED) - writers)}"


def test_the_checks_find_what_they_look_for():
    """A legend over data, a clipped title and a label without unit are found."""
    fig, ax = plt.subplots(figsize=(4, 3))
    x = np.linspace(0, 1, 50)
    ax.plot(x, np.ones_like(x), label="flat line under the legend")
    ax.legend(loc="center")
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("height")
    fig.suptitle("a title far too long to fit in a figure four inches wide, so its ends are cut off")
    fig.legend(["a key beside the figure's title"], loc="outside right upper")
    found = problems(fig)
    plt.close(fig)
    assert any("covers the figure title" in p for p in found), found
    assert any("covers" in p and "data point" in p for p in found), found
    assert any("cut off" in p and "figure title" in p for p in found), found
    assert any("'height' has no unit" in p for p in found), found

    fig, ax = plt.subplots(figsize=(4, 3), layout="constrained")
    ax.plot(x, x, label="rising")
    ax.legend(loc="upper left")  # the line starts in the lower left: nothing under the legend
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("y (mm)")
    ax.set_title("fits")
    check(fig)


@pytest.mark.parametrize("robot_name", ["irb6400", "kr240_r2900"])
def test_stiffness_map(robot_name):
    from robstiff_drake.commands.stiffness_map import make_map

    robot = load_robot(robot_name)
    fig, data = make_map(robot, tool_m=robot.tool_point(where="test"), resolution=7)
    bar = [ax for ax in fig.axes if hasattr(ax, "_colorbar")][0]._colorbar
    finite = np.concatenate([a[np.isfinite(a)] for a in (*data["top_view"], *data["side_view"])])
    # the colour bar is honest: it reaches the maximum, or says it stops short with an arrow
    assert bar.vmax >= finite.max() or bar.extend == "max"
    if bar.extend == "max":
        assert f"up to {finite.max():.2f} mm" in bar.ax.get_ylabel()
    check(fig)


def _sweep_rows(periods, delays=(1,), cutoffs=(5.0,), modes=("plain", "predictive"), unstable=()):
    """Sweep rows as run_sweep returns them (errors in mm, made up)."""
    rows = []
    for d in delays:
        for p in periods:
            for c in cutoffs:
                for m in modes:
                    stable = (p, c, m) not in unstable
                    e = 0.01 * p * (1.5 if m == "plain" else 1.0) * (1 + 0.2 * d)
                    stats = {"mean": e, "entry_max_abs": 2 * e, "exit_max_abs": 1.5 * e}
                    rows.append({"period_ms": p, "delay_steps": d, "cutoff_hz": c, "mode": m, "stable": stable,
                                 "surface_error_mm": stats if stable else None,
                                 "predicted": {"surface_error_mm": {k: 1.1 * v for k, v in stats.items()}}})
    return rows


def _unstable_marker_lines(fig):
    return [line for ax in fig.axes for line in ax.lines if line.get_marker() == "X" and line.get_color() == "k"]


def test_sweep_plot_one_period():
    """One period: the cutoff/mode combinations spread along x (not all at one x of a log axis)."""
    from robstiff_drake.commands.sweep import plot_figure

    fig = plot_figure(_sweep_rows([4.0], cutoffs=(2.0, 5.0, 10.0), unstable={(4.0, 10.0, "plain")}))
    ax = fig.axes[0]
    assert ax.get_xscale() == "linear"
    xs = {float(x) for line in ax.lines for x in np.atleast_1d(line.get_xdata())}
    assert len(xs) == 6  # 3 cutoffs x 2 modes
    assert len(_unstable_marker_lines(fig)) == 2  # one per row of axes
    labels = [t.get_text() for leg in fig.legends for t in leg.get_texts()]
    assert "unstable run" in labels and not any("red" in ax.get_title() for ax in fig.axes)
    check(fig)


def test_sweep_plot_periods_and_delays():
    from robstiff_drake.commands.sweep import plot_figure

    rows = _sweep_rows([0.5, 1, 2, 4, 8, 16, 32, 48, 100], delays=(1, 2), cutoffs=(5.0, 10.0),
                       unstable={(48, 10.0, "plain"), (100, 5.0, "predictive")})
    fig = plot_figure(rows)
    assert fig.axes[0].get_xscale() == "log"
    # the unstable marker is no data colour: black, and the data use the colour cycle
    data_colors = {line.get_color() for ax in fig.axes for line in ax.lines if line.get_marker() != "X"}
    assert "k" not in data_colors and len(_unstable_marker_lines(fig)) == 8  # 2 runs x 2 delays x 2 rows
    check(fig)


def test_surface_plot_legend_covers_no_pad():
    """Four pads like the cylinder head's, the last one low at the right end."""
    from robstiff_drake.commands.simulate import plot_surfaces
    from robstiff_drake.diagrams.experiment import ScanLine

    x = np.arange(1.450, 1.740, 0.0005)
    pads = [(1.450, 1.510), (1.530, 1.580), (1.600, 1.690), (1.715, 1.738)]
    on_pad = np.zeros_like(x, dtype=bool)
    for a, b in pads:
        on_pad |= (x >= a) & (x <= b)

    def result(compensation, scale):
        scans = []
        for y in (0.0, 0.005):
            e = scale * (0.04 + 0.03 * np.sin(40 * x)) - scale * 0.04 * (x > 1.7)
            cmd = np.where(on_pad, 0.7, np.nan)
            scans.append(ScanLine(y, x, cmd, cmd - e, None))
        err = np.concatenate([s.error_m[np.isfinite(s.error_m)] for s in scans]) * 1e3
        stats = {"mean": err.mean(), "rms": np.sqrt(np.mean(err**2)), "max_abs": np.abs(err).max(), "pv": np.ptp(err)}
        return SimpleNamespace(scans=scans, surface_error_mm=stats, compensation=compensation)

    fig = plot_surfaces([result(False, 1e-2), result(True, 1e-3)], SimpleNamespace(name="cylinder_head"))
    check(fig)


def test_surface_plot_along_a_path_keeps_its_title_clear():
    """A G-code contour's plot: three scan lines along the path, labelled with their offsets (long
    labels); the key sat beside the figure's title and covered its end (issue 23)."""
    from robstiff_drake.commands.simulate import plot_surfaces
    from robstiff_drake.diagrams.experiment import ScanLine

    s = np.linspace(0.1, 0.36, 300)

    def result(compensation, scale):
        scans = []
        for off in (-0.015, 0.0, 0.015):
            e = scale * (0.1 + 0.1 * np.sin(30 * s + off))
            scans.append(ScanLine(0.0, s, np.full_like(s, 0.7), 0.7 - e, None, s_m=s, offset_m=off))
        err = np.concatenate([x.error_m for x in scans]) * 1e3
        stats = {"mean": err.mean(), "rms": np.sqrt(np.mean(err**2)), "max_abs": np.abs(err).max(), "pv": np.ptp(err)}
        return SimpleNamespace(scans=scans, surface_error_mm=stats, compensation=compensation)

    fig = plot_surfaces([result(False, 1e-3), result(True, 1e-4)], SimpleNamespace(name="contour_with_arcs"))
    check(fig)


def test_table2_plot():
    from robstiff_drake.commands import table2

    results, F, D, rows = table2.analyse()
    check(table2.plot(results, F, D, rows))


def test_identify_plot(tmp_path):
    from robstiff_drake.commands.identify import plot_fit
    from robstiff_drake.identification.stiffness.campaign import read_stiffness_campaign
    from robstiff_drake.identification.stiffness.joint_stiffness import identify

    data = tmp_path / "campaign.csv"
    assert main(["synth", "stiffness", str(data), "--n", "48", "--quiet"]) == 0
    robot = load_robot()
    campaign = read_stiffness_campaign(data, robot)
    fit = identify(robot, campaign, tool_m=robot.tool_point(where="test"))
    check(plot_fit(fit, campaign, robot))


def test_diagnose_views(tmp_path, monkeypatch):
    """Through the CLI: every residual view `diagnose --plots` saves."""
    import matplotlib.figure

    checked = {}
    savefig = matplotlib.figure.Figure.savefig

    def checked_savefig(fig, fname, *args, **kwargs):
        checked[Path(str(fname)).name] = problems(fig)
        return savefig(fig, fname, *args, **kwargs)

    data = tmp_path / "campaign.csv"
    assert main(["synth", "stiffness", str(data), "--n", "48", "--effect", "lost_motion", "--quiet"]) == 0
    monkeypatch.setattr(matplotlib.figure.Figure, "savefig", checked_savefig)
    assert main(["diagnose", str(data), "--plots", str(tmp_path / "views")]) == 0
    saved = sorted(p.name for p in (tmp_path / "views").glob("*.png"))
    assert saved and sorted(checked) == saved
    bad = {name: found for name, found in checked.items() if found}
    assert not bad, bad


def test_diagnose_tracker_views(tmp_path, monkeypatch):
    """Through the CLI: the view `diagnose --plots` saves for a tracker campaign (tests/tracker_world.py)."""
    import matplotlib.figure
    import tracker_world as tw

    checked = {}
    savefig = matplotlib.figure.Figure.savefig

    def checked_savefig(fig, fname, *args, **kwargs):
        checked[Path(str(fname)).name] = problems(fig)
        return savefig(fig, fname, *args, **kwargs)

    data = tmp_path / "tracker.csv"
    data.write_text(tw.make_tracker_campaign(load_robot("irb6400"), 3, n=120).csv_text)
    monkeypatch.setattr(matplotlib.figure.Figure, "savefig", checked_savefig)
    assert main(["diagnose", str(data), "--plots", str(tmp_path / "views"), "--quiet"]) == 0
    saved = sorted(p.name for p in (tmp_path / "views").glob("*.png"))
    assert saved and sorted(checked) == saved
    bad = {name: found for name, found in checked.items() if found}
    assert not bad, bad


def test_diagnose_run_plot():
    from robstiff_drake.commands.diagnose_run import plot

    x = np.arange(1525.0, 1675.0, 0.5)
    rng = np.random.default_rng(7)
    scan = SimpleNamespace(x_mm=x, y_mm=np.full_like(x, 15.0), error_mm=0.02 + 0.0002 * (x - 1525) + rng.normal(0, 0.003, len(x)))
    covered = np.ones_like(x, dtype=bool)
    cut = SimpleNamespace(x_mm=x, y_mm=np.full_like(x, 15.0), error_mm=rng.normal(0, 0.003, len(x)))
    rep = {"surface_error_before_mm": {"mean": float(scan.error_mm.mean()), "rms": 0.03},
           "causes": [{"name": "loop_lag"}]}
    extras = {"scan": scan, "covered": covered, "model_mm": 0.02 + 0.0002 * (x - 1525),
              "cut_scans": [("loop_lag fix", cut)]}
    check(plot(rep, extras, "run: traced loop_lag; from the verification cuts: confirmed (loop_lag fix)"))
