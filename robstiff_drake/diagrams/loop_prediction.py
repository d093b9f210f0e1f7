"""The linear loop model (model/loop_model.py) set up for a scenario and a
sweep combination: what it predicts for stability and surface error, to set
beside the closed-loop simulation; and the loop check along a scenario's
path (``path_loop_margins``)."""

from dataclasses import replace

import numpy as np

from robstiff_drake.diagrams.experiment import ScanLine, material_top, zone_stats
from robstiff_drake.diagrams.compensator import filter_coefficients
from robstiff_drake.diagrams.milling_cell import planned_path as cell_planned_path
from robstiff_drake.diagrams.scenario import planned_path
from robstiff_drake.diagrams.scenario_step import plant_step_s
from robstiff_drake.diagrams.scenario_models import (
    cutting_setup, model_stiffness, plant_damping_ratios, plant_stiffness
)
from robstiff_drake.diagrams.compliant_arm import (  # noqa: F401  (gravity_stiffness: its old home)
    arm_joints,
    controller_model,
    gravity_stiffness,
    joint_model,
    mass_and_weight_stiffness,
    path_poses,
)
from robstiff_drake.diagrams.station import servo_parameters
from robstiff_drake.diagrams.sweep_config import configure
from robstiff_drake.model import ik, joint_dynamics
from robstiff_drake.model import kinematics as kin
from robstiff_drake.model.loop_check import LoopSetup, payload_inertial_wrench_map
from robstiff_drake.model.loop_model import LoopModel, first_order_lag_s, path_terms, process_stiffness
from robstiff_drake.model.surface import envelope_heights, surface_error_stats

KP_EVERY = 25  # recompute the process stiffness every this many sensor samples


class _Cell:
    """The few fields of a MillingCell that zone_stats reads."""

    def __init__(self, sc, path, workpiece, force_model):
        self.scenario, self.path, self.workpiece, self.force_model = sc, path, workpiece, force_model


def predict(sc, robot, combo, *, plant_step_ms=None, mass_matrix_cache=None, sensor_feels_inertia=True):
    """Predicted closed-loop poles and surface-error statistics for one sweep
    combination (dict with spectral_radius, stable, surface_error_mm,
    first_order_lag_error_mm).  ``sensor_feels_inertia=False`` leaves the
    payload's inertia out of the model's sensor (what the model missed
    before it was traced; kept for that comparison)."""
    sc = configure(sc, combo, plant_step_ms)
    tool = robot.tool_point(where="the loop model")
    from robstiff_drake.diagrams import user_model
    from robstiff_drake.diagrams.milling_cell import planned_path as cell_path

    user_model.resolve(sc, robot, cell_path(sc, robot, tool)[2][0])  # the compensator's model, as the run's
    cutter, fmodel, workpiece = cutting_setup(sc)
    path = planned_path(sc)
    t_mid = path.dwell_s + 0.5 * path.move_s
    q_mid = ik.solve_ik(robot.dh, ik.tool_down_pose(path.position(t_mid), path.yaw), tool)
    _, _, q_ref = cell_planned_path(sc, robot, tool)
    key = (robot.source, tuple(np.round(q_mid, 9)), tuple(np.round(q_ref[0], 9)),
           tuple(plant_stiffness(sc, robot)), float(sc.plant.coupling_c23_rad_per_Nm),
           tuple(plant_damping_ratios(sc)), sc.plant.damping_on, servo_parameters(sc))
    cache = mass_matrix_cache if mass_matrix_cache is not None else {}
    if key not in cache:
        # the plant's joints (drives tuned at the start pose, damping fitted along the path, as the station's),
        # at mid-pass
        plant = controller_model(robot)
        Kg = joint_dynamics.stiffness_matrix(plant_stiffness(sc, robot), sc.plant.coupling_c23_rad_per_Nm)
        at_start = arm_joints(plant, robot, path_poses(q_ref), Kg, plant_damping_ratios(sc), servo_parameters(sc),
                              sc.plant.damping_on)
        cache[key] = at_start.at_pose(*mass_and_weight_stiffness(plant, q_mid))
    joints = cache[key]
    ba = filter_coefficients(sc.controller.filter, sc.sensor.rate_hz, cutter.spindle_rpm)
    T = sc.controller.period_ms / 1e3
    scale = sc.model.force_model_scale
    loop = LoopModel(M=joints.M, K=joints.K, beta_s=None, J=kin.jacobian(robot.dh, q_mid, tool),
                     C_model=1.0 / model_stiffness(sc, robot), filter_ba=ba, rate_hz=sc.sensor.rate_hz, period_s=T,
                     delay_steps=sc.controller.delay_steps, mode=sc.controller.mode, model_scale=scale,
                     sensor_inertia=payload_inertial_wrench_map(robot, q_mid) if sensor_feels_inertia else None,
                     gravity_stiffness=joints.G, joints=joints)

    h = loop.h
    servo = servo_parameters(sc)
    t = np.arange(0.0, path.duration_s + 0.1, h)
    # the arm follows the path a fixed time late (the interpolator's dead time
    # and the servo's own step; the velocity feed-forward leaves no other lag):
    # deviations are taken from the path where the arm is meant to be then
    path_delay = servo.interpolator_delay_s + plant_step_s(sc)
    t_arm = t - path_delay
    pos = path.positions(t_arm)

    def force_at(p, tt):
        return fmodel.average_wrench(p, path.feed_direction(tt), workpiece)

    W = np.array([force_at(p, tt) for p, tt in zip(pos, t_arm)])
    Kp = np.empty((len(t), 3, 3))
    kp_max, kp_now = np.zeros((3, 3)), np.zeros((3, 3))
    for j in range(len(t)):
        if j % KP_EVERY == 0:
            kp_now = process_stiffness(lambda p, tt=t_arm[j]: force_at(p, tt), pos[j])
            if np.linalg.norm(kp_now) > np.linalg.norm(kp_max):
                kp_max = kp_now
        Kp[j] = kp_now
    command_lag = servo.low_frequency_lag_s + plant_step_s(sc)  # as MillingStation.command_lag_s
    lead = (sc.controller.delay_steps + 1.5) * T + command_lag
    ff = (scale * np.array([force_at(path.position(tt + lead), tt + lead) for tt in t])
          if sc.controller.mode == "predictive" else np.zeros_like(W))
    _, t_ref, q_ref = cell_planned_path(sc, robot, tool)
    motion = path_terms(t_arm, t_ref, q_ref, servo.velocity_feedforward)
    dev = loop.simulate(t, W, Kp, ff, motion)
    _, radius = loop.poles(kp_max)

    # the surface the predicted tool path leaves, scanned like the simulation's
    cell = _Cell(sc, path, workpiece, fmodel)
    R = cutter.radius_m
    up = np.tile([0.0, 0.0, 1.0], (len(t), 1))
    margin = sc.scan.edge_margin_mm / 1e3
    x = np.arange(workpiece.x_m[:, 0].min() + margin, workpiece.x_m[:, 1].max() - margin + 1e-12,
                  sc.scan.resolution_mm / 1e3)
    lines = []
    ys = [y / 1e3 for y in sc.scan.lines_y_mm] or sorted({float(np.mean(yr)) for yr in workpiece.y_m})
    for y in ys:
        top = np.nan_to_num(material_top(workpiece, x, np.full_like(x, y)), nan=-np.inf)
        h_cmd = envelope_heights(x, y, pos, up, R, top)
        h_act = envelope_heights(x, y, pos + dev, up, R, top)
        gap = ~(np.isfinite(top) & (h_cmd < top - 1e-9))
        h_cmd[gap], h_act[gap] = np.nan, np.nan
        lines.append(ScanLine(y, x, h_cmd, h_act))
    err = np.concatenate([ln.error_m[np.isfinite(ln.error_m)] for ln in lines])
    stats = surface_error_stats(err) if err.size else {}
    stats.update(zone_stats(cell, lines))
    # first-order lag error: C dF/dt * lag along the surface normal (z)
    C = loop.J[:3] @ np.diag(loop.C_model) @ loop.J.T  # 3x6 (m per N / N m)
    dz = (W @ C.T)[:, 2]
    rate = np.gradient(dz, h)
    lag = first_order_lag_s(ba, sc.sensor.rate_hz, T, sc.controller.delay_steps,
                            command_lag)
    first = float(np.max(np.abs(rate)) * lag * 1e3) if sc.controller.mode == "plain" else None
    # A pole just outside the unit circle grows slowly: call the loop divergent
    # when the worst-case growth over the cut (the engaged time) exceeds 10x.
    engaged = float(np.count_nonzero(np.abs(W[:, :3]).sum(axis=1) > 1.0) * h)
    growth_per_s = float(np.log(max(radius, 1e-300)) / T)
    return {"spectral_radius": radius, "growth_per_s": growth_per_s, "engaged_s": engaged,
            "stable": bool(growth_per_s * engaged < np.log(10.0)), "surface_error_mm": stats,
            "first_order_lag_error_mm": first, "lag_s": lag}


def scenario_loop_setup(sc, robot):
    """model/loop_check's LoopSetup for scenario ``sc`` at its path's first
    pose: the plant's and the compensator's stiffness, the servo, sensor
    rate, period and delay (the scenario's delay_steps counts the
    transport's), the filter's order (the gears' 2-3 coupling left out)."""
    tool = robot.tool_point(where="the loop model")
    _, _, q_ref = cell_planned_path(sc, robot, tool)
    return LoopSetup(robot=robot, q_rad=q_ref[0], k_Nm_per_rad=model_stiffness(sc, robot), servo=servo_parameters(sc),
                     sensor_rate_hz=sc.sensor.rate_hz, period_s=sc.controller.period_ms / 1e3,
                     delay_steps=sc.controller.delay_steps, filter_order=sc.controller.filter.order, tool_m=tool,
                     k_plant_Nm_per_rad=plant_stiffness(sc, robot), transport_delay_steps=0)


def mid_pass_process_stiffness(sc):
    """K_p (3, 3, N/m) of scenario ``sc``'s cut at mid-pass (its force
    model's change with the tool's position, model/loop_model.process_stiffness)."""
    _, fmodel, workpiece = cutting_setup(sc)
    path = planned_path(sc)
    t_mid = path.dwell_s + 0.5 * path.move_s
    return process_stiffness(lambda p: fmodel.average_wrench(p, path.feed_direction(t_mid), workpiece),
                             path.position(t_mid))


def path_loop_margins(sc, robot, filter_ba, samples=12):
    """The loop check (model/loop_check.py, at its margin's damping) at
    ``samples`` poses along scenario ``sc``'s path, the drives tuned at its
    first pose (as the station's): a list of dicts (row, t_s, q_rad,
    spectral_radius {air, cutting (the nominal process stiffness along the
    tool's motion from there)}), in path order."""
    from robstiff_drake.model.loop_check import FEED_DISTANCE_M, check, process_stiffness_along

    tool = robot.tool_point(where="the loop model")
    _, t_ref, q_ref = cell_planned_path(sc, robot, tool)
    start = scenario_loop_setup(sc, robot)
    servo = start.arm(0.02)[0].servo  # (the drives tuned at the first pose, their integral corner chosen there)
    p = kin.tool_position(robot.dh, q_ref, tool)
    out = []
    for r in np.unique(np.linspace(0, len(q_ref) - 1, samples).round().astype(int)):
        d = p[r:, :2] - p[r, :2]
        far = np.nonzero(np.linalg.norm(d, axis=1) >= FEED_DISTANCE_M)[0]
        feed = d[far[0]] if len(far) else None
        setup = replace(start, q_rad=q_ref[r], servo=servo, _arm={})
        v = check(setup, filter_ba, {"air": np.zeros((3, 3)), "cutting": process_stiffness_along(feed)},
                  search_cutoff=False, assumed_damping=False)
        out.append({"row": int(r) + 1, "t_s": float(t_ref[r]), "q_rad": q_ref[r], "spectral_radius": v.radius})
    return out
