"""``robstiff import-urdf ROBOT.urdf --out ROBOT.yaml``: a robot file from a
URDF (robstiff_drake/robot_import.py), checked after writing: the written
file's kinematics against Drake's plant of the URDF (the flange at random
configurations inside the limits) and its links' masses and inertias
against the URDF's, in the base frame."""

import json

import numpy as np

from robstiff_drake.errors import InputError, excerpt, one_line
from robstiff_drake.io import check_outputs, write_atomic
from robstiff_drake.model import kinematics as kin
from robstiff_drake.model.robot import N_JOINTS, NAME_RE, load_robot
from robstiff_drake.progress import info
from robstiff_drake.robot_import import box_of, read_urdf

FK_TOL_M = 1e-12  # 1e-9 mm
INERTIA_TOL = 1e-9  # relative


def _row(values, scale=1.0):
    return "[" + ", ".join(f"{v * scale:.17g}" for v in values) + "]"


def parse_controller_map(text, template):
    """``--controller-map``: "template" (the template's controller block)
    or "S1,..,S6:O1,..,O6" (signs +-1, offsets deg: the URDF's angle is
    sign * the controller's + offset) -> (sign list, offset_deg list), or
    None without the option."""
    if text is None:
        return None
    if text.strip() == "template":
        jm = template.joint_map
        if jm.coupling:
            raise InputError(f"--controller-map template: {template.name}'s controller block has a coupling, which "
                             "import-urdf does not copy; write the controller block into the file by hand")
        return [float(v) for v in jm.sign], [float(v) for v in np.rad2deg(jm.offset_rad)]
    parts = text.split(":")
    if len(parts) != 2:
        raise InputError(f"--controller-map {excerpt(text)}: expected 'template' or S1,..,S6:O1,..,O6 (signs +-1, "
                         "offsets in deg: the URDF's angle = sign x the controller's + offset)")
    out = []
    for what, part in zip(("signs", "offsets"), parts):
        try:
            values = [float(v) for v in part.split(",")]
        except ValueError:
            raise InputError(f"--controller-map: the {what} {excerpt(part)} are not {N_JOINTS} numbers") from None
        if len(values) != N_JOINTS or not all(np.isfinite(values)):
            raise InputError(f"--controller-map: the {what} {excerpt(part)} are not {N_JOINTS} numbers")
        out.append(values)
    if any(v not in (-1.0, 1.0) for v in out[0]):
        raise InputError(f"--controller-map: the signs {excerpt(parts[0])} must each be 1 or -1")
    if any(abs(v) > 360.0 for v in out[1]):
        raise InputError(f"--controller-map: the offsets {excerpt(parts[1])} must be within +-360 deg")
    return out[0], out[1]


def robot_file_text(imp, template, urdf_path, name, controller=None):
    """The robot file (YAML text) of an ImportedRobot, the rest from
    ``template`` (a RobotModel); ``controller``: (sign, offset_deg) of the
    controller block, None for none."""
    d, a, alpha, home, alpha0, a0 = imp.dh_rows
    if imp.convention == "modified_dh":  # rows (alpha_{i-1}, a_{i-1}, d_i, theta_i)
        a_rows, alpha_rows = np.r_[a0, a[:5]], np.r_[alpha0, alpha[:5]]
    else:
        a_rows, alpha_rows = a, alpha
    t = template
    lines = [
        f"# Imported from {one_line(urdf_path)} (sha256 {imp.digest[:16]}) by `robstiff import-urdf`:",
        "# the kinematic table from its joint axes, the links' masses and inertias moved into",
        "# the robot file's link frames, the joint limits.  The model's joint angles are the URDF's;"]
    lines += (["# no controller block: check them against your controller's (docs/your_robot.md), or",
               "# give import-urdf --controller-map."] if controller is None else
              ["# the controller block maps the controller's angles to them (--controller-map)."])
    lines += [
        f"# The flange is the URDF's frame '{imp.flange_frame}'.  Each link's box is a stand-in: the",
        "# solid box of its inertia (the URDF's meshes are not read)."]
    lines += [f"# Absorbed: {one_line(n)}" for n in (imp.notes or [])]
    lines += [
        f"name: {name}",
        "manufacturer: \"-\"",
        f"model: {imp.name}",
        f"source: {json.dumps('imported from ' + urdf_path.name)}",  # any file name: a quoted YAML scalar
        f"convention: {imp.convention}",
        "dh:",
        f"  d_mm: {_row(d, 1e3)}",
        f"  a_mm: {_row(a_rows, 1e3)}",
        f"  alpha_deg: {_row(np.rad2deg(alpha_rows))}",
        f"  home_deg: {_row(np.rad2deg(home))}",
    ]
    lower, upper = np.rad2deg(imp.lower_rad), np.rad2deg(imp.upper_rad)
    if controller is not None:
        lines += ["controller:", f"  sign: {_row(controller[0])}", f"  offset_deg: {_row(controller[1])}"]
        sign, offset = np.asarray(controller[0]), np.asarray(controller[1])
        # the limits in the controller's angles (the URDF's angle = sign x the controller's + offset)
        lower, upper = np.minimum((lower - offset) * sign, (upper - offset) * sign), \
            np.maximum((lower - offset) * sign, (upper - offset) * sign)
    lines += [
        "joint_limits:" + ("  # the controller's angles" if controller is not None else ""),
        f"  lower_deg: {_row(lower)}",
        f"  upper_deg: {_row(upper)}",
        "# ASSUMPTION: a URDF holds no joint stiffness, motor inertias, machining payload or",
        f"# workspace: these are {t.name}'s ({one_line(t.source)}).  Identify your robot's stiffness",
        "# (robstiff identify), and set its motors, payload and workspace here.",
        f"joint_stiffness_Nm_per_rad: {_row(t.joint_stiffness_Nm_per_rad)}",
    ]
    if t.motor_inertia_kgm2 is not None:
        lines.append(f"motor_inertia_kgm2: {_row(t.motor_inertia_kgm2)}")
    lines.append("links:")
    for link in imp.links:
        I = link.inertia_kgm2
        lines += [f"  - name: {link.name}",
                  f"    mass_kg: {link.mass_kg:.17g}",
                  f"    com_mm: {_row(link.com_m, 1e3)}",
                  f"    box_mm: {_row(box_of(link.mass_kg, I), 1e3)}",
                  f"    inertia_kgm2: {_row([I[0, 0], I[1, 1], I[2, 2], I[0, 1], I[0, 2], I[1, 2]])}"]
    pl = t.payload
    mass, com = (imp.payload.mass_kg, imp.payload.com_m) if imp.payload is not None else (pl.mass_kg, pl.com_m)
    lines += ["payload:" + ("  # the URDF's spindle body" if imp.payload is not None else f"  # {t.name}'s"),
              f"  mass_kg: {mass:.17g}", f"  com_mm: {_row(com, 1e3)}"]
    if pl.tool_point_m is not None:
        lines.append(f"  tool_point_mm: {_row(pl.tool_point_m, 1e3)}")
    ws = t.workspace
    lines += ["machining_workspace:",
              f"  x_mm: {_row(ws.x_m, 1e3)}", f"  y_mm: {_row(ws.y_m, 1e3)}", f"  z_mm: {_row(ws.z_m, 1e3)}",
              f"  reference_tool_point_mm: {_row(ws.reference_tool_point_m, 1e3)}"]
    return "\n".join(lines) + "\n"


def world_inertias(robot, q, with_payload=False):
    """[(mass, com (3,), inertia about it (3, 3))] of each link (and the
    payload) in the base frame at model angles q: the robot file's link
    frames moved by the chain."""
    T = kin.frames(robot.dh, q)
    out = []
    for i, link in enumerate(robot.links):
        X = np.eye(4) if i == 0 else T[i - 1].copy()
        if i:
            th = q[i - 1] + robot.dh.home_rad[i - 1]
            c, s = np.cos(th), np.sin(th)
            X[:3, :3] = X[:3, :3] @ np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        R = X[:3, :3]
        out.append((link.mass_kg, X[:3, 3] + R @ link.com_m, R @ link.inertia_kgm2 @ R.T))
    if with_payload:
        pl, R = robot.payload, T[6, :3, :3]
        out.append((pl.mass_kg, T[6, :3, 3] + R @ pl.com_m, R @ pl.inertia_about_com_kg_m2 @ R.T))
    return out


def about_origin(parts):
    """(mass, first moment (3,), rotational inertia about the origin (3, 3))."""
    m = sum(p[0] for p in parts)
    h = sum(p[0] * p[1] for p in parts)
    I = sum(p[2] + p[0] * (np.dot(p[1], p[1]) * np.eye(3) - np.outer(p[1], p[1])) for p in parts)
    return m, h, I


def check_against_urdf(imp, robot, n=20):
    """(flange error m, largest relative error of the mass, first moment and
    rotational inertia about the base origin) of the written robot file
    against Drake's plant of the URDF at n configurations in the limits."""
    plant = imp.plant
    ctx = plant.CreateDefaultContext()
    flange = plant.GetFrameByName(imp.flange_frame)
    bodies = [b for b in plant.GetBodyIndices(plant.GetModelInstanceByName(imp.instance_name))]
    rng = np.random.default_rng(0)  # fixed: the same check every time
    worst_fk, worst_I = 0.0, 0.0
    for q in rng.uniform(imp.lower_rad, imp.upper_rad, size=(n, N_JOINTS)):
        plant.SetPositions(ctx, q)
        p = plant.CalcRelativeTransform(ctx, plant.world_frame(), flange).translation()
        worst_fk = max(worst_fk, float(np.abs(p - kin.tool_position(robot.dh, q)).max()))
        M = plant.CalcSpatialInertia(ctx, plant.world_frame(), bodies)
        theirs = (M.get_mass(), M.get_mass() * M.get_com(), M.CalcRotationalInertia().CopyToFullMatrix3())
        mine = about_origin(world_inertias(robot, q, with_payload=imp.payload is not None))
        for a, b in zip(mine, theirs):
            worst_I = max(worst_I, float(np.max(np.abs(np.asarray(a) - b)) / max(np.max(np.abs(b)), 1e-12)))
    return worst_fk, worst_I


def template_agreement_mm(robot, template, n=20):
    """The largest distance (mm) between the flanges of ``robot`` and
    ``template`` at the same controller angles inside both's limits: how
    well a template's controller map fits the imported arm (0 for the same
    robot)."""
    lo = np.maximum(robot.q_lower_rad, template.q_lower_rad)
    hi = np.minimum(robot.q_upper_rad, template.q_upper_rad)
    if np.any(lo >= hi):
        return None
    q = np.random.default_rng(0).uniform(lo, hi, size=(n, N_JOINTS))
    return float(np.max(np.linalg.norm(kin.tool_position(robot.dh, robot.joint_map.to_model(q))
                                       - kin.tool_position(template.dh, template.joint_map.to_model(q)), axis=1)) * 1e3)


def run(*, urdf, out, template=None, name=None, controller_map=None):
    from pathlib import Path

    urdf_path = Path(urdf)
    check_outputs(inputs=[urdf_path], files={"--out": out})
    if name is not None and not NAME_RE.fullmatch(name):
        raise InputError(f"--name {excerpt(name)}: use letters, digits and _ only, starting with a letter (it names "
                         "files and the URDF)")
    tpl = load_robot(template)
    controller = parse_controller_map(controller_map, tpl)
    imp = read_urdf(urdf_path)
    text = robot_file_text(imp, tpl, urdf_path, name or imp.name, controller)
    # the file is read back and checked before it is written (a failed check leaves nothing behind)
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        draft = Path(tmp) / Path(out).name
        draft.write_text(text, encoding="utf-8")
        robot = load_robot(str(draft))
    fk, inertia = check_against_urdf(imp, robot)
    if fk > FK_TOL_M or inertia > INERTIA_TOL:
        raise InputError(f"{out}: the robot file made from the URDF misses its flange by {fk * 1e3:.3g} mm and its "
                         f"inertia by {inertia:.3g} (relative); nothing written: please report this URDF")
    write_atomic(Path(out), text)
    for note in imp.notes or []:
        info(f"absorbed: {note}")
    info(f"wrote {out}: {imp.convention}, flange within {fk * 1e3:.2g} mm of the URDF's, mass and inertia about the "
         f"base within {inertia:.2g} (relative), at 20 configurations; joint stiffness, motors and workspace from "
         f"{tpl.name}")
    if controller_map is not None and controller_map.strip() == "template":
        agree = template_agreement_mm(robot, tpl)
        info(f"controller map from {tpl.name}: " + ("no controller angles inside both's limits" if agree is None else
             f"at the same controller angles its flange and {tpl.name}'s are within {agree:.3g} mm"
             + ("" if agree < 1.0 else f" (another arm, or another zero than {tpl.name}'s: check the map)")))
    elif controller_map is None:
        info("the joint angles are the URDF's: give --controller-map (template, or the signs and offsets) for your "
             "controller's")
    return 0
