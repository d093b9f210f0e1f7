"""A simulated cut as a cell records it, and a compensator's settings as a
scenario: the simulation side of the run files (identification/runs/files.py).

* ``compensator_settings(sc, robot)``: the compensator of a scenario, as the
  settings file a cell would hold (the model's stiffness resolved from the
  robot file or the identification JSON, the payload calibration resolved
  from its YAML or the exact one).
* ``cell_files(sc, result, robot, run_id)``: the texts of wrench_log.csv,
  joint_log.csv, compensator.yaml and scan.csv of one compensated cut.
* ``scenario_with_compensator(sc, settings, robot)``: the same machine
  (plant, path, workpiece, sensor) with the compensator of a settings file:
  how a verification cut is simulated on the machine of the first cut.  The
  simulation reads the machine from the run folder's ``sim_scenario.yaml``;
  the diagnosis never does.

The joint log's angles are the angles the compensator hands the robot
controller (the program plus the correction); the controller adds its
gravity model and the servo drives the motors after its interpolator's dead
time (diagrams/station.py).  compensator.yaml's ``servo`` section carries
the controller's servo settings (the scenario's ``servo``), which
``diagnose-run`` needs to know when a correction reaches the motor.
"""

import copy
from pathlib import Path

import numpy as np

from robstiff_drake.diagrams.scenario import check_scenario, robot_spec
from robstiff_drake.diagrams.scenario_step import plant_step_s
from robstiff_drake.diagrams.scenario_models import model_stiffness, payload_calibration
from robstiff_drake.errors import InputError
from robstiff_drake.identification.runs import logs as rl
from robstiff_drake.identification.runs import settings as rs
from robstiff_drake.identification.runs import tables as rt


def _payload_dict(cal):
    z = [0.0, 0.0, 0.0]
    return {"mass_kg": float(cal.mass_kg), "com_mm": [float(v) for v in (cal.com_mm or z)],
            "force_bias_N": [float(v) for v in (cal.force_bias_N or z)],
            "torque_bias_Nm": [float(v) for v in (cal.torque_bias_Nm or z)],
            "sensor_mount_rpy_deg": [float(v) for v in (cal.sensor_mount_rpy_deg or z)]}


def compensator_settings(sc, robot, robot_ref=None):
    """The compensator of scenario ``sc`` as CompensatorSettings; ``robot_ref``:
    how its ``robot:`` names the robot (default: the scenario's own)."""
    c = sc.controller
    return rs.CompensatorSettings(
        joint_stiffness_Nm_per_rad=[float(v) for v in model_stiffness(sc, robot)],
        payload=_payload_dict(payload_calibration(sc, robot)),
        tool_point_mm=[float(v) for v in np.asarray(robot.payload.tool_point_m) * 1e3],
        cutter_diameter_mm=float(sc.cutter.diameter_mm), mode=c.mode, period_ms=float(c.period_ms),
        delay_steps=int(c.delay_steps), filter_kind=c.filter.kind, filter_cutoff_hz=float(c.filter.cutoff_hz),
        filter_order=int(c.filter.order), sensor_rate_hz=float(sc.sensor.rate_hz),
        max_jump_N=float(sc.sensor.max_jump_N), spindle_rpm=float(sc.cutter.spindle_rpm),
        saturation_deg=float(c.saturation_deg), rate_limit_deg_per_s=float(c.rate_limit_deg_per_s),
        lost_motion_rad=[float(v) for v in (sc.model.lost_motion_rad or np.zeros(6))],
        # the law the run's compensator applies to it (diagrams/compensator.py: preview keeps the smooth law)
        lost_motion_law="smooth" if c.mode == "preview" else sc.model.lost_motion_law,
        lost_motion_take_up_Nm=[float(v) for v in sc.model.lost_motion_take_up_Nm] or None,
        lost_motion_friction_Nm=[float(v) for v in sc.model.lost_motion_friction_Nm] or None,
        coupling_c23_rad_per_Nm=float(sc.model.coupling_c23_rad_per_Nm),
        force_model_scale=float(sc.model.force_model_scale), robot=robot_ref or _robot_spec_text(sc, robot),
        servo=servo_settings(sc))


def servo_settings(sc):
    """The robot controller's servo of scenario ``sc`` as compensator.yaml's
    ``servo`` section (run_files.SERVO_KEYS).  ``interpolator_delay_ms`` is
    the dead time from a joint target the compensator sends at a controller
    tick to the servo acting on it, as the simulated station has it: the
    interpolator's hold takes the target at its next period (a discrete
    input changed at the same instant is seen one period later), its delay
    line holds it ``servo.interpolator_delay_ms``, and the servo's discrete
    update adds one plant step."""
    out = {k: float(getattr(sc.servo, k)) for k in rs.SERVO_KEYS}
    out["interpolator_delay_ms"] += float(sc.servo.interpolator_period_ms) + plant_step_s(sc) * 1e3
    return out


def _robot_spec_text(sc, robot):
    """The run's robot as a settings file names it: a library name, or its
    robot file's absolute path (the settings may be read elsewhere)."""
    from robstiff_drake.paths import library_robots

    spec = robot_spec(sc)
    if spec is not None and spec == sc.robot:
        return spec  # a library name
    if spec is None and robot.name in library_robots():
        return robot.name
    return str(Path(spec or robot.source).resolve())


def check_same_robot(settings, robot, where):
    """Refuse (InputError) settings whose ``robot`` is not the simulated one
    (another name, or the same name with other kinematics): a verification
    cut runs the compensator of the run's own robot."""
    if not settings.robot:
        return
    from robstiff_drake.model.robot import load_robot
    from robstiff_drake.paths import library_robots

    spec = settings.robot if settings.robot in library_robots() else \
        str(Path(settings.path or ".").parent / settings.robot)
    try:
        theirs = load_robot(spec)
    except (InputError, OSError) as e:
        raise InputError(f"{where}: compensator.robot: {settings.robot}: cannot be read ({e})") from None
    same = theirs.name == robot.name and all(
        np.allclose(getattr(theirs.dh, k), getattr(robot.dh, k), rtol=0, atol=1e-9)
        for k in ("a_m", "d_m", "alpha_rad", "home_rad"))
    if not same:
        raise InputError(f"{where}: compensator.robot is {settings.robot} ({theirs.name}), not the simulated robot "
                         f"{robot.name}: a verification cut runs the compensator made for this robot")


def scenario_with_compensator(sc, settings, robot):
    """Scenario ``sc`` (its plant, path, workpiece, cutting and sensor noise)
    with the compensator of ``settings``.  The tool, cutter and payload
    calibration are the machine's: settings that differ there are refused
    (InputError), since the simulation cannot change the hardware."""
    where = settings.path or "compensator settings"
    check_same_robot(settings, robot, where)
    tool = np.asarray(robot.payload.tool_point_m) * 1e3
    if not np.allclose(settings.tool_point_mm, tool, rtol=0, atol=1e-6):
        raise InputError(f"{where}: compensator.tool.point_mm {settings.tool_point_mm} is not the simulated "
                         f"robot's tool point {tool.tolist()} mm (robot file)")
    for key, got, machine in (("tool.cutter_diameter_mm", settings.cutter_diameter_mm, sc.cutter.diameter_mm),
                              ("tool.spindle_rpm", settings.spindle_rpm, sc.cutter.spindle_rpm)):
        if not np.isclose(got, machine, rtol=1e-9, atol=0):
            raise InputError(f"{where}: compensator.{key} {got:g} is not the scenario's {machine:g} "
                             "(the simulation takes the machine's own tool)")
    if settings.servo is not None:
        from robstiff_drake.diagrams.milling_cell import planned_path
        from robstiff_drake.diagrams.station import resolve_integral_corner

        # (the drives' integral corner the station will choose, where the run's settings logged it)
        _, _, q_ref = planned_path(sc, robot, robot.tool_point(where="the verification cut"))
        resolve_integral_corner(sc, robot, q_ref[0])
        own_servo = servo_settings(sc)
        for k, v in settings.servo.items():
            if not np.isclose(v, own_servo[k], rtol=1e-9, atol=0):
                raise InputError(f"{where}: compensator.servo.{k} {v:g} is not the scenario's servo.{k} "
                                 f"{own_servo[k]:g} (the robot controller's servo is the machine's, not the "
                                 "compensator's)")
    if sc.model.source == "identified" and getattr(sc, "_user_model", None) is None:
        # the run's identified model (made again from its seed): its cutting-coefficient errors and drive
        from robstiff_drake.diagrams import user_model as user_models
        from robstiff_drake.diagrams.milling_cell import planned_path

        _, _, q_ref = planned_path(sc, robot, robot.tool_point(where="the verification cut"))
        user_models.resolve(sc, robot, q_ref[0])
    # the payload calibration is the compensator's gravity removal (what it believes the sensor reads with no
    # cut), not the machine: a candidate fix may change it (diagnose-run's force_bias), and the cut runs with the
    # file's numbers
    keys = ("mass_kg", "com_mm", "force_bias_N", "torque_bias_Nm", "sensor_mount_rpy_deg")
    out = copy.deepcopy(sc)
    from robstiff_drake.model.payload import PayloadCalibration

    out._payload_calibration_override = PayloadCalibration(**{k: settings.payload[k] for k in keys})
    c = out.controller
    c.mode, c.period_ms, c.delay_steps = settings.mode, settings.period_ms, int(settings.delay_steps)
    c.filter.kind, c.filter.cutoff_hz, c.filter.order = (settings.filter_kind, settings.filter_cutoff_hz,
                                                         int(settings.filter_order))
    c.saturation_deg, c.rate_limit_deg_per_s = settings.saturation_deg, settings.rate_limit_deg_per_s
    out.sensor.rate_hz, out.sensor.max_jump_N = settings.sensor_rate_hz, settings.max_jump_N
    m = out.model
    m.joint_stiffness_Nm_per_rad = [float(v) for v in settings.joint_stiffness_Nm_per_rad]
    m.identified_json = ""
    m.lost_motion_rad = [float(v) for v in settings.lost_motion_rad] if any(settings.lost_motion_rad) else []
    m.lost_motion_law = settings.lost_motion_law
    m.lost_motion_take_up_Nm = [float(v) for v in settings.lost_motion_take_up_Nm or []]
    m.lost_motion_friction_Nm = [float(v) for v in settings.lost_motion_friction_Nm or []]
    m.coupling_c23_rad_per_Nm = float(settings.coupling_c23_rad_per_Nm)
    m.force_model_scale = float(settings.force_model_scale)
    check_scenario(out)
    return out


def cell_logs(result):
    """(WrenchLog, JointLog, Scan) of a simulated cut, as a cell logs them."""
    t, w = result.logs["raw_wrench"]
    # the logged signal is the sensor's reading after the compensator's guard,
    # which holds it one sensor period: time-stamp it when it was taken
    dt = 1.0 / result.cell.scenario.sensor.rate_hz
    keep = t >= dt - 1e-12
    wrench = rl.WrenchLog(t[keep] - dt, w[keep])
    tc, corr = result.logs["correction"]
    cell = result.cell
    # a logger sees the state before the discrete updates at its own instant: the correction it records
    # at t was computed one controller period earlier, and sent to the robot controller then
    tc = tc - cell.scenario.controller.period_ms / 1e3
    keep = tc >= -1e-12
    tc, corr = np.maximum(tc[keep], 0.0), corr[keep]
    q_ref = np.column_stack([np.interp(tc, cell.q_ref_times, cell.q_ref[:, j]) for j in range(6)])
    corr = corr if result.compensation else np.zeros_like(corr)
    robot = cell.robot
    joints = rl.JointLog(tc, robot.controller_deg(q_ref + corr), robot.controller_delta_deg(corr))
    return wrench, joints, scan_of(result.scans, cell.scenario.scan.noise_mm)


def scan_of(scans, noise_mm):
    """rl.Scan (mm) of a cut's scan lines (diagrams/experiment.scan_surface)."""
    xs, ys, nom, h = [], [], [], []
    for line in scans:
        face = np.isfinite(line.commanded_m)
        xs.append(line.x_m[face])
        ys.append(line.y_at[face])  # (a scan along the path has a y per point)
        nom.append(line.commanded_m[face])
        h.append((line.machined_m if line.measured_m is None else line.measured_m)[face])
    return rl.Scan(*(np.concatenate(a) * 1e3 for a in (xs, ys, nom, h)), noise_mm=noise_mm)


def cell_files(sc, result, robot, run_id, robot_ref=None):
    """{file name: text} of the cell files of one simulated cut; ``robot_ref``:
    see compensator_settings (a run folder names its kept copy)."""
    wrench, joints, scan = cell_logs(result)
    note = f"simulated by robstiff simulate ({sc.name or sc.source})"
    sim_wrench = ("In this simulated run: the reading after the compensator's guard (a dropout or a spike is "
                  "replaced by the last good sample), sensor noise and bias as the scenario's sensor section sets "
                  "them.")
    sim_scan = (f"In this simulated run: Gaussian height noise of {sc.scan.noise_mm:g} mm (1 sigma, scan.noise_mm, "
                f"seed {sc.scan.seed}) on the simulated face; nominal_mm is the envelope of the programmed pass.")
    return {
        rt.WRENCH_LOG: rl.wrench_log_text(wrench, run_id, [note, sim_wrench]),
        rt.JOINT_LOG: rl.joint_log_text(joints, run_id, [note]),
        rt.SETTINGS: rs.settings_text(compensator_settings(sc, robot, robot_ref), run_id, [note]),
        rt.SCAN: rl.scan_text(scan, run_id, [note, sim_scan]),
    }
