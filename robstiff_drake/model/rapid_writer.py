"""An ABB RAPID module of a corrected program: one motion instruction per
written block, the targets with the orientation and axis configuration
the project's IK gives there.  Plain Python; no Drake.

RAPID features used (RAPID Reference Manual, IRC5 / OmniCore): a program
module (``MODULE ... ENDMODULE``) with one ``PROC main()``; a ``PERS
tooldata`` (the tool point in the flange frame, orientation that of the
flange, the payload's mass and centre of mass); a ``PERS wobjdata`` (the
work object: the program's zero and its turn about the base z axis, user
frame fixed, robot not holding it); ``CONST speeddata`` per feed (mm/s)
and for rapids; one ``CONST zonedata`` (the path zone, ABB's z-data
proportions: orientation and external-axis zones 1.6 times the TCP zone);
``MoveL`` to inline ``robtarget``s, and ``MoveC`` (a circle point halfway
along the arc, then its end) for arcs; ``!`` comments.  No external axes
(9E9).  Numbers: mm and quaternions (q1 the scalar part), as RAPID's.

The axis configuration ``[cf1, cf4, cf6, cfx]``: cf1, cf4, cf6 the quadrant
(floor(angle / 90 deg)) of axes 1, 4 and 6 in the controller's angles;
cfx (ABB's serial-arm convention, 0-7) = 4 * (wrist centre behind axis 1)
+ 2 * (wrist centre behind the lower arm) + (axis 5 negative)."""

import math
from dataclasses import dataclass

import numpy as np

IDENT_MAX = 32  # RAPID identifiers: at most 32 characters


@dataclass
class Target:
    """One motion: kind "line" or "arc" (then ``via_mm``, ``via_quat``,
    ``via_conf``), the end point (mm, work frame), its quaternion (q1 scalar,
    work frame), its configuration [cf1, cf4, cf6, cfx], the speed (mm/s),
    whether it is a rapid, and the program line it comes from."""

    kind: str
    pos_mm: np.ndarray
    quat: np.ndarray
    conf: tuple
    speed_mm_per_s: float
    rapid: bool
    line: int
    via_mm: np.ndarray = None
    via_quat: np.ndarray = None
    via_conf: tuple = None


def quaternion(R, previous=None):
    """[q1 (scalar), q2, q3, q4] of rotation matrix R, unit norm: of its two
    signs the one nearer ``previous`` (a path's quaternions without sign
    flips), else the one with q1 >= 0."""
    from scipy.spatial.transform import Rotation

    x, y, z, w = Rotation.from_matrix(np.asarray(R, dtype=float)).as_quat()
    q = np.array([w, x, y, z])
    if previous is not None:
        return q if float(q @ np.asarray(previous, dtype=float)) >= 0 else -q
    return q if q[0] >= 0 else -q


def configuration(q_ctrl_deg, wrist_centre_m, shoulder_m, lower_arm_dir, axis2_dir):
    """ABB confdata [cf1, cf4, cf6, cfx] of controller angles (deg) and the
    wrist centre (m, base frame); ``shoulder_m`` a point on axis 2,
    ``lower_arm_dir`` the lower arm's direction, ``axis2_dir`` axis 2's."""
    q = np.asarray(q_ctrl_deg, dtype=float)
    cf1, cf4, cf6 = (int(math.floor(q[i] / 90.0)) for i in (0, 3, 5))
    a1 = math.radians(q[0])
    forward = np.array([math.cos(a1), math.sin(a1), 0.0])
    behind_axis1 = float(np.asarray(wrist_centre_m)[:2] @ forward[:2]) < 0.0
    r = np.asarray(wrist_centre_m) - np.asarray(shoulder_m)
    behind_lower_arm = float(np.cross(lower_arm_dir, r) @ axis2_dir) > 0.0
    cfx = 4 * int(behind_axis1) + 2 * int(behind_lower_arm) + int(q[4] < 0.0)
    return cf1, cf4, cf6, cfx


def _num(v, d=4):
    text = f"{v:.{d}f}".rstrip("0").rstrip(".")
    return "0" if text in ("-0", "") else text


def _robtarget(pos, quat, conf):
    p = ",".join(_num(v) for v in pos)
    q = ",".join(_num(v, 8) for v in quat)
    c = ",".join(str(int(v)) for v in conf)
    return f"[[{p}],[{q}],[{c}],[9E9,9E9,9E9,9E9,9E9,9E9]]"


def module_name(stem):
    """A RAPID identifier from a file stem (letters, digits, _; a letter first)."""
    name = "".join(ch if ch.isascii() and (ch.isalnum() or ch == "_") else "_" for ch in stem)
    if not name or not name[0].isalpha():
        name = "m_" + name
    return name[:IDENT_MAX]


def module_text(name, targets, *, tool_mm, payload_mass_kg, payload_com_mm, wobj_mm, wobj_quat, zone_mm,
                header_lines=()):
    """The RAPID module (text) running ``targets`` (Target list)."""
    speeds = {}
    for t in targets:
        key = round(t.speed_mm_per_s, 3)
        speeds.setdefault(key, f"vRapid{len(speeds)}" if t.rapid else f"vFeed{len(speeds)}")
    z = max(float(zone_mm), 0.0)
    out = [f"MODULE {module_name(name)}"]
    out += [f"  ! {h}" for h in header_lines]
    tool = ",".join(_num(v) for v in tool_mm)
    com = ",".join(_num(v) for v in payload_com_mm)
    out.append(f"  PERS tooldata tSpindle := [TRUE,[[{tool}],[1,0,0,0]],[{_num(payload_mass_kg)},[{com}],[1,0,0,0],"
               "0,0,0]];")
    wo = ",".join(_num(v) for v in wobj_mm)
    wq = ",".join(_num(v, 8) for v in wobj_quat)
    out.append(f"  PERS wobjdata wPart := [FALSE,TRUE,\"\",[[{wo}],[{wq}]],[[0,0,0],[1,0,0,0]]];")
    for v, ident in speeds.items():
        out.append(f"  CONST speeddata {ident} := [{_num(v, 3)},500,5000,1000];")
    zone = "fine" if z == 0 else "zProg"
    if z > 0:
        out.append(f"  CONST zonedata zProg := [FALSE,{_num(z, 3)},{_num(1.6 * z, 3)},{_num(1.6 * z, 3)},"
                   f"{_num(0.16 * z, 3)},{_num(1.6 * z, 3)},{_num(0.16 * z, 3)}];")
    out.append("  PROC main()")
    line = None
    for t in targets:
        if t.line != line:
            out.append(f"    ! program line {t.line}")
            line = t.line
        v = speeds[round(t.speed_mm_per_s, 3)]
        if t.kind == "arc":
            out.append(f"    MoveC {_robtarget(t.via_mm, t.via_quat, t.via_conf)},{_robtarget(t.pos_mm, t.quat, t.conf)},"
                       f"{v},{zone},tSpindle\\WObj:=wPart;")
        else:
            out.append(f"    MoveL {_robtarget(t.pos_mm, t.quat, t.conf)},{v},{zone},tSpindle\\WObj:=wPart;")
    out.append("  ENDPROC")
    out.append("ENDMODULE")
    return "\n".join(out) + "\n"
