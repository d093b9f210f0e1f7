"""Scenario files (diagrams/*.yaml): dataclasses read with Drake's
``yaml_load_typed``, after a check of the file against the schema written
next to each field (range and unit: diagrams/schema.py), so that an unknown,
duplicated, mistyped or out-of-range key is one line naming the file, line,
key and allowed range; then checked for what depends on several keys and
for the size of the run, before anything is built.

Units are in the key names.  Paths to other files (an identification JSON,
a payload-calibration YAML) are relative to the scenario file.  Every file
the scenario names is noted as an input of the command when the scenario is
loaded (io.note_input: no output may overwrite or contain it), and read
through user_files (bounded, no YAML aliases).
"""

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from pydrake.multibody.plant import MultibodyPlantConfig
from pydrake.systems.analysis import SimulatorConfig

from robstiff_drake.diagrams.schema import check_object, choice, drake_config, num, rows, text, validate, vec
from robstiff_drake.errors import InputError, excerpt
from robstiff_drake.command import note_input
from robstiff_drake.model.milling import Cutter, CuttingCoefficients, MillingForceModel, Workpiece
from robstiff_drake.diagrams import toolpath as program_setup
from robstiff_drake.model.path import PathError, PlannedPath
from robstiff_drake.model.program_path import program_pieces
from robstiff_drake.model.joint_dynamics import DEFAULT_MODAL_DAMPING_RATIO
from robstiff_drake.model.payload import PayloadCalibration
from robstiff_drake.model.robot_file import STIFFNESS_RANGE_NM_PER_RAD
from robstiff_drake.user_files import load_json, load_yaml, read_user_text

# Ranges: what a machining robot's cell can physically be, wide enough for
# any real set-up, narrow enough that a typo (a unit slip, a missing decimal
# point) is caught before a long run.  The reasoning is next to each one.
MAX_COORD_MM = 10000.0  # a cell: 10 m from the robot base covers the largest arm on a track
MAX_DAMPING_RATIO = 0.5
MAX_PLAY_RAD = 2e-3


def _plant_config():
    # No contact: the gears are explicit forces (the plant's step is symplectic Euler, see
    # model/joint_dynamics.py); 2 ms keeps the IRB 6400's stiffest mode (125 Hz) stable.
    return MultibodyPlantConfig(time_step=0.002, discrete_contact_approximation="sap")


@dataclass
class PlantConfig:
    """The 'true' robot: a discrete MultibodyPlant (its step and solver in
    the scenario's ``plant_config``, Drake's MultibodyPlantConfig) whose
    joints are gears between a motor with its rotor's inertia (robot file:
    ``motor_inertia_kgm2``), which the drive turns, and the link
    (diagrams/station.py, model/joint_dynamics.py)."""

    # Joint stiffness of the plant (N*m/rad); empty: the robot file's nominal.
    joint_stiffness_Nm_per_rad: list[float] = vec([], (0, 6), *STIFFNESS_RANGE_NM_PER_RAD, "N*m/rad")
    # Damping per mode (modal damping, model/joint_dynamics.py): the damping ratio of each mode of the links
    # on their gears (motors held), lowest frequency first; or one ratio for every mode.  damping_ratios,
    # when not empty, sets every mode (modal_damping_ratio is then not used); empty: modal_damping_ratio.  ASSUMPTION (default): 5 % (joint_dynamics.py
    # gives the source).  The plant step is stable by its size, not by the damping (the run is refused
    # with the step it needs when it is not).
    damping_ratios: list[float] = vec([], (0, 6), 0.0, MAX_DAMPING_RATIO, "",
                                      why="a structural mode past 50 % of critical is no longer a mode; modal "
                                          "tests of industrial arms find 2-10 %")
    modal_damping_ratio: float = num(DEFAULT_MODAL_DAMPING_RATIO, 0.0, MAX_DAMPING_RATIO, "",
                                     why="a structural mode past 50 % of critical is no longer a mode; modal "
                                         "tests of industrial arms find 2-10 %")
    # The gears' play (rad): half the width b of each gear's dead zone (2b in all, no torque inside it,
    # the gear's stiffness outside: model/transmission.play_torque), and the coupling compliance between
    # joints 2 and 3 (rad/(N*m)).  Empty / 0: none.
    lost_motion_rad: list[float] = vec([], (0, 6), 0.0, MAX_PLAY_RAD, "rad",
                                       why="2 mrad (7 arcmin) is a worn-out reducer; robot reducers are "
                                           "specified at 0.1-0.3 mrad (RV: at most 1 arcmin)")
    coupling_c23_rad_per_Nm: float = num(0.0, -1e-5, 1e-5, "rad/(N*m)", why="at most the softest joint's own "
                                                                         "compliance (1e-5 rad/(N*m) = 1e5 N*m/rad)")


@dataclass
class ServoConfig:
    """The robot controller between a joint target and the motor
    (model/servo.py): the interpolator's dead time, then a position loop
    around a velocity loop with velocity feed-forward, on the motor side.

    ASSUMPTIONS (ABB publishes none of these for the IRC5):
    * the dead time from a new joint target to the drives: 12 ms, three 4 ms
      path cycles; users of ABB's Externally Guided Motion measure 10-50 ms
      from a sent target to the robot moving, network and EGM's own filter
      included (ros-industrial/abb_libegm issues 49 and 111);
    * a velocity-loop bandwidth of 30 Hz and a position gain of 60 1/s: the
      position loop's closed-loop bandwidth is then about 17 Hz and a
      correction without velocity feed-forward lags by 1 / Kp = 17 ms, the
      range of large robots' published servo bandwidths (5-20 Hz);
    * full velocity feed-forward of the path (the planned path is followed
      with no steady lag; the interpolator knows the path's velocity)."""

    interpolator_delay_ms: float = num(12.0, 0.0, 200.0, "ms")
    interpolator_period_ms: float = num(4.0, 0.5, 50.0, "ms")  # the path's cycle in the robot controller
    position_gain_per_s: float = num(60.0, 1.0, 1000.0, "1/s")
    velocity_bandwidth_hz: float = num(30.0, 1.0, 500.0, "Hz")
    velocity_feedforward: float = num(1.0, 0.0, 1.0, "")
    # The velocity loop's integral corner (a PI, as industrial drives have): ASSUMPTION 7.5 Hz, a quarter of
    # the velocity bandwidth (model/servo.py).
    velocity_integral_hz: float = num(7.5, 0.0, 100.0, "Hz")


@dataclass
class CutterConfig:
    diameter_mm: float = num(75.0, 10.0, 250.0, "mm", why="face mills a robot spindle carries")
    # The spindle's rated power: every run reports the cutting power it
    # implies (spindle_power_W) and warns above this.  The paper's spindle:
    # SETCO 5 HP (3.73 kW), 8000 rpm (its Table 3).
    spindle_rating_W: float = num(3730.0, 10.0, 200000.0, "W")
    # Inserts on the cutter; the tooth pitch pi D / n must stay >= MIN_TOOTH_PITCH_MM (checked below).
    n_teeth: int = num(6, 1, 100, "", integer=True)
    spindle_rpm: float = num(3600.0, 10.0, 60000.0, "rpm", why="the fastest machining spindles")


@dataclass
class CuttingConfig:
    """Mechanistic force model.  Coefficients: 6082-T6 (Duan et al., Chin. J.
    Mech. Eng. 2021, Table 5), scaled as the scenario documents.  Ranges:
    cutting coefficients up to 10,000 N/mm^2 cover hardened steel and
    titanium (2,000-4,000) with margin; edge coefficients up to 1,000 N/mm."""

    mode: str = choice("averaged", ("averaged", "tooth"))  # over a revolution, or tooth-resolved
    samples_per_tooth: int = num(20, 1, 200, "", integer=True)  # tooth mode: force samples per tooth pass
    Ktc_N_per_mm2: float = num(631.0, 0.0, 1e4, "N/mm^2")
    Krc_N_per_mm2: float = num(99.0, -1e4, 1e4, "N/mm^2")
    Kac_N_per_mm2: float = num(273.0, -1e4, 1e4, "N/mm^2")
    Kte_N_per_mm: float = num(13.0, 0.0, 1e3, "N/mm")
    Kre_N_per_mm: float = num(10.0, -1e3, 1e3, "N/mm")
    Kae_N_per_mm: float = num(2.8, -1e3, 1e3, "N/mm")
    tangential_radial_scale: float = num(1.0, 0.0, 10.0, "", lo_open=True)
    axial_scale: float = num(1.0, 0.0, 10.0, "", lo_open=True)
    phase_deg: float = num(0.0, -360.0, 360.0, "deg")


@dataclass
class WorkpieceConfig:
    """Uncut material: boxes [x0, x1, y0, y1, top] in mm, base frame."""

    boxes_mm: list[list[float]] = rows(5, -MAX_COORD_MM, MAX_COORD_MM, "mm", min_rows=1, max_rows=1000,
                                       names="x0, x1, y0, y1, top")


@dataclass
class PathConfig:
    """Tool point (centre of the cutter's bottom face) through waypoints, mm
    (or along the G-code program of the toolpath section)."""

    waypoints_mm: list[list[float]] = rows(3, -MAX_COORD_MM, MAX_COORD_MM, "mm", min_rows=0, max_rows=100000,
                                           names="x, y, z")
    feed_mm_per_s: float = num(20.0, 0.1, 2000.0, "mm/s", why="from a slow finishing pass to a robot's rapid moves")
    # Corner zone (model/path.py): a corner is rounded from this far before
    # it to this far after it, at the programmed speed, as ABB's zone data
    # z1, z5, z10 ... do (a zone is reduced to half the shorter move).  0: the
    # sharp corner at full speed, which no controller does (for comparison).
    zone_mm: float = num(5.0, 0.0, 200.0, "mm", why="ABB's largest standard zone is z200")
    yaw_deg: float = num(0.0, -360.0, 360.0, "deg")
    dwell_s: float = num(0.2, 0.0, 60.0, "s")  # at the first waypoint before the feed starts
    ramp_s: float = num(0.5, 0.0, 60.0, "s")  # cosine speed-up from rest to the feed (and slow-down at the end)
    reference_period_ms: float = num(4.0, 0.1, 100.0, "ms")  # IK samples of the joint references
    # The surface tolerance the planner holds (model/feed_plan.py): where the
    # predicted compensated error of a move exceeds it, the move's feed is
    # lowered (as CAM feed-rate optimisation does), down to
    # min_feed_fraction of the programmed feed.  0: no adaptation.  It must
    # be at least twice the scan's noise (scan.noise_mm, 1 sigma): below
    # that, the scan cannot tell a surface within it from one outside it.
    tolerance_mm: float = num(0.0, 0.0, 10.0, "mm")
    min_feed_fraction: float = num(0.25, 0.01, 1.0, "", why="a feed cut to 1 % is a stop, not a feed")


@dataclass
class ToolpathConfig:
    """A G-code program (model/gcode.py) as the path, placed on the
    workpiece: a program point p (mm, work frame) is at
    work_offset_mm + Rz(work_rotation_deg) p in the robot's base frame (the
    G54 offset; ``simulate --work-offset`` sets both).  F gives the feed
    and S the spindle speed (they replace path.feed_mm_per_s and
    cutter.spindle_rpm); G0 moves go at rapid_mm_per_s."""

    program: str = text("")  # relative to this file; empty: path.waypoints_mm
    work_offset_mm: list[float] = vec([0.0, 0.0, 0.0], (3,), -MAX_COORD_MM, MAX_COORD_MM, "mm")
    work_rotation_deg: float = num(0.0, -360.0, 360.0, "deg")
    # ASSUMPTION: 100 mm/s for G0 in a machining cell (robots slow their
    # rapids near a part; a CNC's rapid traverse of 10-30 m/min is for a
    # machine tool's guarded axes)
    rapid_mm_per_s: float = num(100.0, 0.1, 2000.0, "mm/s")
    # A number without a decimal point (X10): "calculator" reads 10 mm (10 in
    # under G20), as LinuxCNC and a Fanuc with calculator-type input do;
    # "increment": 10 least input increments, 0.010 mm (0.0010 in), as a
    # Fanuc reads it by default (IS-B).  CAM posts write every coordinate
    # with a point (X10.), so only hand-written programs differ.
    decimal_point: str = choice("calculator", ("calculator", "increment"))
    # Blocks that start with '/': "skip" them (the controller's block-delete
    # switch on) or "run" them.
    block_delete: str = choice("skip", ("skip", "run"))


@dataclass
class SensorConfig:
    # ATI's Net F/T streams at up to 7 kHz; 20 kHz leaves margin for any wrist sensor.
    rate_hz: float = num(1000.0, 1.0, 20000.0, "Hz")
    noise_N: float = num(0.5, 0.0, 100.0, "N")
    noise_Nm: float = num(0.05, 0.0, 10.0, "N*m")
    force_bias_N: list[float] = vec([0.0, 0.0, 0.0], (3,), -5000.0, 5000.0, "N")
    torque_bias_Nm: list[float] = vec([0.0, 0.0, 0.0], (3,), -500.0, 500.0, "N*m")
    dropout_probability: float = num(0.0, 0.0, 1.0, "")
    spike_probability: float = num(0.0, 0.0, 1.0, "")
    spike_N: float = num(0.0, 0.0, 1e5, "N")
    max_jump_N: float = num(1000.0, 0.0, 1e5, "N", lo_open=True)  # the guard rejects a sample that jumps more
    seed: int = num(0, 0, 2**32 - 1, "", integer=True)


@dataclass
class FilterConfig:
    kind: str = choice("lowpass", ("lowpass", "revolution_average", "none"))
    # 2 Hz: far below the arm's first mode (about 5 Hz), where a faster
    # filter makes the loop ring (see docs on the sampling-delay study)
    cutoff_hz: float = num(2.0, 0.0, 10000.0, "Hz", lo_open=True)
    # Butterworth order: above 8 the group delay and the coefficients' round-off make no sense for force control.
    order: int = num(2, 1, 8, "", integer=True)


@dataclass
class ControllerConfig:
    # "plain": the paper's compensator (the measured force, filtered and
    # delayed); "predictive": the model's force where the correction will act,
    # plus the filtered measured residual (see systems/predictive_wrench.py)
    # "preview": the predictive model through the arm's dynamics (the
    # model's modes, servo and delays): the correction anticipates the arm's
    # response to the force and to the path's accelerations
    # (model/preview.py, systems/preview_correction.py)
    mode: str = choice("plain", ("plain", "predictive", "preview"))
    # a robot controller's interpolation/position cycle: 0.1 ms (a fast CNC) to 1 s (useless for compensation)
    period_ms: float = num(4.0, 0.1, 1000.0, "ms")
    delay_steps: int = num(1, 0, 100, "periods", integer=True)
    filter: FilterConfig = field(default_factory=FilterConfig)
    saturation_deg: float = num(0.5, 0.0, 10.0, "deg", lo_open=True)  # largest correction per joint
    rate_limit_deg_per_s: float = num(5.0, 0.0, 1000.0, "deg/s", lo_open=True)


@dataclass
class IdentificationConfig:
    """How the compensator's model is made when ``model.source`` is
    "identified": what a user would have (diagrams/user_model.py), each
    part on the scenario's own simulated cell.  Sizes and their sources:
    docs/assumptions.md."""

    # Joint stiffness: "identified" from a stiffness campaign (plan-poses
    # loads on the cell, read by a laser tracker) or "exact" (the plant's).
    stiffness: str = choice("identified", ("identified", "exact"))
    measurements: int = num(40, 6, 500, "", integer=True)
    load_N: float = num(300.0, 10.0, 5000.0, "N")  # the paper's Table 2: 180-360 N
    # ASSUMPTION: 0.02 mm per coordinate, 1 sigma: a laser tracker's MPE
    # (Leica AT960/AT500: 15 um + 6 um/m transverse) at 2-3 m is 27-33 um,
    # typical results half of that; each displacement is two readings.
    tracker_noise_mm: float = num(0.02, 0.0, 1.0, "mm")
    # Payload and sensor bias: "calibrated" at configurations like the
    # paper's (the wrist sensor's own readings, with its noise) or "exact".
    payload: str = choice("calibrated", ("calibrated", "exact"))
    payload_configurations: int = num(15, 4, 200, "", integer=True)  # the paper: 15
    # The bias's drift between the calibration and the cut, 1 sigma per
    # axis.  ASSUMPTION: a strain-gauge force transducer's zero moves by up
    # to 0.05 % of its rated force per 10 K (HBM); a 2500 N six-axis sensor
    # warmed 10-20 K by the spindle: 1.3-2.5 N; 0.1 N*m likewise.
    bias_drift_N: float = num(2.0, 0.0, 100.0, "N")
    bias_drift_Nm: float = num(0.1, 0.0, 10.0, "N*m")
    # Cutting coefficients (predictive and preview modes): "perturbed", each
    # off by a uniform draw within +-coefficient_error, or "exact".
    # ASSUMPTION: 20 %: coefficients from a handbook or another batch of
    # the alloy, another insert grade or a worn edge (issue 20).
    coefficients: str = choice("perturbed", ("perturbed", "exact"))
    coefficient_error: float = num(0.2, 0.0, 0.9, "")
    # The controller's servo (preview mode): "identified" from a step test
    # of the joint targets, or "exact" (the scenario's servo keys).
    servo: str = choice("identified", ("identified", "exact"))
    seed: int = num(20, 0, 2**32 - 1, "", integer=True)  # of every draw above


@dataclass
class ModelConfig:
    """What the compensator believes (the plant is the truth)."""

    # "identified": what a user would have (model.identification: stiffness
    # from a simulated campaign, a calibrated payload and bias, cutting
    # coefficients off by a realistic amount, an identified servo);
    # "nominal": the robot file's stiffness and the scenario's exact payload,
    # bias, coefficients and servo (with a nominal plant: the perfect-model
    # bound).  The keys below (joint_stiffness_Nm_per_rad, identified_json,
    # payload_yaml) override their part of either.
    source: str = choice("identified", ("identified", "nominal"))
    identification: IdentificationConfig = field(default_factory=IdentificationConfig)

    # Joint stiffness (N*m/rad); empty: the robot file's nominal.
    joint_stiffness_Nm_per_rad: list[float] = vec([], (0, 6), *STIFFNESS_RANGE_NM_PER_RAD, "N*m/rad")
    # Or the JSON that `robstiff identify --json` wrote (relative to this file).
    identified_json: str = text("")
    # The YAML that `robstiff calibrate-payload --yaml` wrote; empty: the
    # exact payload and sensor bias (a perfect calibration).
    payload_yaml: str = text("")
    # Predictive mode's cutting-force model: the scenario's coefficients
    # times this factor (1: exact; 1.2: the model over-predicts by 20 %).
    force_model_scale: float = num(1.0, 0.0, 10.0, "", lo_open=True)
    # The compensator's own model of the joint effects (see PlantConfig):
    # what `robstiff diagnose-run` adds when it finds them.
    lost_motion_rad: list[float] = vec([], (0, 6), 0.0, 0.01, "rad")
    coupling_c23_rad_per_Nm: float = num(0.0, -1e-5, 1e-5, "rad/(N*m)")
    # Preview mode's damping of the arm: the modal damping ratio of each mode
    # of the links on their gears (lowest frequency first; one number: every
    # mode), the form of the plant's (model/joint_dynamics.py).  Empty: the
    # ratios this scenario states for its arm (plant.damping_ratios, else
    # plant.modal_damping_ratio), read from the file as a user reads their
    # arm's modal test; ASSUMPTION where the file states none: the plant
    # section's default, 5 %, the middle of the 2-10 % that modal tests of
    # industrial arms report (source in model/joint_dynamics.py).
    damping_ratios: list[float] = vec([], (0, 1, 6), 0.0, MAX_DAMPING_RATIO, "",
                                      why="a structural mode past 50 % of critical is no longer a mode; modal "
                                          "tests of industrial arms find 2-10 %")


@dataclass
class ScanConfig:
    """Laser line scans of the machined surface: along x (lines at given
    y), or along the machined path's centre line (and at offsets across
    it), with positions as arc length along the path and x, y."""

    # "x": lines along x; "path": along the path; "auto": along x for a path
    # that runs along x only, along the path otherwise
    along: str = choice("auto", ("auto", "x", "path"))
    # along x: the lines' y; empty: the centre line of each box
    lines_y_mm: list[float] = vec([], range(0, 101), -MAX_COORD_MM, MAX_COORD_MM, "mm")
    # along the path: offsets across it (+ to the left of the feed direction); empty: the centre line only
    offsets_mm: list[float] = vec([], range(0, 101), -1000.0, 1000.0, "mm")
    resolution_mm: float = num(0.5, 0.01, 50.0, "mm")
    edge_margin_mm: float = num(2.0, 0.0, 100.0, "mm")  # left out at each box edge (burrs, scan edge)
    # entry / exit zones of the statistics: this far from each box's leading /
    # trailing edge (0: the cutter radius, where the engagement changes)
    zone_mm: float = num(0.0, 0.0, 500.0, "mm")
    # The scanner's height noise, 1 sigma per point, added to the measured
    # scan (scan.csv; the statistics of the simulation's own summary stay
    # those of the true surface).  ASSUMPTION, 3 um: a laser line scanner's
    # own repeatability is about 0.5-2 um (Keyence LJ-X8000, Micro-Epsilon
    # scanCONTROL 30xx data sheets), a face-milled aluminium surface adds its
    # roughness (Ra 0.8-1.6 um, sigma about 1.25 Ra) and a scanner carried
    # over the part adds its vibration: together a few um.
    noise_mm: float = num(0.003, 0.0, 1.0, "mm", why="1 mm of scan noise is no measurement of a milled face")
    seed: int = num(0, 0, 2**32 - 1, "", integer=True)  # of the scan noise (each cut and line draws its own)


@dataclass
class Scenario:
    name: str = text("", max_length=200, one_line=True)
    description: str = text("")
    # The robot: a library name (`robstiff robots`) or a robot file (relative
    # to this file); empty: the IRB6400.
    robot: str = text("", max_length=4096)
    # Drake's own configuration of the plant (its step, s, and discrete
    # solver) and of the simulator, as Drake's hardware_sim embeds them.
    plant_config: MultibodyPlantConfig = drake_config(
        _plant_config, ranges={"time_step": (5e-5, 0.02, "s")},
        choices={"discrete_contact_approximation": ("sap", "lagged", "similar")})
    simulator_config: SimulatorConfig = drake_config(
        SimulatorConfig, ranges={"target_realtime_rate": (0.0, 1e6, ""), "start_time": (0.0, 0.0, "s")})
    plant: PlantConfig = field(default_factory=PlantConfig)
    servo: ServoConfig = field(default_factory=ServoConfig)
    cutter: CutterConfig = field(default_factory=CutterConfig)
    cutting: CuttingConfig = field(default_factory=CuttingConfig)
    workpiece: WorkpieceConfig = field(default_factory=WorkpieceConfig)
    path: PathConfig = field(default_factory=PathConfig)
    toolpath: ToolpathConfig = field(default_factory=ToolpathConfig)
    sensor: SensorConfig = field(default_factory=SensorConfig)
    controller: ControllerConfig = field(default_factory=ControllerConfig)
    model: ModelConfig = field(default_factory=ModelConfig)
    scan: ScanConfig = field(default_factory=ScanConfig)
    source: str = field(default="", metadata={"internal": True})  # set by the loader


# Cross-key limits.  A face mill's tooth pitch pi D / n: the densest
# (extra-close pitch) face mills in insert makers' catalogues have about
# 8-10 mm; below 6 mm there is no room for an insert and its chip pocket.
MIN_TOOTH_PITCH_MM = 6.0
# Sizes a run may take: at about 0.2 ms of wall time per plant step (the
# averaged block pass), 2e6 steps is about 7 minutes; the logs then hold
# about 20 floats per step.  Beyond these a typo (a feed of 1e-6 mm/s, a
# dwell of 1e9 s) would allocate for hours before failing.
MAX_PLANT_STEPS = 2_000_000
MAX_SENSOR_SAMPLES = 10_000_000
MAX_REFERENCE_SAMPLES = 1_000_000
MAX_TOOTH_SAMPLES_PER_STEP = 2000
MAX_FILTER_TAPS = 5000
MAX_SCAN_POINTS = 2_000_000


def load_scenario(path, toolpath=None, work_offset=None):
    """Read and check a scenario file; InputError (one line naming the file,
    line, key and allowed range) on anything wrong, before anything is built.
    ``toolpath``: a G-code program that replaces the scenario's path (the
    command line's --toolpath, relative to the working folder);
    ``work_offset``: the command line's --work-offset "X,Y,Z[,ROT_DEG]"
    (mm, deg), replacing toolpath.work_offset_mm (and work_rotation_deg)."""
    from pydrake.common.yaml import yaml_load_typed

    path = Path(path)
    text_ = read_user_text(path, "scenario file")
    try:
        lines = validate(Scenario, path, text_)
    except InputError as e:
        if "plant.damping_ratio: unknown key" in str(e):  # the key before the damping was modal
            raise InputError(str(e).split(": unknown key")[0] + ": replaced by plant.modal_damping_ratio (one "
                             "ratio for every mode) or plant.damping_ratios (one per mode): the plant's damping "
                             "is modal now, not stiffness-proportional") from None
        if "model.damping_ratio: unknown key" in str(e):  # preview's key before its damping was modal
            raise InputError(str(e).split(": unknown key")[0] + ": replaced by model.damping_ratios (the modal "
                             "damping ratio of each mode, or one for every mode; empty: the plant section's "
                             "stated ratios)") from None
        raise
    try:
        sc = yaml_load_typed(schema=Scenario, data=text_) if text_.strip() else Scenario()
    except (RuntimeError, ValueError, TypeError) as e:  # validate() lets nothing through that gets here
        msg = " ".join(str(e).split())
        raise InputError(f"{path}: {msg}") from None
    sc.source = str(path)
    sc._key_lines = lines
    if toolpath is not None:
        note_input(toolpath, "--toolpath")
        sc.toolpath.program = str(Path(toolpath).resolve())
        sc._program_label = str(toolpath)  # (its messages name it as given)
        sc.path.waypoints_mm = []
    if work_offset is not None:
        offset, rotation = program_setup.parse_work_offset(work_offset, ToolpathConfig)
        sc.toolpath.work_offset_mm = offset
        if rotation is not None:
            sc.toolpath.work_rotation_deg = rotation
    for key, named in named_files(sc).items():
        note_input(named, f"{key} of {path}")
    apply_program(sc)
    check_scenario(sc)
    return sc


def named_files(sc):
    """{key: path} of the files the scenario names (its program, robot file,
    identification JSON, payload calibration), resolved against its folder."""
    out = {}
    for key, value in (("toolpath.program", sc.toolpath.program), ("model.identified_json", sc.model.identified_json),
                       ("model.payload_yaml", sc.model.payload_yaml)):
        if value:
            out[key] = resolve(sc, value)
    spec = robot_spec(sc)
    if spec is not None and spec == str(resolve(sc, sc.robot)):
        out["robot"] = Path(spec)
    return out


def _program(sc):
    """The scenario's G-code program (model/gcode.Program), read once."""
    p = resolve(sc, sc.toolpath.program)
    if not p.is_file():
        _fail(sc, "toolpath.program", f"no such G-code program {p}" if not p.exists() else f"{p} is not a file")
    return program_setup.read_program(sc, p)


def _dominant(values_by_length):
    """The value covering the most length: {value: length}."""
    return max(values_by_length.items(), key=lambda kv: kv[1])[0] if values_by_length else None


def apply_program(sc):
    """With a toolpath program: read it (InputError naming its line and
    word) and take the cutting feed (F, the one over most of the cutting
    length) and spindle speed (S) from it for the force model."""
    if not sc.toolpath.program:
        return
    if sc.path.waypoints_mm:
        _fail(sc, "toolpath.program", "give path.waypoints_mm or toolpath.program, not both")
    feeds, speeds = program_setup.feeds_and_speeds(_program(sc))
    if feeds:
        sc.path.feed_mm_per_s = _dominant(feeds) / 60.0
    if speeds:
        sc.cutter.spindle_rpm = float(_dominant(speeds))


def plant_step_s(sc):
    """The plant's discrete step (s)."""
    return float(sc.plant_config.time_step)


def _fail(sc, key, what):
    lines = getattr(sc, "_key_lines", {})
    line = lines.get(tuple(key.split(".")))
    where = f"{sc.source or 'scenario'}:{line}" if line else (sc.source or "scenario")
    raise InputError(f"{where}: {key}: {what}")


def check_scenario(sc):
    """Every key against its range (the schema), then what depends on
    several keys; refused before any simulation starts."""
    check_object(Scenario, sc, sc.source or "scenario", getattr(sc, "_key_lines", {}))
    c, ctl, sen = sc.cutter, sc.controller, sc.sensor
    pitch = np.pi * c.diameter_mm / c.n_teeth
    if pitch < MIN_TOOTH_PITCH_MM:
        _fail(sc, "cutter.n_teeth", f"{c.n_teeth} teeth on a {c.diameter_mm:g} mm cutter is a tooth pitch of "
                                    f"{pitch:.1f} mm; at most {int(np.pi * c.diameter_mm / MIN_TOOTH_PITCH_MM)} "
                                    f"(pitch >= {MIN_TOOTH_PITCH_MM:g} mm)")
    if ctl.filter.kind == "lowpass" and not ctl.filter.cutoff_hz < 0.5 * sen.rate_hz:
        _fail(sc, "controller.filter.cutoff_hz",
              f"{ctl.filter.cutoff_hz:g} Hz must be between 0 and half the sensor rate ({0.5 * sen.rate_hz:g} Hz)")
    if ctl.filter.kind == "revolution_average":
        taps = sen.rate_hz * 60.0 / c.spindle_rpm
        if taps > MAX_FILTER_TAPS:
            _fail(sc, "controller.filter.kind", f"a revolution average at {c.spindle_rpm:g} rpm and "
                                                f"{sen.rate_hz:g} Hz needs {taps:.0f} taps (at most {MAX_FILTER_TAPS})")
    step_ms = plant_step_s(sc) * 1e3
    if ctl.period_ms < step_ms - 1e-9:
        _fail(sc, "controller.period_ms", f"{ctl.period_ms:g} ms is below the plant step ({step_ms:g} ms)")
    for i, b in enumerate(sc.workpiece.boxes_mm):
        if not (b[0] < b[1] and b[2] < b[3]):
            _fail(sc, "workpiece.boxes_mm", f"box {i + 1}: expected [x0, x1, y0, y1, top] with x0 < x1 and "
                                            f"y0 < y1, got {b}")
    if not sc.toolpath.program and len(sc.path.waypoints_mm) < 2:
        _fail(sc, "path.waypoints_mm", f"expected at least 2 waypoints (or a toolpath.program), got "
                                       f"{len(sc.path.waypoints_mm)}")
    tol, floor = sc.path.tolerance_mm, 2.0 * sc.scan.noise_mm
    if 0 < tol < floor:
        _fail(sc, "path.tolerance_mm", f"{tol:g} mm is below what the scan can verify: twice its noise, 2 x "
                                       f"scan.noise_mm = {floor:g} mm (a surface within it could not be told from "
                                       "one outside it)")
    if sc.model.joint_stiffness_Nm_per_rad and sc.model.identified_json:
        _fail(sc, "model.identified_json", "give model.joint_stiffness_Nm_per_rad or model.identified_json, not both")
    if sc.toolpath.program:
        program_setup.check_tool(sc, _program(sc), lambda key, what: _fail(sc, key, what))
    path = _check_sizes(sc)
    _check_engagement(sc, path)
    if sc.toolpath.program:
        program_setup.check_stock(sc, _program(sc))


def _path_key(sc):
    return "toolpath.program" if sc.toolpath.program else "path.waypoints_mm"


def _check_engagement(sc, path):
    """Refuse an air cut: the commanded cutter (a disc of the cutter's
    radius at the tool point) must come below the top of some box while
    over it, or there is no machined surface to measure."""
    R = sc.cutter.diameter_mm / 2.0
    step = max(R / 10.0, 1e-3) / 1e3
    n = int(min(np.ceil(path.total_length / step), 1_000_000)) + 1
    pts = np.array([path.point_at(x) for x in np.linspace(0.0, path.total_length, n)]) * 1e3
    for x0, x1, y0, y1, top in sc.workpiece.boxes_mm:
        dx = np.maximum(np.maximum(x0 - pts[:, 0], pts[:, 0] - x1), 0.0)
        dy = np.maximum(np.maximum(y0 - pts[:, 1], pts[:, 1] - y1), 0.0)
        if np.any((dx * dx + dy * dy < R * R) & (pts[:, 2] < top)):
            return
    if sc.toolpath.program:
        raise InputError(program_setup.placement_message(sc, _program(sc)))
    _fail(sc, _path_key(sc), f"the cutter ({sc.cutter.diameter_mm:g} mm) never comes below the top of a "
                             "workpiece box while over it: an air cut leaves no surface to measure")


def _check_sizes(sc):
    """Time and memory a run would take, before anything is allocated; the
    path itself (built here: cheap) checked too.  Returns the path."""
    p = sc.path
    if not sc.toolpath.program:
        wp = np.asarray(p.waypoints_mm, dtype=float)
        seg = np.linalg.norm(np.diff(wp, axis=0), axis=1)
        if np.any(seg <= 0):
            i = int(np.argmax(seg <= 0))
            _fail(sc, "path.waypoints_mm", f"waypoints {i + 1} and {i + 2} are the same point")
    try:
        path = planned_path(sc)
    except PathError as e:
        _fail(sc, _path_key(sc), str(e))
    duration_s = path.duration_s
    length_mm = path.total_length * 1e3
    checks = (
        ("plant_config.time_step", duration_s / plant_step_s(sc), MAX_PLANT_STEPS, "plant steps"),
        ("sensor.rate_hz", duration_s * sc.sensor.rate_hz, MAX_SENSOR_SAMPLES, "sensor samples"),
        ("path.reference_period_ms", duration_s / (p.reference_period_ms / 1e3), MAX_REFERENCE_SAMPLES,
         "joint-reference (IK) samples"),
    )
    for key, n, limit, what in checks:
        if n > limit:
            _fail(sc, key, f"the pass takes {duration_s:.4g} s ({length_mm:.4g} mm, dwell {p.dwell_s:g} s): "
                           f"{n:.3g} {what}, more than the {limit:.0e} a run may take; shorten the path or raise "
                           "the feed")
    if sc.cutting.mode == "tooth":
        per_step = plant_step_s(sc) * sc.cutter.spindle_rpm / 60.0 * sc.cutter.n_teeth * sc.cutting.samples_per_tooth
        if per_step > MAX_TOOTH_SAMPLES_PER_STEP:
            _fail(sc, "cutting.samples_per_tooth", f"{per_step:.3g} force samples per plant step (at most "
                                                   f"{MAX_TOOTH_SAMPLES_PER_STEP}); lower the spindle speed, the "
                                                   "samples per tooth or the plant step")
    boxes = np.asarray(sc.workpiece.boxes_mm, dtype=float)
    n_lines = max(len(sc.scan.lines_y_mm), len(boxes))
    n_scan = (boxes[:, 1].max() - boxes[:, 0].min()) / sc.scan.resolution_mm * n_lines
    if n_scan > MAX_SCAN_POINTS:
        _fail(sc, "scan.resolution_mm", f"{n_scan:.3g} scan points (at most {MAX_SCAN_POINTS:.0e}); "
                                        "use a coarser resolution")
    n_path_scan = path.total_length * 1e3 / sc.scan.resolution_mm * max(1, len(sc.scan.offsets_mm))
    if n_path_scan > MAX_SCAN_POINTS:
        _fail(sc, "scan.resolution_mm", f"{n_path_scan:.3g} scan points along the path (at most "
                                        f"{MAX_SCAN_POINTS:.0e}); use a coarser resolution")
    return path


def resolve(sc, relative):
    return (Path(sc.source).parent / relative) if sc.source else Path(relative)


def user_model_of(sc):
    """The identified model a run resolved for ``sc`` (diagrams/user_model.py
    sets it before the compensator is built), or None (``model.source:
    nominal``, or not resolved: then the nominal parts stand in)."""
    return getattr(sc, "_user_model", None) if sc.model.source == "identified" else None


def model_stiffness(sc, robot):
    """The compensator's joint stiffness (N*m/rad): the scenario's explicit
    model keys, else the identified model's, else the robot file's nominal."""
    if sc.model.joint_stiffness_Nm_per_rad:
        return np.asarray(sc.model.joint_stiffness_Nm_per_rad, dtype=float)
    if sc.model.identified_json:
        p = resolve(sc, sc.model.identified_json)
        named_by = f"model.identified_json of {sc.source or 'the scenario'}"
        doc = load_json(read_user_text(p, "JSON file", named_by=named_by), p)
        if not isinstance(doc, dict) or "joint_stiffness_Nm_per_rad" not in doc:
            _fail(sc, "model.identified_json", f"{p} has no joint_stiffness_Nm_per_rad (write it with `robstiff "
                                               "identify DATA.csv --json OUT`)")
        return checked_joint_stiffness(doc["joint_stiffness_Nm_per_rad"], where=str(p))
    um = user_model_of(sc)
    if um is not None:
        return um.joint_stiffness_Nm_per_rad
    return robot.joint_stiffness_Nm_per_rad


def checked_joint_stiffness(value, *, where):
    """``value`` as six finite joint stiffnesses (N*m/rad) within
    STIFFNESS_RANGE_NM_PER_RAD, or an InputError that names ``where``."""
    lo, hi = STIFFNESS_RANGE_NM_PER_RAD
    k = numbers(value)
    if k is None or k.shape != (6,) or not np.all(np.isfinite(k)) or np.any((k < lo) | (k > hi)):
        raise InputError(f"{where}: joint_stiffness_Nm_per_rad: expected six finite stiffnesses in "
                         f"[{lo:g}, {hi:g}] N*m/rad, got {excerpt(value)}")
    return k


def numbers(value):
    """``value`` as a flat float array when it is a list of plain numbers
    (no text, bool, list or dict in it), else None."""
    if not isinstance(value, (list, tuple)) or not all(isinstance(v, (int, float)) and not isinstance(v, bool)
                                                        for v in value):
        return None
    return np.asarray(value, dtype=float)


def plant_damping_ratios(sc):
    """The plant's damping ratio of each mode (6,), lowest frequency first."""
    if sc.plant.damping_ratios:
        return np.asarray(sc.plant.damping_ratios, dtype=float)
    return np.full(6, float(sc.plant.modal_damping_ratio))


def model_damping_ratios(sc):
    """(6,) the modal damping ratios the compensator's preview assumes
    (model.damping_ratios; empty: the scenario's stated plant ratios)."""
    r = sc.model.damping_ratios
    if r:
        return np.broadcast_to(np.asarray(r, dtype=float), (6,)).copy()
    return plant_damping_ratios(sc)


def plant_stiffness(sc, robot):
    if sc.plant.joint_stiffness_Nm_per_rad:
        return np.asarray(sc.plant.joint_stiffness_Nm_per_rad, dtype=float)
    return robot.joint_stiffness_Nm_per_rad


def planned_path(sc):
    """The scenario's tool path (PlannedPath, SI units): through its
    waypoints, or along its G-code program; PathError if it is malformed."""
    p = sc.path
    overrides = getattr(sc, "_feed_overrides", None)  # the feed planner's (diagrams/feed_plan.py)
    if sc.toolpath.program:
        tp = sc.toolpath
        prog = _program(sc)
        elements, speeds, stops, dwells, moves = program_pieces(prog.moves, tp.rapid_mm_per_s / 1e3,
                                                                program_setup.work_transform(tp))
        return PlannedPath.from_elements(elements, speeds, np.deg2rad(p.yaw_deg), p.dwell_s + prog.dwell_before_s,
                                         p.ramp_s, p.zone_mm / 1e3, stops=stops, dwells_s=dwells,
                                         tags=[f"{prog.path}:{m.line}" for m in moves],
                                         speed_overrides=overrides, lines=[m.line for m in moves])
    return PlannedPath(np.asarray(p.waypoints_mm, dtype=float) / 1e3, p.feed_mm_per_s / 1e3, np.deg2rad(p.yaw_deg),
                       p.dwell_s, p.ramp_s, p.zone_mm / 1e3, speed_overrides=overrides)


def cutting_setup(sc, scale=1.0, factors=None, groups=None):
    """(cutter, force model, workpiece) of the scenario; ``scale`` multiplies
    every coefficient (a compensator's model that is off by that factor),
    ``factors`` ({coefficient name: factor}) each one; ``groups``: keep
    only these coefficients (names), the others 0 (a group's share)."""
    cutter = Cutter(sc.cutter.diameter_mm / 1e3, int(sc.cutter.n_teeth), sc.cutter.spindle_rpm)
    c = sc.cutting
    s, sa = c.tangential_radial_scale * scale, c.axial_scale * scale
    f = dict(factors or {})
    values = {"Ktc_N_per_mm2": c.Ktc_N_per_mm2 * s, "Krc_N_per_mm2": c.Krc_N_per_mm2 * s,
              "Kac_N_per_mm2": c.Kac_N_per_mm2 * sa, "Kte_N_per_mm": c.Kte_N_per_mm * s,
              "Kre_N_per_mm": c.Kre_N_per_mm * s, "Kae_N_per_mm": c.Kae_N_per_mm * sa}
    values = {k: v * f.get(k, 1.0) * (1.0 if groups is None or k in groups else 0.0) for k, v in values.items()}
    coeffs = CuttingCoefficients(**values)
    model = MillingForceModel(cutter, coeffs, sc.path.feed_mm_per_s / 1e3)
    workpiece = Workpiece.from_boxes(np.asarray(sc.workpiece.boxes_mm, dtype=float) / 1e3)
    return cutter, model, workpiece


# The force model's coefficients by group (preview mode scales each group
# by what the cut shows): tangential, radial, axial.
COEFFICIENT_GROUPS = (("Ktc_N_per_mm2", "Kte_N_per_mm"), ("Krc_N_per_mm2", "Kre_N_per_mm"),
                      ("Kac_N_per_mm2", "Kae_N_per_mm"))


def model_cutting_setup(sc, groups=None):
    """(cutter, force model, workpiece) as the compensator models the cut:
    the scenario's coefficients times model.force_model_scale and, with an
    identified model, each coefficient's error factor."""
    um = user_model_of(sc)
    return cutting_setup(sc, scale=sc.model.force_model_scale,
                         factors=um.coefficient_factors if um is not None else None, groups=groups)


def exact_payload_calibration(sc, robot):
    """The true payload (robot file) and the scenario's sensor bias: a perfect calibration."""
    return PayloadCalibration(mass_kg=robot.payload.mass_kg, com_mm=list(robot.payload.com_m * 1e3),
                              force_bias_N=list(sc.sensor.force_bias_N), torque_bias_Nm=list(sc.sensor.torque_bias_Nm),
                              sensor_mount_rpy_deg=[0.0, 0.0, 0.0])


@dataclass
class PayloadCalibrationSchema:
    """The block `robstiff calibrate-payload --yaml` writes, with its ranges."""

    # the heaviest robot payloads are about 1.3 t; below 0.1 kg there is no spindle
    mass_kg: float = num(0.0, 0.1, 2000.0, "kg")
    com_mm: list[float] = vec([0.0, 0.0, 0.0], (3,), -2000.0, 2000.0, "mm")
    force_bias_N: list[float] = vec([0.0, 0.0, 0.0], (3,), -5000.0, 5000.0, "N")
    torque_bias_Nm: list[float] = vec([0.0, 0.0, 0.0], (3,), -500.0, 500.0, "N*m")
    sensor_mount_rpy_deg: list[float] = vec([0.0, 0.0, 0.0], (3,), -360.0, 360.0, "deg")


@dataclass
class PayloadCalibrationFile:
    payload_calibration: PayloadCalibrationSchema = field(default_factory=PayloadCalibrationSchema)


def read_payload_calibration(path, named_by=None):
    """A payload-calibration YAML, checked against its ranges (InputError);
    ``named_by``: the file and key that name it (for the output check)."""
    path = Path(path)
    text_ = read_user_text(path, "payload calibration", named_by=named_by)
    validate(PayloadCalibrationFile, path, text_)
    doc = load_yaml(text_, path)[0] or {}
    if "payload_calibration" not in doc or "mass_kg" not in (doc["payload_calibration"] or {}):
        raise InputError(f"{path}: payload_calibration.mass_kg: missing (write the file with "
                         "`robstiff calibrate-payload DATA.csv --yaml OUT.yaml`)")
    block = doc["payload_calibration"]
    return PayloadCalibration(**{k: (float(v) if k == "mass_kg" else [float(x) for x in v])
                                 for k, v in block.items()})


def payload_calibration(sc, robot):
    """The gravity-removal parameters: from the scenario's payload_yaml, or
    the identified model's, or the exact payload and sensor bias (an error
    budget's run with the arm's masses scaled keeps the real payload's:
    ``_payload_calibration_override``, diagrams/budget.py)."""
    override = getattr(sc, "_payload_calibration_override", None)
    if override is not None:
        return override
    if sc.model.payload_yaml:
        p = resolve(sc, sc.model.payload_yaml)
        if not p.is_file():
            _fail(sc, "model.payload_yaml", f"no such file {p}")
        return read_payload_calibration(p, f"model.payload_yaml of {sc.source or 'the scenario'}")
    um = user_model_of(sc)
    if um is not None:
        return um.calibration
    return exact_payload_calibration(sc, robot)


# How far the compensator's model may stray from the robot file before a
# run says so: a factor of 2 in a joint stiffness, 25 % in the payload's
# mass, 50 mm in its centre of mass (a calibration that far off is more
# likely of another tool or in other units than a real change).
MODEL_STIFFNESS_FACTOR = 2.0
PAYLOAD_MASS_REL = 0.25
PAYLOAD_COM_MM = 50.0


def scenario_warnings(sc, robot):
    """Legal settings whose results are likely implausible (one line each)."""
    out = []
    k_model, k_robot = model_stiffness(sc, robot), robot.joint_stiffness_Nm_per_rad
    ratio = k_model / k_robot
    for j in np.flatnonzero((ratio > MODEL_STIFFNESS_FACTOR) | (ratio < 1 / MODEL_STIFFNESS_FACTOR)):
        out.append(f"model: joint {j + 1}'s stiffness {k_model[j]:.3g} N*m/rad is {ratio[j]:.2g} times the robot "
                   f"file's nominal {k_robot[j]:.3g}")
    if sc.model.payload_yaml:
        cal = payload_calibration(sc, robot)
        m, m0 = cal.mass_kg, robot.payload.mass_kg
        if abs(m - m0) > PAYLOAD_MASS_REL * m0:
            out.append(f"model.payload_yaml: calibrated payload {m:.3g} kg is far from the robot file's {m0:.3g} kg "
                       "(another tool, or forces in other units?)")
        dc = np.linalg.norm(np.asarray(cal.com_mm or [0, 0, 0]) - robot.payload.com_m * 1e3)
        if dc > PAYLOAD_COM_MM:
            out.append(f"model.payload_yaml: calibrated centre of mass is {dc:.0f} mm from the robot file's")
    out += program_setup.program_warnings(sc)
    if sc.cutting.mode == "tooth":
        tooth_hz = sc.cutter.spindle_rpm / 60.0 * sc.cutter.n_teeth
        if sc.sensor.rate_hz < 2.0 * tooth_hz:
            out.append(f"sensor.rate_hz: {sc.sensor.rate_hz:g} Hz samples below twice the tooth-passing frequency "
                       f"({tooth_hz:g} Hz) in tooth-resolved mode: the tooth force aliases into the loop")
    return out
def robot_spec(sc):
    """The scenario's ``robot:`` as load_robot takes it (a library name, or
    its file resolved against the scenario's folder); None when empty."""
    if not sc.robot:
        return None
    from robstiff_drake.paths import library_robots

    if sc.robot in library_robots():
        return sc.robot
    return str(resolve(sc, sc.robot))


def scenario_robot(sc, override=None):
    """The RobotModel that runs scenario ``sc``: ``override`` (--robot) or
    the scenario's ``robot:`` (default: the IRB6400).  InputError, naming
    both, when the two are given and name different robots."""
    from robstiff_drake.model.robot import load_robot, same_robot_file

    spec = robot_spec(sc)
    if override is not None and spec is not None and not same_robot_file(spec, override):
        raise InputError(f"--robot {override} disagrees with the robot of {sc.source or 'the scenario'} "
                         f"(robot: {sc.robot}); drop --robot or edit the scenario")
    return load_robot(override if override is not None else spec)
