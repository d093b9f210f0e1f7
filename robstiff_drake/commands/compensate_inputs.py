"""``robstiff compensate``'s input files: the compensator's model (`robstiff
identify --json`), the joint reference it streams (a CSV, checked against
the robot's limits by cell/safety.py), and the wait for a reference a
simulated cell writes when it is ready, and whether the reference is a
corrected one (compensate-program's mark) as ``--reference-is-corrected``
says.  Each bad file is one line naming it (exit 2), before any socket
opens."""

import sys
import time
from pathlib import Path

import numpy as np

from robstiff_drake.errors import InputError, excerpt

# A model whose nominal stiffness differs from the robot file's by more
# than this (relative) was identified against another robot file.
NOMINAL_TOLERANCE = 1e-6


def json_doc(path, what):
    """A user's JSON file through the project's one reader (size, depth,
    one-line errors; user_files.py)."""
    from robstiff_drake.user_files import load_json, read_user_text

    return load_json(read_user_text(path, f"{what} file"), f"{what} {path}")


def read_model(path, robot):
    """The compensator's joint stiffness (N*m/rad) from `robstiff identify
    --json`'s file; InputError if it is not one, or is for another robot."""
    from robstiff_drake.diagrams.scenario_models import checked_joint_stiffness, numbers

    doc = json_doc(path, "--model")
    if not isinstance(doc, dict) or "joint_stiffness_Nm_per_rad" not in doc:
        raise InputError(f"--model {path}: no joint_stiffness_Nm_per_rad (write it with `robstiff identify DATA.csv "
                         "--json OUT`)")
    name = doc.get("robot")
    if name is not None and name != robot.name:
        raise InputError(f"--model {path}: identified for the robot {str(name)[:80]!r}, not for {robot.name!r} "
                         f"({robot.source})")
    nominal = doc.get("joint_stiffness_nominal_Nm_per_rad")
    try:
        if nominal is not None:
            nom = numbers(nominal)  # None for text, a dict or a ragged list
            if nom is None or nom.shape != (6,):
                raise InputError(f"--model {path}: joint_stiffness_nominal_Nm_per_rad: expected six numbers, got "
                                 f"{excerpt(nominal)}")
            if not np.allclose(nom, robot.joint_stiffness_Nm_per_rad, rtol=NOMINAL_TOLERANCE, atol=0):
                raise InputError(f"--model {path}: identified against another robot file (its nominal stiffness "
                                 f"{np.round(nom, 0).tolist()} is not {robot.name}'s "
                                 f"{np.round(robot.joint_stiffness_Nm_per_rad, 0).tolist()} N*m/rad)")
        return checked_joint_stiffness(doc["joint_stiffness_Nm_per_rad"], where=f"--model {path}")
    except RecursionError:  # a last guard: load_json bounds the depth
        raise InputError(f"--model {path}: nested too deeply to be a model file") from None


def read_reference(path, robot, period_s=0.004):
    """(times s from 0, q (N, 6) controller angles in rad) of a joint reference CSV:
    columns t_s, q1_deg .. q6_deg (header first; '#' lines are comments), read in one
    pass (cell/reference_file.py), checked by cell/safety.check_reference."""
    from robstiff_drake.cell.reference_file import read_reference_rows
    from robstiff_drake.cell.safety import check_reference

    t, q, numbers = read_reference_rows(path)
    check_reference(str(Path(path)), robot, t, q, period_s, numbers)
    t -= t[0]
    return t, np.radians(q, out=q)


def wait_for_file(path, wait_s, what="--reference"):
    """Wait up to ``wait_s`` for ``path`` to appear (a simulated cell
    writes it when it is ready), saying so once."""
    p = Path(path)
    if p.exists():
        return
    print(f"robstiff: compensate: waiting up to {wait_s:g} s for {what} {path} to appear", file=sys.stderr,
          flush=True)
    t_end = time.monotonic() + wait_s
    while not p.exists():
        if time.monotonic() > t_end:
            raise InputError(f"{what} {path}: no such file (waited {wait_s:g} s for it to appear)")
        time.sleep(0.05)


# What streaming a corrected reference with online compensation on top did on the plant: the deflection corrected
# twice.  docs/offline_compensation.md's results table (studies/offline_compensation.py, face_and_contour.yaml): the
# corrected program with online plain compensation on the whole measured wrench, against the corrected joint
# reference streamed with no online correction (surface error, mean and largest |e|, mm).
TWICE_FIGURES = ("the corrected program with online compensation of the whole measured wrench, on the plant: "
                 "+0.078 mm mean, 0.228 mm largest surface error, against -0.007 / 0.025 mm for the corrected joint "
                 "reference streamed alone; docs/offline_compensation.md's results table")
CORRECTED_FLAG = "--reference-is-corrected"


def check_reference_claim(reference, is_corrected):
    """The reference's corrected mark (cell/reference_file.corrected_mark)
    against ``--reference-is-corrected``: a marked file streamed with online
    compensation, or the flag on a file without the mark, is an InputError
    (one line).  Returns the correction's reason to be held at zero (the
    flag given, on a marked file), else None."""
    from robstiff_drake.cell.reference_file import corrected_mark

    mark = corrected_mark(reference)
    if mark and not is_corrected:
        raise InputError(f"--reference {reference}:{mark[0]}: a corrected reference (its mark there): its joint "
                         "references already carry the deflection's correction, and streaming it with online "
                         "compensation corrects the deflection twice (" + TWICE_FIGURES + "); stream "
                         f"it with {CORRECTED_FLAG} (the online correction held at zero), or compensate online "
                         "with the uncorrected path's reference; nothing was sent")
    if is_corrected and not mark:
        raise InputError(f"--reference {reference}: {CORRECTED_FLAG} but the file carries no corrected-reference "
                         "mark (a '# corrected_reference: ...' line before its header, as robstiff "
                         "compensate-program writes); streamed with the correction held at zero, an uncorrected "
                         f"reference is not compensated at all: drop {CORRECTED_FLAG} to compensate online, or "
                         "write the corrected reference with robstiff compensate-program; nothing was sent")
    if mark:
        return (f"--reference {Path(reference).name} is a corrected reference (its line {mark[0]}: the model's "
                f"deflection correction included; {CORRECTED_FLAG}): streamed as it is")
    return None


def endpoint_clash(controller, sensor, listen_port):
    """Why the controller (IP, port or None), the sensor (IP, port) and this
    compensator's UDP ``listen_port`` (0: any) cannot all be what they say,
    else None: the sensor at the controller's own address and port, or either
    of them at this PC's loopback address on the port it listens on (its
    datagrams would come from, or go to, this compensator itself)."""
    import ipaddress

    if controller[1] is not None and tuple(controller) == tuple(sensor):
        return (f"--controller and --netft name the same address and port ({sensor[0]}:{sensor[1]}): the robot "
                "controller and the force sensor are two devices")
    for what, (ip, p) in (("--netft", sensor), ("--controller", controller)):
        if listen_port and p == listen_port and ipaddress.ip_address(ip).is_loopback:
            return (f"{what} {ip}:{p} is this compensator's own --listen-port {listen_port} on this PC; give "
                    f"the {'sensor' if what == '--netft' else 'controller'}'s own port")
    return None


def check_axis_limits(robot):
    """InputError (one line) when the robot file gives no axis speeds or
    accelerations: without them cell/safety.motion_reason checks nothing (holding
    the first pose, no --reference, an RSI start learnt from a setpoint that
    lies was answered, its AK from that start moving the arm by the lie)."""
    missing = [(key, unit) for key, unit, value in (
        ("joint_limits.speed_deg_per_s", "deg/s", robot.speed_limit_deg_per_s),
        ("joint_limits.acceleration_deg_per_s2", "deg/s^2", robot.acceleration_limit_deg_per_s2)) if value is None]
    if missing:  # name only what is missing (a file with the speeds was told both were)
        raise InputError(f"{robot.source}: key {' and '.join(repr(k) for k, _ in missing)}: missing (six values "
                         f"each, {' and '.join(u for _, u in missing)}, controller convention); compensate checks "
                         "every target's step against them "
                         "(the controller's motion supervision): the speeds from the maker's data sheet, the "
                         "accelerations from your controller (the library's files take full speed in 0.25 s: 4 x "
                         "the speed; docs/your_robot.md, models/*.yaml)")


# A payload calibration's mass this far from the robot file's payload mass is a warning (not an error: the robot
# file's is a data-sheet or catalogue figure, the calibration is measured).  ASSUMPTION: a spindle's catalogue mass
# and a wrist-sensor calibration of it agree within a few per cent (the example payload campaign: 39.98 kg against
# 40 kg); 10 % is a calibration of another tool, or one computed with another robot's kinematics (calibrate-payload
# without --robot takes the irb6400).  Each kg of error is 9.81 N on the force the gravity removal leaves.
PAYLOAD_MASS_MISMATCH = 0.10


def payload_mass_note(robot, cal, payload):
    """A warning line when the payload calibration ``cal`` (read from
    ``payload``) weighs more than PAYLOAD_MASS_MISMATCH off the robot file's
    payload.mass_kg, else None."""
    file_kg, cal_kg = float(robot.payload.mass_kg), float(cal.mass_kg)
    if file_kg <= 0.0 or abs(cal_kg - file_kg) <= PAYLOAD_MASS_MISMATCH * file_kg:
        return None
    return (f"--payload {payload}: mass {cal_kg:.1f} kg, but the robot file's payload.mass_kg is {file_kg:g} kg "
            f"({100.0 * abs(cal_kg - file_kg) / file_kg:.0f} % apart): a calibration of another tool, or made with "
            f"another robot (calibrate-payload --robot {robot.name})? The gravity removal takes the calibration's; "
            f"{abs(cal_kg - file_kg):.1f} kg off is {9.81 * abs(cal_kg - file_kg):.0f} N of force compensated as "
            "if it were the cut's")


def payload_robot_note(robot, cal, payload, robot_spec=None):
    """(warning, note) on the robot the payload calibration ``cal`` (read
    from ``payload``) was computed with: a warning when its
    payload_calibration.robot is not ``robot``'s name (another arm's
    kinematics turn the same joint angles into other gravity directions: a
    KR 210 campaign computed with the IRB 6400's cut 0.1 mm shallow), a note
    when the file names none (written before calibrate-payload named it);
    None for either that does not apply.  ``robot_spec``: --robot as given
    (a file's path), for the advice."""
    if cal.robot is None or not str(cal.robot).strip():
        return None, (f"--payload {payload} names no robot (payload_calibration.robot; written before "
                      f"calibrate-payload recorded it): not checked against {robot.name}")
    if cal.robot != robot.name:
        return (f"--payload {payload}: calibrated with the robot {str(cal.robot)[:80]!r}, not {robot.name!r} "
                f"({robot.source}): its gravity directions came from another arm's kinematics; calibrate again "
                f"with `calibrate-payload DATA.csv --robot {robot_spec or robot.name}`"), None
    return None, None


def sensor_timeout_note(sensor_timeout_ms, sensor_rate_hz):
    """A warning line when ``sensor_timeout_ms`` is within JITTER_PERIODS
    record periods at ``sensor_rate_hz`` (an honest stream's jitter of a
    record period then makes silences: each ramps the correction to zero
    and in again), else None.  (Not longer than one period: refused at the
    command line.)"""
    from robstiff_drake.cell.sensor_checks import JITTER_PERIODS

    period_ms = 1e3 / sensor_rate_hz
    if sensor_timeout_ms >= JITTER_PERIODS * period_ms:
        return None
    # (measured: an honest 100 Hz stream, +-1 record period, at 20 ms: 104-131 silences a minute, each ramping
    # the correction out and in: benchmarks/checks_attacked.py)
    return (f"--sensor-timeout-ms {sensor_timeout_ms:g} is within {JITTER_PERIODS:g} record periods at "
            f"--sensor-rate-hz {sensor_rate_hz:g} ({JITTER_PERIODS * period_ms:.4g} ms): a record a period late "
            "is a silence, the correction ramped out and in again; set it to at least "
            f"{JITTER_PERIODS * period_ms:.4g} ms")
