"""compensator.yaml of a compensator process (docs/run_files.md): what
`robstiff compensate` runs with, in the run-file format that
`robstiff diagnose-run` reads (identification/runs/files.py writes it)."""

from pathlib import Path

import numpy as np

from robstiff_drake.identification.runs import files as rf

SERVO_NOTE = ("servo: not given to compensate (--servo DELAY_MS,KP_PER_S,BANDWIDTH_HZ,FEEDFORWARD[,KI_HZ]); add the robot "
              "controller's servo section before diagnose-run")
CUTTER_NOTE = ("tool.cutter_diameter_mm: not given to compensate (--cutter-diameter-mm); add it before "
               "diagnose-run")


def _robot_text(robot, robot_spec):
    from robstiff_drake.paths import library_robots

    if robot_spec is None or str(robot_spec) in library_robots():
        return robot.name if robot_spec is None else str(robot_spec)
    return str(Path(robot.source).resolve())


def compensator_yaml(*, robot, robot_spec, k, cal, tool_m, period_ms, delay_steps, filter_kind, cutoff_hz,
                     filter_order, sensor_rate_hz, max_jump_N, spindle_rpm, saturation_deg, rate_limit_deg_per_s,
                     servo=None, cutter_diameter_mm=None, robot_ref=None, mode="plain"):
    """The text of compensator.yaml without its run-id line.  ``servo``:
    (interpolator delay ms, position gain 1/s, velocity bandwidth Hz,
    velocity feed-forward 0-1) or None; a missing servo or cutter diameter
    is left out with a comment saying so.  ``robot_ref``: how ``robot:``
    names the robot (the run folder's kept copy, diagrams/run_inputs.py;
    None: the library name or the robot file's absolute path)."""
    z = [0.0, 0.0, 0.0]
    payload = {"mass_kg": float(cal.mass_kg), "com_mm": [float(v) for v in (cal.com_mm or z)],
               "force_bias_N": [float(v) for v in (cal.force_bias_N or z)],
               "torque_bias_Nm": [float(v) for v in (cal.torque_bias_Nm or z)],
               "sensor_mount_rpy_deg": [float(v) for v in (cal.sensor_mount_rpy_deg or z)]}
    s = rf.CompensatorSettings(
        joint_stiffness_Nm_per_rad=[float(v) for v in k], payload=payload,
        tool_point_mm=[float(v) for v in np.asarray(tool_m) * 1e3],
        cutter_diameter_mm=float(cutter_diameter_mm) if cutter_diameter_mm else 1.0, mode=mode,
        period_ms=float(period_ms), delay_steps=int(delay_steps), filter_kind=filter_kind,
        filter_cutoff_hz=float(cutoff_hz), filter_order=int(filter_order), sensor_rate_hz=float(sensor_rate_hz),
        max_jump_N=float(max_jump_N), spindle_rpm=float(spindle_rpm), saturation_deg=float(saturation_deg),
        rate_limit_deg_per_s=float(rate_limit_deg_per_s), robot=robot_ref or _robot_text(robot, robot_spec),
        servo=None if servo is None else dict(zip(rf.SERVO_KEYS, (float(v) for v in servo))))
    notes = ["written by robstiff compensate at the start of its run"]
    if servo is None:
        notes.append(SERVO_NOTE)
    if not cutter_diameter_mm:
        notes.append(CUTTER_NOTE)
    text = rf.settings_text(s, None, notes)
    lines = text.splitlines(keepends=True)
    if not cutter_diameter_mm:
        lines = [ln for ln in lines if not ln.strip().startswith("cutter_diameter_mm:")]
    return "".join(ln for ln in lines if not ln.startswith("# run_id:"))
