"""The scenario file's ``model:`` section: what the compensator believes
(its source, stiffness, payload, play, damping) and, for an identified
model, how a user would have measured it (``model.identification``:
campaigns, noise, perturbed inertias, a hammer test, a TCP calibration, a
probe).  The dataclasses diagrams/scenario_schema.Scenario embeds, each
field with its range and unit (diagrams/schema.py)."""

from dataclasses import dataclass, field

from robstiff_drake.diagrams.schema import choice, num, text, vec
from robstiff_drake.model.robot_file import STIFFNESS_RANGE_NM_PER_RAD

# a structural mode past half of critical damping is no longer a mode (the plant's and the model's ratios)
MAX_DAMPING_RATIO = 0.5

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
    # the alloy, another insert grade or a worn edge.
    coefficients: str = choice("perturbed", ("perturbed", "exact"))
    coefficient_error: float = num(0.2, 0.0, 0.9, "")
    # The controller's servo (preview mode): "identified" from a step test
    # of the joint targets, or "exact" (the scenario's servo keys).
    servo: str = choice("identified", ("identified", "exact"))
    # What the preview knows of the arm and the cell besides (diagrams/
    # user_measurements.py; each "exact" for the bound):
    # the links' masses and inertias: the robot file's, each off by a
    # uniform draw within +-inertia_error.  ASSUMPTION 15 %: a robot file's
    # inertial data are CAD or catalogue values, and identification studies
    # of industrial arms find link masses and inertias 10-20 % from them.
    inertia_error: float = num(0.15, 0.0, 0.9, "")
    # the damping: "modal_test" (hammer blows on the tool, drives on, modes
    # fitted: identification/stiffness/modes.py) or "stated" (model.damping_ratios,
    # else the plant's stated ratios).
    damping: str = choice("modal_test", ("modal_test", "stated"))
    # the tool point from a TCP calibration (four-point or sphere method):
    # ASSUMPTION 0.5 mm, 1 sigma per axis (robot TCP routines reach 0.2-1 mm)
    tcp_error_mm: float = num(0.5, 0.0, 20.0, "mm")
    # the workpiece's top from a touch probe: 0.05 mm, 1 sigma (ASSUMPTION:
    # a robot-carried probe's repeatability is a few um, the arm's own
    # repeatability 0.03-0.1 mm dominates)
    probe_error_mm: float = num(0.05, 0.0, 5.0, "mm")
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
    # The torque over which each joint's lost motion is taken up (N*m, the smooth law's tanh scale,
    # model/transmission.twist), identified from a campaign (identification/stiffness/play_law.py); empty: the
    # fallback, 1.5 % of each gear's rated torque (model/transmission.fallback_take_up_Nm).
    lost_motion_take_up_Nm: list[float] = vec([], (0, 6), 0.01, 1e4, "N*m",
                                              why="from a fraction of a N*m (a tight small reducer) to the "
                                                  "largest arms' kN*m")
    # The compensator's law of the lost motion (model/compensator.PLAY_LAWS): "hysteretic" (the default: each
    # gear's position in its gap tracked from the history of the torque it carries, model/play_hysteresis.py;
    # a gear with friction in its play stays on the flank it last pressed until the torque passes the
    # friction the other way, which no single-valued law follows: docs/run_diagnosis.md, "Gear play") or
    # "smooth" (b tanh(tau / take-up)).  Preview mode keeps the smooth law (its table is memoryless).
    lost_motion_law: str = choice("hysteretic", ("hysteretic", "smooth"))
    # The hysteretic law's friction inside each gear's play (N*m), identified from a campaign's reversals
    # (identification/stiffness/play_law.fit_hysteretic_play); empty: the fallback, 1.5 % of each gear's rated
    # torque (model/transmission.gap_friction_Nm, the plant's own default).
    lost_motion_friction_Nm: list[float] = vec([], (0, 6), 0.0, 1000.0, "N*m",
                                               why="a reducer's internal friction is a few % of its rated torque, "
                                                   "at most some hundred N*m on the largest arms")
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
