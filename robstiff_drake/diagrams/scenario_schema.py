"""The scenario file's schema: the dataclasses a scenario file is read
into (Drake's ``yaml_load_typed``, diagrams/scenario.py), each field with
its range and unit (diagrams/schema.py), Drake's own plant and simulator
configs embedded."""

from dataclasses import dataclass, field

from pydrake.multibody.plant import MultibodyPlantConfig
from pydrake.systems.analysis import SimulatorConfig

from robstiff_drake.diagrams.model_schema import MAX_DAMPING_RATIO, ModelConfig
from robstiff_drake.diagrams.plant_step import NOT_GIVEN
from robstiff_drake.diagrams.schema import choice, drake_config, num, rows, text, vec
from robstiff_drake.model.joint_dynamics import DEFAULT_MODAL_DAMPING_RATIO
from robstiff_drake.model.robot_file import STIFFNESS_RANGE_NM_PER_RAD

# Ranges: what a machining robot's cell can physically be, wide enough for
# any real set-up, narrow enough that a typo (a unit slip, a missing decimal
# point) is caught before a long run.  The reasoning is next to each one.
MAX_COORD_MM = 10000.0  # a cell: 10 m from the robot base covers the largest arm on a track


MAX_PLAY_RAD = 2e-3


def _plant_config():
    # No contact: the gears are explicit forces (the plant's step is symplectic Euler, see
    # model/joint_dynamics.py).  time_step 0 (NOT_GIVEN, also when the file leaves it out): the station takes
    # the largest step up to 2 ms that keeps every mode stable and resolves the scenario's play and
    # tooth-resolved force (diagrams/scenario_step.scenario_step_s); a step given is used as it is (and refused,
    # naming the step that would do, if it does not).
    return MultibodyPlantConfig(time_step=NOT_GIVEN, discrete_contact_approximation="sap")


@dataclass
class PlantConfig:
    """The 'true' robot: a discrete MultibodyPlant (its step and solver in
    the scenario's ``plant_config``, Drake's MultibodyPlantConfig) whose
    joints are gears between a motor with its rotor's inertia (robot file:
    ``motor_inertia_kgm2``), which the drive turns, and the link
    (diagrams/station.py, model/joint_dynamics.py)."""

    # Joint stiffness of the plant (N*m/rad); empty: the robot file's nominal.
    joint_stiffness_Nm_per_rad: list[float] = vec([], (0, 6), *STIFFNESS_RANGE_NM_PER_RAD, "N*m/rad")
    # Damping per mode (modal damping, model/joint_dynamics.py): the damping ratio of each mode of the arm
    # with its drives closed (what a modal test with the drives on measures; damping_on: motors_held states
    # it on the links on their gears, motors held, instead), lowest frequency first; or one ratio for every
    # mode.  damping_ratios,
    # when not empty, sets every mode (modal_damping_ratio is then not used); empty: modal_damping_ratio.  ASSUMPTION (default): 5 % (joint_dynamics.py
    # gives the source).  The plant step is stable by its size, not by the damping (the run is refused
    # with the step it needs when it is not).
    damping_ratios: list[float] = vec([], (0, 6), 0.0, MAX_DAMPING_RATIO, "",
                                      why="a structural mode past 50 % of critical is no longer a mode; modal "
                                          "tests of industrial arms find 2-10 %")
    modal_damping_ratio: float = num(DEFAULT_MODAL_DAMPING_RATIO, 0.0, MAX_DAMPING_RATIO, "",
                                     why="a structural mode past 50 % of critical is no longer a mode; modal "
                                         "tests of industrial arms find 2-10 %")
    # Which modes the ratios are stated on: drives_closed (the arm's modes with the drives' loops closed, as a
    # modal test with the drives on measures them: the plant solves for the gears' damping that gives them)
    # or motors_held (the links on their gears; the drives then add or take damping).
    damping_on: str = choice("drives_closed", ("drives_closed", "motors_held"))
    # The gears' play (rad): half the width b of each gear's dead zone (2b in all, no torque inside it,
    # the gear's stiffness outside: model/transmission.play_torque), and the coupling compliance between
    # joints 2 and 3 (rad/(N*m)).  Empty / 0: none.
    lost_motion_rad: list[float] = vec([], (0, 6), 0.0, MAX_PLAY_RAD, "rad",
                                       why="2 mrad (7 arcmin) is a worn-out reducer; robot reducers are "
                                           "specified at 0.1-0.3 mrad (RV: at most 1 arcmin)")
    coupling_c23_rad_per_Nm: float = num(0.0, -1e-5, 1e-5, "rad/(N*m)", why="at most the softest joint's own "
                                                                         "compliance (1e-5 rad/(N*m) = 1e5 N*m/rad)")
    # The Coulomb torque (N*m) with which a gear with play still drags its link while the flanks are apart;
    # empty: 1.5 % of the gear's rated torque (model/transmission.gap_friction_Nm gives the source); zeros: none.
    gap_friction_Nm: list[float] = vec([], (0, 6), 0.0, 1000.0, "N*m",
                                       why="a reducer's internal friction is a few % of its rated torque, at "
                                           "most some hundred N*m on the largest arms")


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
    # How the integral corner is chosen: antiresonance (the arm's first antiresonance, its first motors-held
    # mode at the path's first pose, over model/servo.INTEGRAL_BELOW_ANTIRESONANCE, at most
    # velocity_integral_hz: the PI's integral then takes no damping from the arm's modes; the station writes
    # the corner it chose into velocity_integral_hz, so the run's settings and the compensator's servo model
    # carry it) or stated (velocity_integral_hz as it is).
    velocity_integral: str = choice("antiresonance", ("antiresonance", "stated"))


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
    # the plant's chip: "program": its thickness from the tool's progress along the program, its direction the
    # program's where the tool is (systems/milling_force.py); "regenerative": each tooth's chip the tool centre's
    # own displacement since the earlier teeth's passes, a tooth with none out of the cut (model/regenerative_chip.py;
    # tooth mode only)
    chip: str = choice("program", ("program", "regenerative"))
    Ktc_N_per_mm2: float = num(631.0, 0.0, 1e4, "N/mm^2")
    Krc_N_per_mm2: float = num(99.0, -1e4, 1e4, "N/mm^2")
    Kac_N_per_mm2: float = num(273.0, -1e4, 1e4, "N/mm^2")
    Kte_N_per_mm: float = num(13.0, 0.0, 1e3, "N/mm")
    Kre_N_per_mm: float = num(10.0, -1e3, 1e3, "N/mm")
    Kae_N_per_mm: float = num(2.8, -1e3, 1e3, "N/mm")
    tangential_radial_scale: float = num(1.0, 0.0, 10.0, "", lo_open=True)
    axial_scale: float = num(1.0, 0.0, 10.0, "", lo_open=True)
    phase_deg: float = num(0.0, -360.0, 360.0, "deg")
    # The plant's own cutting physics (model/plant_cutting.py, sources
    # there): "rich": the chip from the tool's actual motion, a Kienzle chip
    # law, the worn edge's ploughing, runout; "linear": the compensator's
    # law (linear chip, no wear or runout), still from the actual motion.
    plant_law: str = choice("rich", ("rich", "linear"))
    # 1 - m_c of the Kienzle law (0.75: Sandvik Coromant's ISO N groups; 0.7-0.8 for wrought AlMgSi)
    chip_exponent: float = num(0.75, 0.3, 1.0, "")
    runout_mm: float = num(0.010, 0.0, 0.2, "mm", why="a face mill's insert runout is 5-20 um")
    runout_angle_deg: float = num(0.0, -360.0, 360.0, "deg")
    flank_wear_mm: float = num(0.02, 0.0, 1.0, "mm", why="ISO 3685's end-of-life criterion is VB = 0.3 mm")
    flank_wear_mm_per_m: float = num(0.0003, 0.0, 0.1, "mm/m")


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
    """A G-code program (model/gcode/program.py) as the path, placed on the
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
        _plant_config, ranges={"time_step": (5e-5, 0.02, "s", NOT_GIVEN)},
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
