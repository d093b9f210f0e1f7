"""The preview's table (cell/preview_job.build_plan's PreviewPlan) kept on
disk by its content, and computed in a process of its own while
`compensate --mode preview` waits for and then answers the controller.

The key is what the table depends on: the job as read (the scenario's
every setting: its cutting model, tool, servo, damping, sensor and path
sections), its planned path (the reference's times and joint angles: the
program's geometry and feeds), the robot file's content, the compensator's
numbers (the identified stiffness, the controller period, the force
filter, the sensor rate, the delay line, --servo) and the source of the
modules that compute it.  A file that cannot be read, or holds anything
else, is computed again; one that cannot be written is skipped.  Files go
in plant.cache_dir(), written to a temporary file and renamed
(diagrams/reference_cache.py does the same for the path's IK).

``python -m robstiff_drake.cell.preview_build`` (the background build,
``BUILD_MODULE``; a module of its own above cell/preview_job.py, so this
one imports nothing of the job's) reads its inputs as JSON on stdin, builds the table and writes the file;
it runs at normal scheduling in its own interpreter, so the loop's
real-time thread never shares Python's lock with the hours of arithmetic
a long job's table can take.
"""

import hashlib
import io
import json
import sys

import numpy as np

# the modules whose code the table depends on: a change in any makes the cached files stale
CODE = ("robstiff_drake.cell.preview_job", "robstiff_drake.cell.preview_table", "robstiff_drake.model.preview",
        "robstiff_drake.systems.preview_correction", "robstiff_drake.diagrams.scenario_models",
        "robstiff_drake.diagrams.user_model", "robstiff_drake.diagrams.milling_cell",
        "robstiff_drake.model.arm_dynamics", "robstiff_drake.model.realtime", "robstiff_drake.model.kinematics",
        "robstiff_drake.model.robot", __name__)
ARRAYS = ("u", "c", "replica", "sensor", "q_plan_deg", "v_plan_deg_per_s", "t_ref_s", "q_ref_deg")
NUMBERS = ("period_s", "lead_s", "lag_s", "expected_lag_s", "seconds")
SERVO = ("dead_time_s", "position_gain_per_s", "velocity_bandwidth_hz", "velocity_integral_hz")


def key(sc, robot, k_Nm_per_rad, t_ref_s, q_ref_rad, *, period_s, filter_ba, rate_hz, delay_steps, servo_option):
    """The hex digest naming the table of these inputs."""
    from robstiff_drake.plant import code_digest

    h = hashlib.sha256(code_digest(CODE).encode())
    h.update(repr(sc).encode())
    for part in (k_Nm_per_rad, t_ref_s, q_ref_rad, [period_s, rate_hz, delay_steps], *filter_ba):
        h.update(np.ascontiguousarray(part, dtype=float).tobytes())
    h.update(repr(None if servo_option is None else [float(v) for v in servo_option]).encode())
    try:
        with open(robot.source, "rb") as f:
            h.update(f.read())
    except (OSError, TypeError, ValueError):
        h.update(repr(robot.source).encode())
    return h.hexdigest()[:32]


def file_for(digest):
    """The cache file of a key (None: no writable cache folder)."""
    from robstiff_drake.errors import InputError
    from robstiff_drake.plant import cache_dir

    try:
        return cache_dir() / f"preview-table-{digest}.npz"
    except InputError:
        return None


def save(plan, file):
    """Write ``plan`` to ``file`` (atomically); False when it cannot be written."""
    from robstiff_drake.io import write_atomic

    buf = io.BytesIO()
    np.savez(buf, **{n: getattr(plan, n) for n in ARRAYS}, numbers=[getattr(plan, n) for n in NUMBERS],
             servo=[getattr(plan.servo, n) for n in SERVO])
    try:
        write_atomic(file, buf.getvalue())
        return True
    except OSError:
        return False


def load(file):
    """The PreviewPlan in ``file``; None when there is none or it is not one."""
    from robstiff_drake.cell.preview_table import PreviewPlan
    from robstiff_drake.model.preview import ServoModel

    if file is None:
        return None
    try:
        with np.load(file) as z:
            arrays = {n: np.array(z[n], dtype=float) for n in ARRAYS}
            numbers, servo = np.array(z["numbers"], dtype=float), np.array(z["servo"], dtype=float)
    except (OSError, ValueError, KeyError, EOFError):
        return None
    n = len(arrays["u"])
    if (numbers.shape != (len(NUMBERS),) or servo.shape != (len(SERVO),) or n < 1
            or arrays["c"].shape[0] != n or arrays["replica"].shape != arrays["c"].shape
            or not all(np.all(np.isfinite(a)) for a in arrays.values())):
        return None
    return PreviewPlan(**arrays, **dict(zip(NUMBERS, numbers.tolist())),
                       servo=ServoModel(**dict(zip(SERVO, servo.tolist()))))


BUILD_MODULE = "robstiff_drake.cell.preview_build"


def build_command():
    """The command line of the background build (its inputs go on stdin: ``build_input``)."""
    return [sys.executable, "-m", BUILD_MODULE]


def build_input(*, job, robot_yaml, k_Nm_per_rad, period_s, filter_ba, rate_hz, delay_steps, servo_option, file):
    return json.dumps({"job": str(job), "robot": None if robot_yaml is None else str(robot_yaml),
                       "k": [float(v) for v in k_Nm_per_rad], "period_s": float(period_s),
                       "filter_ba": [[float(v) for v in x] for x in filter_ba], "rate_hz": float(rate_hz),
                       "delay_steps": int(delay_steps),
                       "servo": None if servo_option is None else [float(v) for v in servo_option],
                       "file": str(file)})
