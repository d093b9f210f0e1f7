"""``robstiff compensate`` and the gears' play (lost motion) a user has
identified: what the real-time chain does with it, said in one line at
the start and in summary.json.

The real-time chain (model/compensator.Compensator, cell/compensate.py)
predicts the deflection with the linear law dq = C J(q)^T W only: the
simulation's compensator applies the play's law too (model/compensator.
DeflectionModel with ``lost_motion_rad``: the smooth or the hysteretic
law, from the torque the gears already carry, gravity's, which the
diagram takes from the controller's model), but ``compensate`` does not.
Where the play sits is read from the inputs that can carry it: the
``--model`` JSON's keys (the names of a scenario's ``model:`` block:
``lost_motion_rad``, ``lost_motion_take_up_Nm``, ``lost_motion_law``,
``lost_motion_friction_Nm``) and ``--job``'s ``model.lost_motion_rad``.

How large the ignored twist is.  The play b of a joint shows only where
the torque its gear carries (gravity's holding torque minus the process
load's) changes sign: the link then crosses the gap, 2b in all, and the
linear law misses all of it; where the torque keeps its sign it is a
constant offset any static model absorbs (model/transmission.py).  So the
line gives, per joint with play, the bound 2b, the holding torque at the
start pose (the reference's first row: a process torque larger than it,
against it, reverses the gear) and the tool point's move for 2b there.
Without a reference the start pose is not known before the first
message: the bound alone.  (The job's process loads are not computed
here: outside preview mode ``compensate`` has no force plan.)

Plain numpy (model/arm_dynamics.ArmInertia's gravity torques, model/
kinematics' Jacobian): once, before any socket opens.
"""

import numpy as np

from robstiff_drake.errors import InputError
from robstiff_drake.model.compensator import PLAY_LAWS

# the ranges of a scenario's model block (diagrams/model_schema.ModelConfig), the same keys
MAX_PLAY_RAD = 0.01
TAKE_UP_RANGE_NM = (0.01, 1e4)
FRICTION_RANGE_NM = (0.0, 1000.0)
HOLD_SMALL_NM = 1.0  # a gear holding less gravity torque than this (N*m) is crossed by any process torque


def _six(doc, key, lo, hi, where):
    v = doc.get(key)
    if v is None or (isinstance(v, list) and not v):
        return None
    ok = (isinstance(v, list) and len(v) == 6
          and all(isinstance(x, (int, float)) and not isinstance(x, bool) and lo <= x <= hi for x in v))
    if not ok:
        raise InputError(f"{where}: {key}: expected six numbers in [{lo:g}, {hi:g}], got {str(v)[:80]}")
    return [float(x) for x in v]


def read_play(doc, where):
    """The play keys of a ``--model`` JSON object ``doc`` (None: no play,
    every b zero or the key absent): {"lost_motion_rad", "take_up_Nm",
    "law", "friction_Nm", "source"}; InputError (one line naming the file
    and key) for a value out of range."""
    if not isinstance(doc, dict):
        return None
    b = _six(doc, "lost_motion_rad", 0.0, MAX_PLAY_RAD, where)
    law = doc.get("lost_motion_law", "hysteretic")
    if law not in PLAY_LAWS:
        raise InputError(f"{where}: lost_motion_law: {str(law)[:40]!r}, expected one of {', '.join(PLAY_LAWS)}")
    take_up = _six(doc, "lost_motion_take_up_Nm", *TAKE_UP_RANGE_NM, where)
    friction = _six(doc, "lost_motion_friction_Nm", *FRICTION_RANGE_NM, where)
    if b is None or not any(b):
        return None
    return {"lost_motion_rad": b, "take_up_Nm": take_up, "law": law, "friction_Nm": friction,
            "source": f"{where}'s lost_motion_rad"}


def job_play(sc, job):
    """The play of ``--job``'s scenario model block (None: none)."""
    b = list(getattr(sc.model, "lost_motion_rad", []) or [])
    if not b or not any(b):
        return None
    return {"lost_motion_rad": [float(x) for x in b], "take_up_Nm": list(sc.model.lost_motion_take_up_Nm) or None,
            "law": sc.model.lost_motion_law, "friction_Nm": list(sc.model.lost_motion_friction_Nm) or None,
            "source": f"--job {job}'s model.lost_motion_rad"}


def play_note(robot, play, q_start_ctrl_deg=None, start_what="the start pose"):
    """(the one line, the dict for summary.json) saying that the play
    ``play`` (``read_play``'s) is not compensated and how large the twist
    the linear chain ignores is (see the module docstring);
    ``q_start_ctrl_deg``: the start pose (controller degrees; None: not
    known yet); (None, None) without play."""
    if play is None:
        return None, None
    from robstiff_drake.model import kinematics as kin
    from robstiff_drake.model.arm_dynamics import ArmInertia

    b = np.asarray(play["lost_motion_rad"], dtype=float)
    joints = [j for j in range(6) if b[j] > 0.0]
    out = {"compensated": False, "source": play["source"], "law": play["law"], "lost_motion_rad": b.tolist(),
           "ignored_twist_bound_rad": (2.0 * b).tolist(), "start_pose_deg": None, "holding_torque_Nm": None,
           "tool_move_bound_mm": None}
    parts = []
    if q_start_ctrl_deg is not None:
        q = robot.joint_map.to_model(np.radians(np.asarray(q_start_ctrl_deg, dtype=float)))
        hold = ArmInertia(robot).gravity_torques(q)  # the torque gravity puts on each joint; the gears hold it
        J = kin.jacobian(robot.dh, q, robot.payload.tool_point_m)
        move_mm = np.linalg.norm(J[:3], axis=0) * 2.0 * b * 1e3  # the tool point's move for 2b on each joint alone
        out.update(start_pose_deg=[float(v) for v in q_start_ctrl_deg], holding_torque_Nm=np.abs(hold).tolist(),
                   tool_move_bound_mm=move_mm.tolist())
        for j in joints:
            h = abs(hold[j])
            when = (f"a process torque of either sign takes its gear across (it holds {h:.1f} N*m of gravity there)"
                    if h < HOLD_SMALL_NM else f"a process torque over the {h:.0f} N*m gravity holding torque, "
                                              "against it, takes its gear across")
            parts.append(f"q{j + 1}: up to {2e6 * b[j]:.0f} urad ({move_mm[j] * 1e3:.0f} um at the tool point) where "
                         + when)
        where = f" at {start_what}"
    else:
        parts = [f"q{j + 1}: up to {2e6 * b[j]:.0f} urad where its gear's torque reverses" for j in joints]
        where = " (the start pose not known before the controller's first message)"
    line = (f"the gears' play ({play['source']}, {play['law']} law) is NOT compensated: the real-time chain is "
            f"linear (C J^T W); the twist it ignores{where}: " + "; ".join(parts))
    out["line"] = line
    return line, out
