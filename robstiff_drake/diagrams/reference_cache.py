"""The joint references along a job's path (model/ik_path.joint_references:
IK every reference period), kept on disk by their content so that a job
run again (`compensate --mode preview --job`, `simulate`, a sweep) skips
the IK.

The key is what the IK's answer depends on: the tool points themselves
(every sample of the path, so any change of the program, its speeds or
the scenario's path section shows), the tool's yaw, the reference period,
the robot (its file's content, its chain, working ranges and joint map),
the tool offset, and the source of the modules that compute it.  A file
that cannot be read, or holds anything else, is computed again; one that
cannot be written is skipped.  Files go in plant.cache_dir()
($ROBSTIFF_CACHE_DIR, else $XDG_CACHE_HOME/robstiff-drake, else
~/.cache/robstiff-drake), written to a temporary file and renamed.
"""

import hashlib
import io

import numpy as np

from robstiff_drake.model import ik_path

# the modules whose code the references depend on: a change in any makes the cached files stale
CODE = ("robstiff_drake.model.ik", "robstiff_drake.model.ik_path", "robstiff_drake.model.kinematics",
        "robstiff_drake.model.robot", "robstiff_drake.model.stiffness", __name__)


def key(path, robot, tool_m, dt_s, q_start=None, points_m=None):
    """The hex digest naming the references of these inputs (``points_m``:
    the path's tool points at ik_path.sample_times, when known)."""
    from robstiff_drake.model.path import MIN_JACOBIAN_CONDITION

    from robstiff_drake.plant import code_digest

    h = hashlib.sha256(code_digest(CODE).encode())
    if points_m is None:
        points_m = path.positions(ik_path.sample_times(path, dt_s))
    h.update(np.ascontiguousarray(points_m, dtype=float).tobytes())
    h.update(np.array([path.yaw, dt_s, MIN_JACOBIAN_CONDITION], dtype=float).tobytes())
    h.update(np.asarray(np.zeros(3) if tool_m is None else tool_m, dtype=float).tobytes())
    h.update(b"-" if q_start is None else np.asarray(q_start, dtype=float).tobytes())
    try:
        with open(robot.source, "rb") as f:
            h.update(f.read())
    except (OSError, TypeError, ValueError):
        h.update(repr(robot.source).encode())
    dh = robot.dh
    for part in (dh.d_m, dh.a_m, dh.alpha_rad, dh.home_rad, dh.base, getattr(dh, "beta_rad", None),
                 robot.q_lower_rad, robot.q_upper_rad, robot.controller_deg(np.zeros(6)),
                 robot.controller_deg(np.eye(6))):
        h.update(b"-" if part is None else np.asarray(part, dtype=float).tobytes())
    return h.hexdigest()[:32]


def joint_references(path, robot, tool_m, dt_s, q_start=None):
    """(times (N,), q (N, 6) rad): model/ik_path.joint_references, from the
    disk cache when these inputs were solved before."""
    from robstiff_drake.errors import InputError
    from robstiff_drake.io import write_atomic
    from robstiff_drake.plant import cache_dir

    points = path.positions(ik_path.sample_times(path, dt_s))
    try:
        file = cache_dir() / f"joint-references-{key(path, robot, tool_m, dt_s, q_start, points)}.npz"
    except InputError:  # no writable cache folder: the IK as usual
        file = None
    if file is not None:
        try:
            with np.load(file) as z:
                ts, qs = np.array(z["t_s"], dtype=float), np.array(z["q_rad"], dtype=float)
            if qs.shape == (len(ts), 6) and np.all(np.isfinite(qs)):
                return ts, qs
        except (OSError, ValueError, KeyError, EOFError):
            pass
    ts, qs = ik_path.joint_references(path, robot, tool_m, dt_s, q_start, points_m=points)
    if file is not None:
        buf = io.BytesIO()
        np.savez(buf, t_s=ts, q_rad=qs)
        try:
            write_atomic(file, buf.getvalue())
        except OSError:
            pass  # (no cache on disk: computed again next time)
    return ts, qs
