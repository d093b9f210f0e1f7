"""What a user would really have for the compensator's model, made the way
a user makes it, on the scenario's own simulated cell (the station of
diagrams/station.py, through its ports only: nothing of its formulas):

* joint stiffness identified from a stiffness campaign: the poses and
  loads of `robstiff plan-poses` (D-optimal), each load applied at the tool
  on the station and the tool point's displacement read as a laser
  tracker reads it (with its noise), then `robstiff identify`'s fit;
* the payload and the sensor's bias from a payload calibration on the
  station (the wrist sensor's own readings, with its noise, at the
  configurations the paper used: 15), the bias as it was then: it has
  drifted by the cut;
* cutting coefficients each off by a draw within +-coefficient_error
  (the force model's, for predictive and preview modes);
* the controller's servo from a step test (a small joint-target step
  through the reference port, the encoders read back), fitted by
  model/preview.fit_servo (preview mode): dead time, position gain,
  velocity bandwidth and the velocity loop's integral corner of a rigid
  axis (the drives' PI; the gears and links the step also moves are not
  in that form: their share is the fit's residual).

Every draw has the scenario's ``model.identification.seed``; the result is
computed once per process for given inputs (``user_model``) and recorded
in the run's outputs (``describe``).  The sizes and their sources are in
docs/assumptions.md.
"""

import copy
import math
import warnings

import numpy as np
from pydrake.common import RandomGenerator
from pydrake.systems.analysis import Simulator

from robstiff_drake.diagrams.scenario import planned_path
from robstiff_drake.diagrams.scenario_step import plant_step_s
from robstiff_drake.diagrams.scenario_models import plant_stiffness
from robstiff_drake.diagrams.station import make_milling_station, resolve_integral_corner
from robstiff_drake.diagrams.user_model_record import UserModel, disk_path, from_json, signature, to_json
from robstiff_drake.identification.stiffness.campaign import PayloadCampaign, StiffnessCampaign
from robstiff_drake.identification.stiffness.joint_stiffness import identify
from robstiff_drake.identification.stiffness.payload import calibrate
from robstiff_drake.identification.stiffness.pose_planning import plan_poses
from robstiff_drake.io import write_atomic
from robstiff_drake.model.milling import Cutter
from robstiff_drake.model.payload import PayloadCalibration
from robstiff_drake.model.preview import ServoModel, fit_servo

# How the station is loaded and read (simulated time per measurement):
LOAD_RAMP_S = 0.4  # the load comes on smoothly (no ringing to wait out)
LOAD_HOLD_S = 0.4  # then held while the arm settles (first mode ~5 Hz; the ramped load excites little ringing)
READ_S = 0.1  # the tracker's reading: the mean over the last 0.1 s
PAYLOAD_READ_S = 0.2  # the sensor's reading at a calibration configuration: its mean over 0.2 s
STEP_TEST_RAD = 1e-3  # the servo step test's target step (0.06 deg)
STEP_TEST_S = 0.3


class _ConstantLoad:
    """A stand-in for the milling force model: a wrench (N, N*m at the tool
    point, base frame) set from outside, whatever the tool's position."""

    def __init__(self, cutter):
        self.cutter = cutter
        self.wrench = np.zeros(6)

    def average_wrench(self, tool_point_m, feed_dir_xy, workpiece, feed_m_per_s=None):
        return self.wrench.copy()


COEFFICIENTS = ("Ktc_N_per_mm2", "Krc_N_per_mm2", "Kac_N_per_mm2", "Kte_N_per_mm", "Kre_N_per_mm", "Kae_N_per_mm")


class _Bench:
    """The scenario's station on its own, its inputs held: a bench to load,
    read and step the arm."""

    def __init__(self, sc, robot, q0, seed=0):
        sc = copy.deepcopy(sc)
        self._seed = int(seed)
        self._n = 0  # readings so far: each draws its sensor noise from (seed, n)
        sc.cutting.mode = "averaged"
        self.load = _ConstantLoad(Cutter(sc.cutter.diameter_mm / 1e3, int(sc.cutter.n_teeth), sc.cutter.spindle_rpm))
        from robstiff_drake.diagrams.scenario_models import cutting_setup

        _, _, workpiece = cutting_setup(sc)
        path = planned_path(sc)

        def make(q):
            # the scenario's plant step where it is stable at q; halved until it is (a folded arm's gear modes can
            # be faster than the cut's pose allows for: the step is the simulation's, not the cell's)
            s = sc
            for _ in range(4):
                try:
                    return make_milling_station(s, robot, path=path, force_model=self.load, workpiece=workpiece,
                                                q_modes_rad=q, tool_pose=True)
                except ValueError:
                    s = copy.deepcopy(s)
                    s.plant_config.time_step = plant_step_s(s, robot) / 2.0
                    s.servo.interpolator_period_ms = max(s.servo.interpolator_period_ms,
                                                         float(s.plant_config.time_step) * 1e3)
            return make_milling_station(s, robot, path=path, force_model=self.load, workpiece=workpiece,
                                        q_modes_rad=q, tool_pose=True)

        self._make = make
        self._q0 = np.asarray(q0, dtype=float)
        self._stations = {}
        self._key = 0
        self._switch(None)
        self.sensor_rate_hz = sc.sensor.rate_hz
        self._payload_weight_N = 9.81 * float(robot.payload.mass_kg)

    def _switch(self, q):
        """Use the station set up at pose ``q`` (None: the first pose's)."""
        key = None if q is None else tuple(np.round(np.asarray(q, dtype=float), 6))
        if key == self._key:
            return
        if key not in self._stations:
            station = self._make(self._q0 if q is None else np.asarray(q, dtype=float))
            self._stations[key] = (station, Simulator(station.diagram))
        self.station, self.sim = self._stations[key]
        self._key = key
        self.h = self.station.plant_step_s
        d = self.station.diagram
        self.root = self.sim.get_mutable_context()
        self.cmd = d.GetInputPort("position_command")
        self.vel = d.GetInputPort("velocity_command")
        self.vel.FixValue(self.root, np.zeros(6))

    def _measured(self, q, measure, plausible):
        """``measure()`` on the station set up at the path's first pose; where that reading is not plausible
        (the simulated station linearises its drives' tuning, its damping and its step's stability at that
        pose, and far from it, e.g. with a KUKA's arm folded, it can diverge where the cell would not), again
        on a station set up at q itself (its plant step halved until stable there: the step is the
        simulation's, not the cell's)."""
        self._switch(None)
        value = measure()
        if not plausible(value):
            self._switch(q)
            value = measure()
        return value

    def rest_at(self, q):
        self.load.wrench = np.zeros(6)
        self.root.SetTime(0.0)
        self._n += 1
        self.station.diagram.SetRandomContext(self.root, RandomGenerator(self._seed * 100003 + self._n))
        self.cmd.FixValue(self.root, np.asarray(q, dtype=float))
        self.station.set_initial_state(self.root, q)
        self.sim.Initialize()
    def tool_point(self):
        return self.station.diagram.GetOutputPort("tool_pose").Eval(self.root)[9:].copy()

    def mean_of(self, port, duration_s, step_s):
        t0 = self.root.get_time()
        vals = []
        for t in np.arange(t0 + step_s, t0 + duration_s + 1e-12, step_s):
            self.sim.AdvanceTo(t)
            vals.append(self.station.diagram.GetOutputPort(port).Eval(self.root).copy())
        return np.mean(vals, axis=0)

    def loaded_displacement(self, q, force_N):
        """Tool-point displacement (m) under a force (N) at the tool."""
        # plausible: at most 10 um/N (ten times the compliance of the softest industrial arm at its tool) + 1 mm
        return self._measured(q, lambda: self._loaded(q, force_N),
                              lambda d: np.all(np.isfinite(d)) and np.linalg.norm(d) <= 1e-5 * np.linalg.norm(
                                  force_N) + 1e-3)

    def _loaded(self, q, force_N):
        self.rest_at(q)
        p0 = self.tool_point()
        n = max(1, int(round(LOAD_RAMP_S / 0.02)))
        for i in range(1, n + 1):
            self.load.wrench = np.r_[force_N * 0.5 * (1 - math.cos(math.pi * i / n)), np.zeros(3)]
            self.sim.AdvanceTo(i * LOAD_RAMP_S / n)
        self.sim.AdvanceTo(LOAD_RAMP_S + LOAD_HOLD_S - READ_S)
        pose = self.mean_of("tool_pose", READ_S, self.h)
        return pose[9:] - p0

    def sensor_reading(self, q):
        """The wrist sensor's mean reading (sensor frame) at rest at q."""
        def read():
            self.rest_at(q)
            return self.mean_of("wrench_measured", PAYLOAD_READ_S, 1.0 / self.sensor_rate_hz)

        limit_N = 10.0 * self._payload_weight_N + 100.0  # at rest the sensor reads the payload's weight and its bias
        return self._measured(q, read, lambda w: np.all(np.isfinite(w)) and np.linalg.norm(w[:3]) <= limit_N)

    def step_response(self, q):
        """(t, mean motor response over the joints) to a STEP_TEST_RAD step of
        every joint's target at t = 0, read from the reported positions."""
        self.rest_at(q)
        base = self.station.diagram.GetOutputPort("position_measured").Eval(self.root).copy()
        self.cmd.FixValue(self.root, np.asarray(q, dtype=float) + STEP_TEST_RAD)
        ts = np.arange(0.0, STEP_TEST_S + 1e-12, self.h)
        out = []
        for t in ts:
            self.sim.AdvanceTo(t)
            out.append(np.mean(self.station.diagram.GetOutputPort("position_measured").Eval(self.root) - base))
        return ts, np.array(out)


def stiffness_campaign(bench, robot, cfg, rng_seed):
    """A plan-poses campaign measured on the bench, with tracker noise."""
    tool = robot.payload.tool_point_m
    with warnings.catch_warnings():  # (plan_poses compares with no random designs here)
        warnings.simplefilter("ignore", RuntimeWarning)
        plan = plan_poses(robot, cfg.measurements, n_candidate_poses=max(40, cfg.measurements), force_N=cfg.load_N,
                          noise_mm=max(cfg.tracker_noise_mm, 1e-3), tool_m=tool, seed=rng_seed, n_random=0)
    rng = np.random.default_rng([rng_seed, 1])
    disp = np.array([bench.loaded_displacement(q, f) for q, f in zip(plan.q_rad, plan.force_N)])
    # each displacement is a loaded minus an unloaded tracker reading
    disp_mm = disp * 1e3 + rng.normal(scale=cfg.tracker_noise_mm, size=disp.shape) * math.sqrt(2.0)
    n = len(disp)
    poses = [f"P{i + 1:03d}" for i in plan.pose_index]
    return StiffnessCampaign("simulated stiffness campaign", robot.controller_deg(plan.q_rad), plan.force_N,
                             np.zeros((n, 3)), disp_mm, None, poses, np.arange(1.0, n + 1), np.arange(n) + 1, [],
                             False, tool_mm=tool * 1e3)


def payload_configurations(robot, n, rng):
    """The paper's kind of calibration set: arm joints 2 and 3 near 10 and
    20 deg, joint 1 within +-29 deg, the wrist spread over its ranges
    (model angles)."""
    lo, hi = robot.q_lower_rad, robot.q_upper_rad
    margin = np.deg2rad(1.0)
    base = np.clip(np.deg2rad([0.0, 10.0, 20.0, 0.0, 0.0, 0.0]), lo + margin, hi - margin)
    q = np.tile(base, (n, 1))
    q[:, 0] = rng.uniform(-0.5, 0.5, n)
    q[:, 3] = rng.uniform(max(lo[3], -np.pi), min(hi[3], np.pi), n)
    q[:, 4] = rng.uniform(max(lo[4], -2.0), min(hi[4], 2.0), n)
    q[:, 5] = rng.uniform(max(lo[5], -np.pi), min(hi[5], np.pi), n)
    return robot.joint_map.to_model(q)


def payload_calibration_campaign(sc, robot, q0, cfg, rng_seed):
    """The payload calibration as made before the cut: the sensor's bias
    then was the cut's less its drift since (a draw of ``bias_drift``)."""
    rng = np.random.default_rng([rng_seed, 2])
    drift_f = rng.normal(scale=cfg.bias_drift_N, size=3)
    drift_t = rng.normal(scale=cfg.bias_drift_Nm, size=3)
    sc_cal = copy.deepcopy(sc)
    sc_cal.sensor.force_bias_N = list(np.asarray(sc.sensor.force_bias_N) - drift_f)
    sc_cal.sensor.torque_bias_Nm = list(np.asarray(sc.sensor.torque_bias_Nm) - drift_t)
    sc_cal.sensor.dropout_probability = sc_cal.sensor.spike_probability = 0.0
    sc_cal.sensor.seed = int(rng.integers(2**31))
    bench = _Bench(sc_cal, robot, q0, seed=rng_seed)
    q = payload_configurations(robot, cfg.payload_configurations, rng)
    readings = np.array([bench.sensor_reading(qi) for qi in q])
    camp = PayloadCampaign("simulated payload calibration", robot.controller_deg(q), readings[:, :3], readings[:, 3:],
                           np.arange(len(q)) + 1, [])
    fit = calibrate(robot, camp)
    cal = PayloadCalibration(mass_kg=fit.mass_kg, com_mm=list(fit.com_m * 1e3), force_bias_N=list(fit.force_bias_N),
                             torque_bias_Nm=list(fit.torque_bias_Nm), sensor_mount_rpy_deg=[0.0, 0.0, 0.0])
    return cal, {"bias_drift_N": drift_f.tolist(), "bias_drift_Nm": drift_t.tolist(),
                 "payload_fit_rms_N": fit.rms_force_N, "payload_fit_rms_Nm": fit.rms_torque_Nm}


_CACHE = {}  # the process's user models, by their inputs (user_model_record.signature)


def user_model(sc, robot, q0):
    """The scenario's UserModel, computed once for given inputs (kept in the
    process, and in the robot-description cache folder on disk, plant.py,
    keyed by the inputs and the code it depends on: the seeds fix every
    draw, so a cached model is the one a new computation would give).
    ``q0``: the path's first joint angles (the modes the damping is set at).
    The drives' integral corner is the one the run's station chooses at q0
    (station.resolve_integral_corner, on a copy of the servo's settings):
    the benches below choose it there anyway, so a scenario asked before its
    first station is built (simulate's checks: the stated corner) and the
    run's own (the chosen corner written in) are one model, measured once
    (before: two keys, and the bench campaigns ran twice)."""
    if sc.servo.velocity_integral == "antiresonance":
        sc = copy.copy(sc)
        sc.servo = copy.deepcopy(sc.servo)
        resolve_integral_corner(sc, robot, q0)
    key = signature(sc, robot, q0)
    if key in _CACHE:
        return _CACHE[key]
    disk = disk_path(key)
    try:
        _CACHE[key] = from_json(disk.read_text())
        return _CACHE[key]
    except (OSError, ValueError, KeyError, TypeError):
        pass
    cfg = sc.model.identification
    seed = int(cfg.seed)
    notes = {"seed": seed}
    k_plant = np.asarray(plant_stiffness(sc, robot), dtype=float)
    bench = None
    if cfg.stiffness == "identified":
        quiet = copy.deepcopy(sc)
        quiet.sensor.noise_N = quiet.sensor.noise_Nm = 0.0  # the tracker reads the tool, not the sensor
        bench = _Bench(quiet, robot, q0, seed=seed)
        camp = stiffness_campaign(bench, robot, cfg, seed)
        fit = identify(robot, camp, tool_m=robot.payload.tool_point_m)
        k = np.asarray(fit.stiffness_Nm_per_rad, dtype=float)
        ident_ok = np.asarray(fit.identifiable, dtype=bool)
        notes["stiffness_campaign"] = {"measurements": len(camp), "poses": len(set(camp.pose)),
                                       "load_N": cfg.load_N, "tracker_noise_mm": cfg.tracker_noise_mm}
    else:
        k, ident_ok = k_plant.copy(), np.ones(6, dtype=bool)
    if cfg.payload == "calibrated":
        cal, pnotes = payload_calibration_campaign(sc, robot, q0, cfg, seed)
        notes["payload_calibration"] = dict(pnotes, configurations=cfg.payload_configurations)
    else:
        from robstiff_drake.diagrams.scenario_models import exact_payload_calibration

        cal = exact_payload_calibration(sc, robot)
    rng = np.random.default_rng([seed, 3])
    draws = rng.uniform(-1.0, 1.0, len(COEFFICIENTS)) * cfg.coefficient_error
    factors = {name: (1.0 + float(d) if cfg.coefficients == "perturbed" else 1.0)
               for name, d in zip(COEFFICIENTS, draws)}
    if cfg.servo == "identified":
        if bench is None:
            bench = _Bench(sc, robot, q0, seed=seed)
        t, y = bench.step_response(q0)
        servo, rms = fit_servo(t, y, STEP_TEST_RAD)
    else:
        servo, rms = _exact_servo(sc), 0.0
    model = UserModel(k, ident_ok, cal, factors, servo, rms, notes)
    _CACHE[key] = model
    try:
        write_atomic(disk, to_json(model))
    except OSError:
        pass  # (no cache on disk: computed again next time)
    return model


def resolve(sc, robot, q0):
    """Set the scenario's identified model (``model.source: identified``)
    for the functions of diagrams/scenario_models.py that give the compensator's
    model (model_stiffness, payload_calibration, model_cutting_setup);
    returns it (None with ``model.source: nominal``)."""
    if sc.model.source != "identified":
        sc._user_model = None
        return None
    pinned = getattr(sc, "_user_model_pinned", None)  # set by the error budget (diagrams/budget.py)
    sc._user_model = pinned if pinned is not None else user_model(sc, robot, q0)
    return sc._user_model


def servo_model(sc):
    """The compensator's model of the controller's servo: identified, or
    the scenario's own servo keys (``model.source: nominal``)."""
    um = getattr(sc, "_user_model", None) if sc.model.source == "identified" else None
    if um is not None:
        return um.servo
    return _exact_servo(sc)


def _exact_servo(sc):
    """The scenario's servo keys as a ServoModel."""
    s = sc.servo
    # the station's dead time: the interpolator's and its servo's own discrete update (one plant step)
    return ServoModel(s.interpolator_delay_ms / 1e3 + plant_step_s(sc), s.position_gain_per_s,
                      s.velocity_bandwidth_hz, s.velocity_integral_hz)
