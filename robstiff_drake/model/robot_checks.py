"""Is a robot file's physics plausible?  Checks of a RobotModel that a file
can pass key by key and still be no robot: link masses no material makes,
centres of mass outside their link, inertias far from the link's size, a
first natural mode no machining arm has, and joints too soft to hold the
arm up (a stiffness written in kN*m/rad).  ``plausibility`` returns one-line
warnings and raises InputError for the impossible.

The rigid-body quantities (joint-space mass matrix, gravity torques) are
model/arm_dynamics.ArmInertia's (plain numpy; tests/test_robot_file_schema.py
checks them against Drake's MultibodyPlant).
"""

import numpy as np

from robstiff_drake.errors import InputError
from robstiff_drake.model.arm_dynamics import ArmInertia
from robstiff_drake.model.stiffness_rule import extrapolated_rule_warning

# Densities a link's mass over its shape's volume can have (kg/m^3): a
# robot link is a hollow casting or weldment with motors and gears inside;
# the library's arms lie at 1,200-3,200.  Below 50 is lighter than any
# structure (a mass in tonnes?); above 1.2 times solid steel's 7,850 no
# material holds it (a mass in grams, or a shape far too small).
DENSITY_RANGE_KG_PER_M3 = (50.0, 1.2 * 7850.0)
# A published inertia tensor whose trace is this far from the link shape's
# (either way) is in other units (g*mm^2, kg*mm^2) or of another body; the
# KUKA's published tensors lie within 0.5-2.5 of their shapes'.
INERTIA_FACTOR = 10.0
# The first natural frequency (joint springs, motors held) of a machining
# robot: 4.9 Hz for the IRB6400 here; published modal tests of large arms
# report 5-20 Hz.  Outside 2-40 Hz the stiffness or the masses are off.
FIRST_MODE_RANGE_HZ = (2.0, 40.0)
# The joint springs' deflection under the arm's own weight: a few mrad for
# a real arm; beyond 0.1 rad (5.7 deg) no arm could hold its pose (a
# stiffness in kN*m/rad reads 1000 times too soft).
MAX_GRAVITY_SAG_RAD = 0.1
# A centre of mass this much beyond its link's segment and housing (m) is
# not on the link (the margin is the housing's half-diagonal, at least 0.1 m).
MIN_COM_MARGIN_M = 0.1


def first_modes_hz(robot, q_rad):
    """Undamped natural frequencies (Hz) of the joint springs at ``q_rad``
    (motors held), ascending."""
    M = ArmInertia(robot).mass_matrix(q_rad)
    w2 = np.linalg.eigvals(np.linalg.solve(M, np.diag(robot.joint_stiffness_Nm_per_rad))).real
    return np.sort(np.sqrt(np.maximum(w2, 0.0))) / (2 * np.pi)


def reference_pose(robot):
    """(model angles rad, words) where the checks look at the arm: the
    machining workspace's reference tool point, spindle down (IK); the
    middle of the working ranges when that cannot be reached."""
    from robstiff_drake.model.ik import IKError, solve_for, tool_down_pose

    tool = robot.payload.tool_point_m if robot.payload.tool_point_m is not None else np.zeros(3)
    try:
        q = solve_for(robot, tool_down_pose(robot.workspace.reference_tool_point_m), tool)
        return q, "at the reference machining pose"
    except (IKError, ValueError, np.linalg.LinAlgError):
        lo, hi = robot.model_limits_rad
        return 0.5 * (lo + hi), "at the middle of the working ranges"


def _shape_volume_m3(link):
    if link.shape == "box":
        return float(np.prod(link.size_m))
    radius, length = link.size_m[0], link.size_m[1]
    return float(np.pi * radius**2 * length)


def shape_inertia(mass_kg, shape, size_m, axis="z"):
    """(3, 3) inertia (kg m^2) about the centre of a solid box (size_m: the
    three sides) or cylinder (size_m: radius, length; along ``axis``)."""
    m = mass_kg
    if shape == "box":
        a, b, c = size_m
        return np.diag([m * (b * b + c * c), m * (a * a + c * c), m * (a * a + b * b)]) / 12.0
    radius, length = size_m[0], size_m[1]
    diag = [m * (3 * radius**2 + length**2) / 12.0] * 3
    diag["xyz".index(axis)] = 0.5 * m * radius**2
    return np.diag(diag)


def _shape_inertia(link):
    return shape_inertia(link.mass_kg, link.shape, link.size_m, link.cylinder_axis)


def _half_diagonal_m(link):
    if link.shape == "box":
        return 0.5 * float(np.linalg.norm(link.size_m))
    return 0.5 * float(np.hypot(2 * link.size_m[0], link.size_m[1]))


def _segment_distance(p, b):
    """Distance (m) of point p from the segment from the origin to b."""
    bb = float(b @ b)
    t = 0.0 if bb == 0 else float(np.clip(p @ b / bb, 0.0, 1.0))
    return float(np.linalg.norm(p - t * b))


def link_warnings(robot):
    """Masses, centres of mass and inertias of the links (one line each)."""
    out = []
    src = robot.source
    lo, hi = DENSITY_RANGE_KG_PER_M3
    for i, link in enumerate(robot.links):
        key = f"links[{i}] ({link.name})"
        rho = link.mass_kg / _shape_volume_m3(link)
        if not lo <= rho <= hi:
            out.append(f"{src}: {key}: {link.mass_kg:g} kg in a {link.shape} of {_shape_volume_m3(link):.3g} m^3 is "
                       f"{rho:.3g} kg/m^3, outside the {lo:g}-{hi:g} a robot link can have (mass in other units, "
                       "or the shape's size?)")
        if i > 0:  # the base has no segment: its joint 1 sits at its frame's origin
            seg = np.array([robot.dh.a_m[i - 1], 0.0, robot.dh.d_m[i - 1]])
            margin = max(_half_diagonal_m(link), MIN_COM_MARGIN_M)
            d = _segment_distance(link.com_m, seg)
            if d > margin:
                out.append(f"{src}: {key}: the centre of mass {np.round(link.com_m * 1e3, 1).tolist()} mm is "
                           f"{d * 1e3:.0f} mm from the link's segment to the next joint (0 to "
                           f"{np.round(seg * 1e3, 1).tolist()} mm), beyond its housing ({margin * 1e3:.0f} mm)")
        ratio = np.trace(link.inertia_kgm2) / np.trace(_shape_inertia(link))
        if not 1 / INERTIA_FACTOR <= ratio <= INERTIA_FACTOR:
            out.append(f"{src}: {key}: inertia_kgm2 is {ratio:.3g} times that of the link's {link.shape} (other "
                       "units, e.g. kg*mm^2, or another body's tensor?)")
    return out


def largest_compliance_um_per_N(robot, q_rad):
    """The tool point's largest translational compliance (um/N) at ``q_rad``:
    the largest eigenvalue of model/stiffness.translational_compliance (the
    conventional model, Jv diag(1/k) Jv^T)."""
    from robstiff_drake.model import kinematics as kin
    from robstiff_drake.model.stiffness import translational_compliance

    tool = robot.payload.tool_point_m if robot.payload.tool_point_m is not None else np.zeros(3)
    C = translational_compliance(kin.jacobian(robot.dh, q_rad, tool), robot.joint_stiffness_Nm_per_rad)
    return float(np.linalg.eigvalsh(C)[-1]) * 1e6


def plausibility(robot):
    """Warnings (one line each) about a robot file's physics; InputError
    when its joints could not hold the arm up (see MAX_GRAVITY_SAG_RAD)."""
    out = link_warnings(robot)
    q, where = reference_pose(robot)
    sag = np.abs(ArmInertia(robot).gravity_torques(q)) / robot.joint_stiffness_Nm_per_rad
    j = int(np.argmax(sag))
    if sag[j] > MAX_GRAVITY_SAG_RAD:
        raise InputError(f"{robot.source}: key 'joint_stiffness_Nm_per_rad': joint {j + 1}: "
                         f"{robot.joint_stiffness_Nm_per_rad[j]:g} N*m/rad lets the arm sag "
                         f"{np.rad2deg(sag[j]):.3g} deg under its own weight {where}: no arm holds itself so "
                         "softly; are the stiffnesses in kN*m/rad? (write N*m/rad)")
    try:
        f1 = float(first_modes_hz(robot, q)[0])
    except np.linalg.LinAlgError:  # a mass matrix that cannot be inverted: no inertia on some joint
        f1 = 0.0
    rule = extrapolated_rule_warning(robot, largest_compliance_um_per_N(robot, q))
    if rule:
        out.append(rule)
    lo, hi = FIRST_MODE_RANGE_HZ
    if not lo <= f1 <= hi:
        out.append(f"{robot.source}: the first natural frequency {where} is {f1:.3g} Hz (joint springs, motors "
                   f"held), outside the {lo:g}-{hi:g} Hz of machining robots: check joint_stiffness_Nm_per_rad and "
                   "the link masses")
    return out
