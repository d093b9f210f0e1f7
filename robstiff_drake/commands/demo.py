"""``robstiff demo``: the project's main job, the paper's block-milling test
(Table 3, Fig. 7) in simulation, without and with real-time compensation.

Prints the surface-error table and why the uncompensated robot cuts more
(the stiffness model's coupling at the machining pose), and writes to
``out`` (default ./robstiff-out/): surface_error.png (like Fig. 7), the
diagram, time series CSVs, demo.json and the stiffness map."""

import copy
import tempfile
from pathlib import Path

import numpy as np

from robstiff_drake.commands import simulate, stiffness_map
from robstiff_drake.diagrams.run_vibration import vibration_of, vibration_warnings
from robstiff_drake.io import RunFolder, Warnings, check_outputs, json_text
from robstiff_drake.model import kinematics as kin
from robstiff_drake.model import stiffness as st
from robstiff_drake.errors import InputError
from robstiff_drake.progress import info, wrote
from robstiff_drake.paths import DEFAULT_ROBOT_NAME, DIAGRAMS_DIR, library_robots, scenario_file

BLOCK = DIAGRAMS_DIR / "block_milling.yaml"  # the IRB6400's (the paper's) block test
IDENTIFIED_NOTE = ("  compensated: on the model a user would have (stiffness from a simulated laser-tracker campaign, "
                   "a calibrated payload,\n  the sensor's bias as calibrated; docs/assumptions.md); exact model: "
                   "the plant's own stiffness, payload and bias (the bound)")


def block_scenario(robot_yaml=None):
    """The block test's scenario for --robot: the library robot's own
    (diagrams/block_milling_NAME.yaml), or the IRB6400's for a robot file
    (which run() moves to the file's reference point: moved_block)."""
    if robot_yaml is None or robot_yaml == DEFAULT_ROBOT_NAME:
        return BLOCK
    if robot_yaml in library_robots():
        path = scenario_file(f"block_milling_{robot_yaml}")
        if not path.exists():
            raise InputError(f"demo --robot {robot_yaml}: no block test for it ({path.name} is missing)")
        return path
    return BLOCK


def moved_block(robot, folder):
    """The IRB6400's block test moved to a robot file's reference machining
    point (machining_workspace.reference_tool_point_mm, "the block test's"
    in docs/your_robot.md): the block, the pass and the scan line shifted by
    the point less the pass's middle, as the library's
    diagrams/block_milling_NAME.yaml are; written into ``folder``.  BLOCK
    itself when the point is the IRB6400's (1600, 0, 700) mm.  Returns the
    path and the shift (mm)."""
    import yaml

    data = yaml.safe_load(BLOCK.read_text())
    ends = np.array(data["path"]["waypoints_mm"], dtype=float)
    shift = robot.workspace.reference_tool_point_m * 1e3 - ends.mean(axis=0)
    if np.max(np.abs(shift)) < 1e-6:
        return BLOCK, np.zeros(3)
    dx, dy, dz = (float(v) for v in shift)
    data["workpiece"]["boxes_mm"] = [[x0 + dx, x1 + dx, y0 + dy, y1 + dy, top + dz]
                                     for x0, x1, y0, y1, top in data["workpiece"]["boxes_mm"]]
    data["path"]["waypoints_mm"] = (ends + shift).tolist()
    data["scan"]["lines_y_mm"] = [y + dy for y in data["scan"]["lines_y_mm"]]
    data["description"] = (f"{data['description']} Moved to {robot.name}'s reference machining point "
                           f"({', '.join(f'{v:g}' for v in robot.workspace.reference_tool_point_m * 1e3)}) mm.")
    path = folder / BLOCK.name
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path, shift


def cut_more_explanation(result, robot):
    """Each force component's share of the tool's vertical deflection at
    mid-pass, from the conventional model at the actual pose."""
    t, w = result.logs["cutting_wrench"]
    ts, x = result.logs["state"]
    i = len(t) // 2
    q = x[min(np.searchsorted(ts, t[i]), len(ts) - 1), :6]
    J = kin.jacobian(robot.dh, q, robot.tool_point(where="demo"))
    C = st.cartesian_compliance(J, robot.joint_stiffness_Nm_per_rad)  # 6x6, SI
    W = w[i]
    shares = C[2, :] * W * 1e3  # mm, vertical displacement from each wrench component
    return {"force_N": W[:3], "moment_Nm": W[3:], "compliance_z_um_per_N": C[2, :3] * 1e6,
            "dz_from_component_mm": shares, "dz_total_mm": float(shares.sum())}


def format_explanation(e):
    f, c, s = e["force_N"], e["compliance_z_um_per_N"], e["dz_from_component_mm"]
    lines = ["why the uncompensated robot cuts more (conventional model at the mid-pass pose):",
             "  component   force on the tool   C_z,i (um/N)   tool dz (mm)"]
    for k, name in enumerate(("x (feed)", "y (cross)", "z (axial)")):
        lines.append(f"  {name:10s}  {f[k]:+10.1f} N      {c[k]:+8.3f}      {s[k]:+8.3f}")
    lines.append(f"  moments     ({', '.join(f'{v:+.1f}' for v in e['moment_Nm'])}) N*m             "
                 f"{s[3:].sum():+8.3f}")
    lines.append(f"  total                                          {e['dz_total_mm']:+8.3f} mm "
                 "(negative: down, into the part)")
    if s[0] < 0 < c[0] and e["dz_total_mm"] < 0:
        lines.append("  The feed force pulls the cutter back towards the robot; at this pose the arm's coupled "
                     "stiffness turns that into a downward motion (C_zx > 0 with F_x < 0) larger than the axial "
                     "force's push up: the robot cuts deeper than commanded.")
    else:
        lines.append("  (negative total: the tool sinks into the part, cuts more; positive: it is pushed up, "
                     "cuts less)")
    return "\n".join(lines)


def run(*, out="robstiff-out", robot_yaml=None):
    check_outputs(folders={"--out": out})
    with tempfile.TemporaryDirectory(prefix="robstiff-demo-") as tmp:
        return _run(out=out, robot_yaml=robot_yaml, folder=Path(tmp))


def _run(*, out, robot_yaml, folder):
    block = block_scenario(robot_yaml)
    from robstiff_drake.diagrams.scenario import load_scenario, scenario_robot  # Drake: after the checks

    robot = scenario_robot(load_scenario(block), None if robot_yaml in library_robots() else robot_yaml)
    if block == BLOCK and robot_yaml is not None and robot_yaml not in library_robots():
        block, shift = moved_block(robot, folder)
        if np.any(shift):
            info(f"robstiff: demo: the IRB6400's block test moved by ({', '.join(f'{v:+g}' for v in shift)}) mm "
                 f"to {robot_yaml}'s machining_workspace.reference_tool_point_mm")
    warnings = Warnings()
    sc, results = simulate.simulate(scenario=block, compensation="both", robot=robot, warnings=warnings,
                                    progress=None)  # a bar over simulated time on a terminal
    summ = simulate.summary(results, sc, warnings)
    # the bound: the compensator holding the plant's own model (what the identified model approaches)
    from robstiff_drake.diagrams.experiment import run_cut  # (Drake: after the inputs are checked)

    exact = copy.deepcopy(sc)
    exact.model.source = "nominal"
    bound = run_cut(exact, robot, compensation=True)
    summ["surface_error_mm"]["exact model"] = bound.surface_error_mm
    # did the bound's run vibrate? (simulate's check, which the two runs above had in simulate.simulate)
    summ["vibration"]["exact model"] = vibration_of(bound)
    warnings.extend_from(vibration_warnings({"exact model": summ["vibration"]["exact model"]}, sc))
    summ["warnings"] = list(warnings)
    summ["compensator_model"] = simulate.model_description(sc, robot)
    expl = cut_more_explanation(results[0], robot)
    print(f"== the paper's block-milling test (Table 3), simulated: {robot.title} ==")
    print(simulate.format_table(summ))
    print(IDENTIFIED_NOTE)
    print()
    print(format_explanation(expl))
    summ["cut_more_explanation"] = expl
    with RunFolder(out) as run:
        written = simulate.write_outputs(sc, results, robot, run, warnings)
        fig, _ = stiffness_map.make_map(robot, tool_m=robot.tool_point(where="demo"))
        run.save_figure("stiffness_map.png", fig, dpi=110)
        written.append("stiffness_map.png")
        run.write("demo.json", json_text(dict(summ, run_id=run.run_id)))
        written.append("demo.json")
    info("")
    wrote(out, ", ".join(written), folder=True)
    return 0
