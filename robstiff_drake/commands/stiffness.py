"""``robstiff stiffness Q1..Q6``: tool position, Cartesian translational
compliance (um/N) and stiffness (N/um) with principal directions.

Q1..Q6 are the controller's angles (deg); the Jacobian and the joint
stiffness refer to the model's joints (the physical joints of the serial
chain, whose springs the robot file gives)."""

import math

import numpy as np

from robstiff_drake.commands.options import parse_tool
from robstiff_drake.errors import InputError, SingularPoseError
from robstiff_drake.io import check_outputs, emit_json
from robstiff_drake.model import kinematics as kin
from robstiff_drake.model import stiffness as st
from robstiff_drake.model.robot import load_robot
from robstiff_drake.progress import wrote


def parse_q_deg(values, what="stiffness"):
    """Six command-line strings -> floats, with errors naming the value."""
    if len(values) != 6:
        raise InputError(f"{what}: expected 6 joint angles Q1..Q6 in degrees, got {len(values)}")
    q = []
    for i, v in enumerate(values):
        try:
            q.append(float(v))
        except ValueError:
            raise InputError(f"{what}: q{i + 1} = {v!r} is not a number (degrees)") from None
    # six angles all within +-2 pi, three or more of them off zero and not whole degrees: radians typed where
    # the pendant's degrees go (a newcomer's FANUC pose from a campaign in rad: -1.047 -0.291 -0.505 ...)
    off = [v for v in q if v != 0.0]
    if len(off) >= 3 and all(abs(v) <= 2.0 * math.pi for v in q) and any(v != round(v) for v in off):
        from robstiff_drake.command import input_warning

        input_warning(f"{what}: every joint angle ({', '.join(f'{v:g}' for v in q)}) is within +-2 pi: radians? "
                      "The angles are the controller's degrees")
    return q


def pose_report(robot, q_deg, tool_m):
    """Everything the table and the JSON show for one configuration.

    ``q_deg`` (controller convention, deg) must already be checked."""
    q = robot.joint_rad(q_deg)
    k = robot.joint_stiffness_Nm_per_rad
    J = kin.jacobian(robot.dh, q, tool_m)
    C3 = st.translational_compliance(J, k)  # m/N
    w, V = st.principal_axes(C3)
    with np.errstate(divide="ignore"):
        stiff_eig_N_per_um = np.where(w > 1e-15, 1e-6 / np.maximum(w, 1e-300), np.inf)
    K3 = np.linalg.inv(C3) * 1e-6 if w[0] > 1e-15 * max(w[-1], 1e-300) else None
    joints = st.singular_joints(J)
    return {
        "robot": robot.name,
        "q_deg": list(map(float, q_deg)),
        "q_model_deg": np.rad2deg(q).tolist(),
        "tool_mm": (np.asarray(tool_m) * 1e3).tolist(),
        "position_mm": (kin.tool_position(robot.dh, q, tool_m) * 1e3).tolist(),
        "jacobian": J.tolist(),
        "joint_stiffness_Nm_per_rad": k.tolist(),
        "compliance_mm_per_N": (C3 * 1e3).tolist(),
        "compliance_um_per_N_principal": (w * 1e6).tolist(),
        "principal_directions": V.T.tolist(),
        "stiffness_N_per_um": None if K3 is None else K3.tolist(),
        "stiffness_N_per_um_principal": [None if not np.isfinite(s) else float(s) for s in stiff_eig_N_per_um],
        "singular_joints": list(joints),
        "warnings": ([f"singular pose ({st.describe_singularity(joints)}): the stiffness along the lost direction "
                      "is unbounded and K_x does not exist"] if joints else []),
    }


def format_report(rep, robot):
    lines = []
    q = rep["q_deg"]
    lines.append(f"{robot.name}: q = [" + ", ".join(f"{v:.3f}" for v in q) + "] deg (controller convention)")
    t = rep["tool_mm"]
    lines.append(f"tool point in flange frame: ({t[0]:.1f}, {t[1]:.1f}, {t[2]:.1f}) mm")
    p = rep["position_mm"]
    lines.append(f"tool position (base frame):  x {p[0]:10.3f}  y {p[1]:10.3f}  z {p[2]:10.3f}  mm")
    lines.append("joint stiffness (N*m/rad):   " + "  ".join(f"{v:.3g}" for v in rep["joint_stiffness_Nm_per_rad"]))
    if rep["singular_joints"]:
        lines.append("note: singular pose, " + st.describe_singularity(rep["singular_joints"])
                     + "; K_x (6x6) does not exist, the compliance form below still holds")
    lines.append("")
    lines.append("translational compliance C (um/N), conventional model C = Jv Cq Jv^T:")
    lines.append("            Fx         Fy         Fz")
    C = np.asarray(rep["compliance_mm_per_N"]) * 1e3
    for name, row in zip("xyz", C):
        lines.append(f"  d{name}  " + " ".join(f"{v:10.4f}" for v in row))
    K = rep["stiffness_N_per_um"]
    lines.append("")
    if K is None:
        lines.append("translational stiffness: not defined (C is singular at this pose)")
    else:
        lines.append("translational stiffness K = C^-1 (N/um), moments free:")
        lines.append("            dx         dy         dz")
        for name, row in zip("xyz", np.asarray(K)):
            lines.append(f"  F{name}  " + " ".join(f"{v:10.4f}" for v in row))
    lines.append("")
    lines.append("principal directions (base frame), softest last:")
    lines.append("   compliance um/N   stiffness N/um   direction")
    for c, s, d in zip(rep["compliance_um_per_N_principal"], rep["stiffness_N_per_um_principal"],
                       rep["principal_directions"]):
        s_txt = "inf" if s is None else f"{s:.4f}"
        lines.append(f"   {c:15.4f}   {s_txt:>14}   ({d[0]:+.3f}, {d[1]:+.3f}, {d[2]:+.3f})")
    return "\n".join(lines)


def run(*, q, tool=None, kx=False, json_out=None, robot_yaml=None):
    check_outputs(inputs=[robot_yaml], files={"--json": json_out})
    robot = load_robot(robot_yaml)
    q_deg = parse_q_deg(q)
    robot.check_q_deg(q_deg, where="stiffness")
    tool_m = robot.tool_point(parse_tool(tool), where="stiffness")
    rep = pose_report(robot, q_deg, tool_m)
    from robstiff_drake.io import Warnings

    rep["warnings"] = list(Warnings()) + rep["warnings"]  # an input's first (a --tool in metres)
    if kx:
        J = np.asarray(rep["jacobian"])
        try:
            Kx = st.cartesian_stiffness(J, robot.joint_stiffness_Nm_per_rad)
        except SingularPoseError as e:
            if json_out != "-":
                print(format_report(rep, robot))
            raise InputError(f"stiffness --kx: {e}") from None
        rep["cartesian_stiffness_6x6"] = Kx.tolist()
    if json_out is not None:
        emit_json(rep, json_out)
    if json_out != "-":
        print(format_report(rep, robot))
        if kx:
            print("\nK_x (6x6; rows/cols: x y z [N/m], rx ry rz [N*m/rad]):")
            for row in rep["cartesian_stiffness_6x6"]:
                print("  " + " ".join(f"{v:11.4g}" for v in row))
    wrote(json_out, to_stderr=json_out == "-")
    return 0
