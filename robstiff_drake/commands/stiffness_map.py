"""``robstiff stiffness-map``: where the robot is soft.  The tool-point
deflection under a force at the tool (conventional model), over a top view
(plane at the reference machining height) and a side view (plane y = 0) of
the workspace, with the spindle axis pointing down; in the softest direction
and along z (the direction that a face-milling surface error takes)."""

import textwrap

import numpy as np

from robstiff_drake.commands.options import parse_tool
from robstiff_drake.errors import InputError
from robstiff_drake.io import check_outputs, save_figure_atomic
from robstiff_drake.model import ik
from robstiff_drake.model import kinematics as kin
from robstiff_drake.model import stiffness as st
from robstiff_drake.model.robot import load_robot
from robstiff_drake.progress import progress


def deflection_grid(robot, xs_m, ys_m, zs_m, tool_m, force_N, bar=None):
    """Deflection (mm) on a 2-D grid: exactly one of xs/ys/zs has length 1.

    Returns (worst_mm, along_z_mm), each of shape (len(a), len(b)) for the two
    varying axes in x, y, z order; NaN where the pose is unreachable.
    ``bar``: a progress bar stepped once per grid row."""
    grid = np.stack(np.meshgrid(xs_m, ys_m, zs_m, indexing="ij"), axis=-1).squeeze()
    worst = np.full(grid.shape[:2], np.nan)
    along_z = np.full(grid.shape[:2], np.nan)
    q_ref = None
    for i in range(grid.shape[0]):
        for j in range(grid.shape[1]):
            try:
                q = ik.solve_for(robot, ik.tool_down_pose(grid[i, j]), tool_m, q_ref_rad=q_ref)
            except ik.IKError:
                continue
            q_ref = q
            C = st.translational_compliance(kin.jacobian(robot.dh, q, tool_m), robot.joint_stiffness_Nm_per_rad)
            worst[i, j] = force_N * np.linalg.eigvalsh(C)[-1] * 1e3
            along_z[i, j] = force_N * C[2, 2] * 1e3
        if bar is not None:
            bar.update(grid.shape[1])
    return worst, along_z


def make_map(robot, *, tool_m, force_N=500.0, resolution=41):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ws = robot.workspace
    z_ref = ws.reference_tool_point_m[2]
    # the views span 2.7 m in x (the IRB6400's reach), more for a longer arm
    dh = robot.dh
    reach_m = abs(dh.a_m[0]) + abs(dh.a_m[1]) + np.hypot(dh.a_m[2], dh.d_m[3]) + abs(dh.d_m[5])
    scale = max(1.0, reach_m / 2.7)
    xs = np.linspace(0.6, 2.7 * scale, resolution)
    ys = np.linspace(-1.6 * scale, 1.6 * scale, resolution)
    zs = np.linspace(0.0, 2.2 * scale, resolution)
    # (301 points a side: 181,202 IK solutions, minutes: a bar on a terminal, log lines elsewhere)
    with progress(2 * resolution**2, None, "stiffness-map", unit="points") as bar:
        top = deflection_grid(robot, xs, ys, [z_ref], tool_m, force_N, bar)
        side = deflection_grid(robot, xs, [0.0], zs, tool_m, force_N, bar)
    finite = np.concatenate([a[np.isfinite(a)] for a in (*top, *side)])
    # the colour scale stops at the 99th percentile (a few points near a
    # singular pose would squeeze the rest into one colour); points above
    # it get the over colour and the colour bar an arrow that says how far
    # the map goes
    vmax = float(np.percentile(finite, 99)) if finite.size else 1.0
    top_mm = float(finite.max()) if finite.size else vmax
    over = top_mm > vmax * (1 + 1e-9)
    cmap = plt.get_cmap("viridis").with_extremes(over=OVER_COLOR)

    fig, axes = plt.subplots(2, 2, figsize=(12, 9.6), layout="constrained")
    titles = ("softest direction", "along z (face-milling surface error)")
    views = (  # row, grids, vertical axis, workspace range on it, view title
        (0, top, ys, "y", ws.y_m, f"top view, tool point at z = {z_ref * 1e3:.0f} mm"),
        (1, side, zs, "z", ws.z_m, "side view, plane y = 0"),
    )
    for row, grids, vs, vname, vrange, view in views:
        for col, (data, title) in enumerate(zip(grids, titles)):
            ax = axes[row, col]
            im = ax.pcolormesh(xs * 1e3, vs * 1e3, data.T, vmin=0, vmax=vmax, cmap=cmap, shading="auto")
            ax.set_title(f"{view}:\n{title}", fontsize=10)
            ax.set_xlabel("x (mm)")
            ax.set_ylabel(f"{vname} (mm)")
            ax.add_patch(plt.Rectangle((ws.x_m[0] * 1e3, vrange[0] * 1e3), (ws.x_m[1] - ws.x_m[0]) * 1e3,
                                       (vrange[1] - vrange[0]) * 1e3, fill=False, ec="w", ls="--"))
            ax.plot(0, 0, "r^", ms=10)
            ax.set_aspect("equal")
    label = f"tool-point deflection under {force_N:g} N (mm)"
    if over:
        label += f"\nabove {vmax:.2f} mm (99th percentile): {OVER_NAME}, up to {top_mm:.2f} mm"
    fig.colorbar(im, ax=axes, label=label, shrink=0.8, extend="max" if over else "neither")
    fig.legend(handles=_key_handles(over), loc="outside lower center", ncol=4, fontsize=9, facecolor="0.8",
               framealpha=1.0)
    name = robot.title
    fig.suptitle("\n".join(textwrap.wrap(f"{name}: stiffness map (conventional model, spindle axis down)", 90)))
    return fig, {"top_view": top, "side_view": side, "xs_m": xs, "ys_m": ys, "zs_m": zs}


OVER_COLOR, OVER_NAME = "#ff00ff", "magenta"


def _key_handles(over):
    """The map's key: workspace box, robot base, blank cells (and the over colour)."""
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    handles = [Patch(fill=False, ec="w", ls="--", label="machining workspace"),
               Line2D([], [], color="r", marker="^", ls="", ms=8, label="robot base"),
               Patch(fc="w", ec="0.4", label="blank: out of reach or joint limits")]
    if over:
        handles.append(Patch(fc=OVER_COLOR, label="above the colour scale"))
    return handles


def run(*, out, force_N=500.0, resolution=41, tool=None, robot_yaml=None):
    if not force_N > 0:
        raise InputError(f"stiffness-map: --force-N must be > 0, got {force_N}")
    if not 5 <= resolution <= 301:
        raise InputError(f"stiffness-map: --resolution must be between 5 and 301, got {resolution}")
    if not str(out).lower().endswith(".png"):
        raise InputError(f"stiffness-map: --out must name a .png file, got {out!r}")
    check_outputs(inputs=[robot_yaml], files={"--out": out})
    robot = load_robot(robot_yaml)
    tool_m = robot.tool_point(parse_tool(tool), where="stiffness-map")
    fig, data = make_map(robot, tool_m=tool_m, force_N=force_N, resolution=resolution)
    save_figure_atomic(fig, out, dpi=110)
    worst = np.concatenate([data["top_view"][0].ravel(), data["side_view"][0].ravel()])
    worst = worst[np.isfinite(worst)]
    print(f"wrote {out}: deflection under {force_N:g} N in the softest direction "
          f"{worst.min():.3f}-{worst.max():.3f} mm over the reachable points of the map")
    return 0
