"""The ``robstiff`` command's argument parser: every subcommand, its
options with their ranges, and its example at the end of ``--help``.
A usage error is one line (``_UsageError``), as every other InputError.
The dispatch is commands/main.py's."""

import argparse

from robstiff_drake.commands.help_examples import EXAMPLES
from robstiff_drake.cell.correction_bound import DEFAULT_MAX_CORRECTION_MM
from robstiff_drake.commands.parser_cell import add_cell_commands
from robstiff_drake.commands.options import (
    FORCE_N,
    NOISE_MM,
    PROGRAM_MAX_CORRECTION_MM,
    SCENARIO_HELP,
    SEED,
    TOOL_DEFAULT,
    add_robot_option as _add_robot_option,
    number_in as _number_in,
)
from robstiff_drake.errors import InputError


class _UsageError(InputError):
    def __init__(self, prog, message):
        super().__init__(message)
        self.prog = prog


class _Parser(argparse.ArgumentParser):
    """argparse with a one-line error (the usage stays under --help)."""

    def error(self, message):
        raise _UsageError(self.prog, message)


def _add_tool_option(p, default_help=f"default: {TOOL_DEFAULT}"):
    p.add_argument("--tool", metavar="X,Y,Z", default=None,
                   help="tool point in the flange frame (DH frame 6), mm; "
                        f"{default_help}; a negative first value works as --tool -10,0,350 or --tool=-10,0,350")


def _add_campaign_command(sub, name, help_text, json_what):
    """A subcommand that reads a stiffness campaign: DATA.csv, --tool, --json, --robot."""
    p = sub.add_parser(name, help=help_text)
    p.add_argument("data", metavar="DATA.csv")
    _add_tool_option(p, f"default: the file's '# tool_mm:' line, else {TOOL_DEFAULT}; a --tool that disagrees "
                        "with the file's line is an error")
    p.add_argument("--json", metavar="OUT", help=f"write the {json_what} as JSON ('-' for stdout)")
    _add_robot_option(p)
    return p


def build_parser():
    parser = _Parser(prog="robstiff", description="Joint-stiffness models and compensation for machining robots.")
    from robstiff_drake import __version__

    parser.add_argument("--version", action="version", version=f"robstiff-drake {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    sub.required = True

    p = sub.add_parser("robots", help="the robot library: name, manufacturer, kinematic convention, source")
    p.add_argument("--json", metavar="OUT", help="write the list as JSON ('-' for stdout)")

    p = sub.add_parser("fk", help="forward kinematics: the flange (or --tool point) for six controller angles")
    p.add_argument("q", nargs="*", metavar="Q", help="six joint angles in degrees (the robot's controller convention)")
    _add_tool_option(p, "default: none, the flange itself")
    p.add_argument("--json", metavar="OUT", help="write a JSON object to OUT ('-' for stdout)")
    _add_robot_option(p)

    p = sub.add_parser("stiffness", help="Cartesian compliance and stiffness at one configuration")
    p.add_argument("q", nargs="*", metavar="Q", help="six joint angles in degrees (the robot's controller convention)")
    _add_tool_option(p)
    p.add_argument("--kx", action="store_true",
                   help="also print the 6x6 Cartesian stiffness K_x (an error at a singular pose)")
    p.add_argument("--json", metavar="OUT", help="write a JSON object to OUT ('-' for stdout)")
    _add_robot_option(p)

    p = sub.add_parser("stiffness-map", help="PNG map of the deflection under a tool force over the workspace")
    p.add_argument("--out", default="stiffness_map.png", help="PNG path (default: %(default)s)")
    p.add_argument("--force-N", type=FORCE_N, default=500.0, help="force magnitude at the tool (default: %(default)s N)")
    p.add_argument("--resolution", type=_number_in(5, 301, integer=True), default=41,
                   help="grid points per side (default: %(default)s)")
    _add_tool_option(p)
    _add_robot_option(p)

    p = sub.add_parser("kg-study", help="how much the CCT term K_g changes the deflection over machining poses")
    p.add_argument("--grid", type=_number_in(1, 20, integer=True), default=5, help="grid points per axis of the workspace box (default: %(default)s)")
    p.add_argument("--force-N", type=FORCE_N, default=500.0, help="tool force magnitude (default: %(default)s N)")
    p.add_argument("--payload-kg", type=_number_in(1e-3, 2000.0, "kg"), default=150.0, help="payload mass (default: %(default)s kg)")
    p.add_argument("--json", metavar="OUT", help="write the results as JSON ('-' for stdout)")
    p.add_argument("--progress", action="store_true", default=None, help="show the progress bar even off a terminal")
    _add_robot_option(p)

    p = sub.add_parser("make-urdf", help="write a robot's Drake/ROS description (URDF, package.xml) into a folder")
    p.add_argument("--out", default="robstiff-out/urdf",
                   help="folder; the files go to OUT/robstiff_NAME/ (default: %(default)s)")
    p.add_argument("--check", action="store_true", help="only check that the files in OUT are up to date")
    _add_robot_option(p)

    p = sub.add_parser("import-urdf", help="a robot file from a URDF (Drake's parser): DH from the joint axes, "
                                           "masses and inertias in the link frames, joint limits")
    p.add_argument("urdf", metavar="ROBOT.urdf")
    p.add_argument("--out", required=True, metavar="ROBOT.yaml", help="the robot file to write")
    p.add_argument("--template", metavar="ROBOT", default=None,
                   help="library robot or robot file whose joint stiffness, motor inertias, payload and workspace "
                        "the new file takes (a URDF has none; default: irb6400)")
    p.add_argument("--name", default=None, help="the robot's name in the file (default: the URDF's, cleaned)")
    p.add_argument("--controller-map", metavar="template|S1,..,S6:O1,..,O6", default=None,
                   help="the controller's joint angles: 'template' takes the template's controller block, or the "
                        "signs (+-1) and offsets (deg) with the URDF's angle = sign x the controller's + offset "
                        "(default: none, the URDF's angles)")

    p = _add_campaign_command(sub, "identify", "joint stiffness from a stiffness campaign (least squares, Eq. 8)",
                              "result")
    p.add_argument("--plot", metavar="OUT.png", help="measured vs predicted, residuals, stiffness with intervals")
    p.add_argument("--robust", action="store_true", help="Huber loss, for campaigns with outliers")
    p.add_argument("--noise-mm", type=_number_in(1e-6, 10.0, "mm"), default=None, metavar="SIGMA",
                   help="1-sigma noise of one displacement component (instrument), mm, for the test of the fit "
                        "against it; default: the file's '# noise_mm:' line, else replicate rows (same pose and load)")

    p = sub.add_parser("calibrate-payload", help="wrist-sensor payload: mass, centre of mass, biases")
    p.add_argument("data", metavar="DATA.csv")
    p.add_argument("--json", metavar="OUT", help="write the result as JSON ('-' for stdout)")
    p.add_argument("--yaml", metavar="OUT.yaml", help="write the gravity-removal parameter block")
    p.add_argument("--mount-rpy", metavar="R,P,Y", help="sensor frame's rotation from DH frame 6 (deg, URDF rpy)")
    _add_robot_option(p)

    p = sub.add_parser("synth", help="virtual measurement campaigns made from the model")
    kinds = p.add_subparsers(dest="kind", metavar="KIND", parser_class=_Parser)
    kinds.required = True
    s = kinds.add_parser("stiffness", help="a stiffness campaign (poses, loads, CMM displacements)")
    s.add_argument("out", metavar="OUT.csv", help="the campaign file ('-' for stdout)")
    s.add_argument("--n", type=_number_in(6, 100000, integer=True), default=120,
                   help="measurements (default: %(default)s)")
    s.add_argument("--loads-per-pose", type=_number_in(1, 100, integer=True), default=4, help="(default: %(default)s)")
    s.add_argument("--force-N", type=FORCE_N, default=300.0, help="load magnitude (default: %(default)s N)")
    s.add_argument("--noise-mm", type=NOISE_MM, default=0.01, help="CMM noise sigma (default: %(default)s mm)")
    s.add_argument("--seed", type=SEED, default=0)
    _add_tool_option(s, f"default: {TOOL_DEFAULT}; written into the file's '# tool_mm:' line")
    s.add_argument("--stiffness", metavar="K1,..,K6", help="true joint stiffness, N*m/rad (default: nominal)")
    s.add_argument("--effect", action="append", metavar="NAME[=RMS_MM]",
                   help="switch on an effect the conventional model lacks, sized so that the part of its "
                        "displacement the six joint springs cannot absorb has this RMS (default 0.04 mm); "
                        "repeatable")
    _add_robot_option(s)
    s = kinds.add_parser("payload", help="a payload (gravity) campaign of wrist-sensor readings")
    s.add_argument("out", metavar="OUT.csv", help="the campaign file ('-' for stdout)")
    s.add_argument("--n", type=_number_in(3, 100000, integer=True), default=15, help="configurations (default: %(default)s, as in the paper)")
    s.add_argument("--mass-kg", type=_number_in(1e-3, 2000.0, "kg"), default=None, help="(default: the robot file's payload)")
    s.add_argument("--com-mm", default=None, metavar="X,Y,Z", help="(default: the robot file's payload)")
    s.add_argument("--noise-N", type=_number_in(0.0, 1000.0, "N"), default=1.0, help="(default: %(default)s N)")
    s.add_argument("--noise-Nm", type=_number_in(0.0, 100.0, "N*m"), default=0.1, help="(default: %(default)s N*m)")
    s.add_argument("--seed", type=SEED, default=0)
    _add_robot_option(s)
    s = kinds.add_parser("tracker", help="a laser-tracker campaign (joint angles, measured x, y, z) made by Drake's "
                                         "plant of a perturbed arm")
    s.add_argument("out", metavar="OUT.csv", help="the campaign file ('-' for stdout)")
    s.add_argument("--n", type=_number_in(20, 100000, integer=True), default=300,
                   help="measured poses (default: %(default)s)")
    s.add_argument("--noise-mm", type=_number_in(0.0, 1.0, "mm"), default=0.03,
                   help="the tracker's noise sigma per component (default: %(default)s mm)")
    s.add_argument("--seed", type=SEED, default=0, help="draws the arm's errors, the tracker's place and the poses")
    s.add_argument("--export", action="store_true",
                   help="write it as a tracker's software exports it (';', decimal commas, units in the header, a "
                        "point id, an uncertainty, a timestamp)")
    _add_robot_option(s)

    p = _add_campaign_command(sub, "diagnose", "which effect the six-spring model lacks explains a campaign's residual",
                              "diagnosis")
    p.add_argument("--report", metavar="OUT.md", help="write a Markdown report")
    p.add_argument("--plots", metavar="DIR", help="write the residual views (one PNG per view)")
    p.add_argument("--noise-mm", type=float, default=None, metavar="SIGMA",
                   help="1-sigma noise of one displacement component (instrument), mm; without it the file's "
                        "'# noise_mm:' line (as identify reads it), else replicate rows (same pose and load), else "
                        "no verdict is given")
    p.add_argument("--validate", metavar="FILE.csv",
                   help="absolute-position campaigns: a second campaign of the same arm to test the fitted model on")
    p.add_argument("--write-robot", metavar="OUT.yaml",
                   help="absolute-position campaigns: write the robot file with the corrections kept (kinematics, "
                        "tool point, stiffness) and their provenance")

    p = sub.add_parser("diagnose-run", help="trace a machining run's residual surface error to its cause; write "
                                            "each candidate fix and decide from verification cuts")
    p.add_argument("run_dir", metavar="RUN_DIR", help="a run folder (docs/run_files.md): a cell's logs, or "
                                                      "`robstiff simulate ... --out RUN_DIR`")
    p.add_argument("--noise-mm", type=_number_in(1e-6, 10.0, "mm"), metavar="SIGMA",
                   help="the scan's 1-sigma height noise (mm); default: scan.csv's noise_mm, and the estimate "
                        "from the scan is reported too")
    p.add_argument("--verify", nargs="+", metavar="CUT_DIR",
                   help="run folders of verification cuts (one per candidate fix's compensator.yaml): decide "
                        "from their scans")
    p.add_argument("--scan", metavar="SCAN.csv",
                   help="a scan of the machined face made outside the project (a CMM's or a laser line's, "
                        "scan.csv's columns, no run id needed), instead of RUN_DIR/scan.csv")
    p.add_argument("--json", metavar="OUT", help="write the report as JSON ('-' for stdout)")
    p.add_argument("--out", metavar="DIR", help="where to write the report, candidate settings and plot "
                                                "(default: RUN_DIR/diagnosis)")
    _add_robot_option(p, "the run's robot (default: the one its compensator.yaml names); must agree with it")

    p = sub.add_parser("plan-poses", help="a well-conditioned measurement plan for the identification")
    p.add_argument("n", type=_number_in(6, 500, integer=True), metavar="N", help="number of measurements (6-500)")
    p.add_argument("--candidates", type=_number_in(2, 1000, integer=True), default=120,
                   help="candidate poses (default: %(default)s)")
    p.add_argument("--force-N", type=FORCE_N, default=300.0, help="(default: %(default)s N)")
    p.add_argument("--noise-mm", type=_number_in(1e-6, 10.0, "mm"), default=0.01, help="(default: %(default)s mm)")
    _add_tool_option(p, f"default: {TOOL_DEFAULT}; written into the plan's '# tool_mm:' line")
    p.add_argument("--seed", type=SEED, default=0)
    p.add_argument("--out", metavar="PLAN.csv", help="write the plan (q1..q6, fx, fy, fz per row)")
    p.add_argument("--json", metavar="OUT", help="write the comparison as JSON ('-' for stdout)")
    p.add_argument("--separate", metavar="EFFECT_A,EFFECT_B",
                   help="plan the rows that best separate two confounded effects (stiffness_jN, a named effect or "
                        "a dictionary term, as `robstiff diagnose` names them): poses and load directions with the "
                        "predicted 95 %% interval half-widths")
    p.add_argument("--campaign", metavar="DATA.csv",
                   help="with --separate: the stiffness campaign the plan adds to (its rows count, its identified "
                        "compliances and '# tool_mm:' line are used)")
    _add_robot_option(p)

    from robstiff_drake.identification.stiffness.table2_grouping import GROUPING

    p = sub.add_parser("table2", help="the paper's Table 2: linearity in load, offsets, repeatability",
                       description="The paper's Table 2 (data/seed_table2.csv) analysed per pose group: linearity "
                                   "in load, offset at zero load, repeatability.\n\n" + GROUPING)
    p.add_argument("--json", metavar="OUT", help="('-' for stdout)")
    p.add_argument("--plot", metavar="OUT.png")

    p = sub.add_parser("simulate", help="closed-loop milling simulation of a scenario (diagrams/*.yaml)")
    p.add_argument("scenario", metavar="SCENARIO.yaml", help=SCENARIO_HELP)
    p.add_argument("--compensation", default="both", choices=["on", "off", "both"],
                   help="run with, without, or both (default: %(default)s)")
    p.add_argument("--json", metavar="OUT", help="write the summary as JSON ('-' for stdout)")
    p.add_argument("--out", default="robstiff-out", help="output folder (default: %(default)s)")
    p.add_argument("--toolpath", metavar="PROGRAM", help="a G-code program as the path, placed by the scenario's "
                                                        "toolpath.work_offset_mm (docs/toolpaths.md)")
    p.add_argument("--work-offset", metavar="X,Y,Z[,ROT_DEG]",
                   help="where the program's zero is in the robot's base frame (mm), and its turn about the base z "
                        "axis (deg): replaces toolpath.work_offset_mm (and work_rotation_deg)")
    p.add_argument("--stock", metavar="X0,X1,Y0,Y1,TOP",
                   help="the workpiece: one block from X0 to X1 and Y0 to Y1, its top at TOP (mm, the robot's base "
                        "frame): replaces workpiece.boxes_mm")
    p.add_argument("--compensator", metavar="SETTINGS.yaml",
                   help="run the scenario's machine with this compensator (a compensator.yaml, e.g. a candidate "
                        "fix of diagnose-run): a verification cut")
    p.add_argument("--noise-seed", type=SEED, metavar="N",
                   help="seed of the sensor's and the scanner's noise (default: the scenario's); a repeated cut "
                        "draws new noise")
    p.add_argument("--replay", metavar="OUT.html",
                   help="a 3D replay of the run (robot, spindle, workpiece, tool path, the deflection magnified) "
                        "as one HTML file that opens in a browser without a server")
    p.add_argument("--progress", action="store_true", default=None,
                   help="show the progress bar (simulated time) even off a terminal")
    p.add_argument("--tolerance-mm", type=_number_in(0.0, 10.0, "mm"), default=None,
                   help="the surface tolerance the feed planner holds (replaces the scenario's path.tolerance_mm)")
    p.add_argument("--advise", action="store_true",
                   help="list the program lines whose predicted surface error exceeds the tolerance, with cause "
                        "and the feed that keeps them within it")
    p.add_argument("--advise-out", metavar="PROGRAM.nc", help="write the program with the advised feeds")
    p.add_argument("--budget", action="store_true",
                   help="the compensated cut's error budget: its residual by source (imperfections removed one at "
                        "a time, and cumulatively in an order and its reverse; docs/results.md)")
    p.add_argument("--budget-metric", choices=["mean", "rms", "max_abs", "pv"], default="rms",
                   help="the statistic of the measured surface error the budget decomposes (default: %(default)s)")
    p.add_argument("--budget-split", choices=["ordered", "one-at-a-time"], default="ordered",
                   help="ordered: the shares of removing the sources cumulatively in an order and its reverse "
                        "beside one at a time (3n - 2 cuts for n sources; they sum to the total); one-at-a-time: "
                        "only those (n + 2 cuts; what no single source owns is the interaction) "
                        "(default: %(default)s)")
    _add_robot_option(p, "the robot to run (default: the scenario's `robot:`, else irb6400); must agree with the "
                         "scenario's `robot:` when it has one")

    p = sub.add_parser("sweep", help="sampling-delay study: closed-loop runs over period, delay, cutoff and mode")
    p.add_argument("scenario", metavar="SCENARIO.yaml", help=SCENARIO_HELP)
    p.add_argument("--period-ms", required=True, help="controller periods, e.g. 0.5,1,2,4,8,12,16,24,32,48,100")
    p.add_argument("--delay-steps", default="1", help="transport delays in periods (default: %(default)s)")
    p.add_argument("--cutoff-hz", default="5", help="force-filter cutoffs (default: %(default)s)")
    p.add_argument("--mode", default="plain", help="plain and/or predictive (default: %(default)s)")
    p.add_argument("--json", metavar="OUT", help="write all runs as JSON ('-' for stdout)")
    p.add_argument("--plot", metavar="OUT.png", help="error against period, one curve per cutoff and mode")
    p.add_argument("--workers", type=_number_in(1, 64, integer=True), default=None, help="local processes (default: the number of cores)")
    p.add_argument("--scheduler", metavar="ADDRESS", help="a Dask scheduler, e.g. tcp://127.0.0.1:8786")
    p.add_argument("--plant-step-ms", type=_number_in(0.05, 20.0, "ms"), default=None, help="plant step for every run (default: the scenario's, or the shortest period when that is shorter)")
    p.add_argument("--no-predict", action="store_true", help="skip the linear loop model's predictions")
    p.add_argument("--progress", action="store_true", default=None, help="show the progress bar even off a terminal")
    _add_robot_option(p, "the robot to run (default: the scenario's `robot:`, else irb6400); must agree with the "
                         "scenario's `robot:` when it has one")

    p = sub.add_parser("compensate-program", help="offline compensation: the job's G-code program corrected for "
                                                  "the predicted deflection (no sensor, no real-time interface)")
    p.add_argument("job", metavar="JOB.yaml", help="a scenario with a toolpath.program, or the name of a packaged "
                                                   "one (face_and_contour)")
    p.add_argument("--out", required=True, metavar="DIR", help="folder for the corrected program, RAPID module and "
                                                                "joint reference (written whole, or not at all)")
    p.add_argument("--json", metavar="FILE", help="write the summary as JSON ('-' for stdout)")
    p.add_argument("--chord-mm", type=_number_in(1e-4, 1.0, "mm"), default=0.005,
                   help="largest distance of a written block from the corrected path (default: %(default)s mm)")
    p.add_argument("--max-correction-mm", type=_number_in(1e-3, 10.0, "mm"), default=PROGRAM_MAX_CORRECTION_MM,
                   help="offline, before anything is written: refuse the job (exit 2, naming the G-code line) "
                        "when the model's predicted correction of a programmed point is larger than this (mm, "
                        f"the tool point's translation). Not `compensate --max-correction-mm` (default "
                        f"{DEFAULT_MAX_CORRECTION_MM:g}), the real-time bound on what the streamed correction moves "
                        "the tool (default: %(default)s)")
    p.add_argument("--refine-rounds", type=_number_in(0, 10, integer=True), default=2, metavar="N",
                   help="rounds of refining the corrected program's floor on the compensator's model (each one "
                        "simulation of the job; 0: the preview's correction as it is; default: %(default)s)")
    p.add_argument("--advise", action="store_true",
                   help="lower the feeds where `simulate --advise` would (the feed planner: the job run on the "
                        "compensator's model two or more times) and write them into the corrected program")
    p.add_argument("--no-simulate", action="store_true", help="skip the proof runs on the plant")
    p.add_argument("--progress", action="store_true", default=None, help="show the progress bar even off a terminal")
    _add_robot_option(p, "the robot (default: the job's `robot:`, else irb6400)")

    add_cell_commands(sub)  # sim-cell, compensate (commands/parser_cell.py)

    p = sub.add_parser("examples", help="the packaged scenarios, G-code programs, robot files and example "
                                        "campaigns; --copy DIR copies them to edit")
    p.add_argument("--copy", metavar="DIR", help="copy them into DIR (created if missing; nothing existing is "
                                                 "overwritten)")

    p = sub.add_parser("demo", help="the main job: the paper's block-milling test, without and with compensation")
    p.add_argument("--out", default="robstiff-out", help="output folder (default: %(default)s)")
    _add_robot_option(p, "run the block test of this library robot (diagrams/block_milling_NAME.yaml) or of a "
                         "robot file (the IRB6400's block scenario moved to the file's "
                         "machining_workspace.reference_tool_point_mm); default: irb6400")
    _finish(parser)
    return parser


QUIET_HELP = ("no progress bars and no informational lines (what was written where); results, warnings and errors "
              "still print")


def _subcommands(parser, prefix=""):
    """(name, parser) of every subcommand, nested ones as 'synth stiffness'."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, p in action.choices.items():
                yield prefix + name, p
                yield from _subcommands(p, prefix + name + " ")


def _finish(parser):
    """Every subcommand: its example at the end of --help, and --quiet."""
    parser.add_argument("--quiet", action="store_true", default=argparse.SUPPRESS, help=QUIET_HELP)
    for name, p in _subcommands(parser):
        p.formatter_class = argparse.RawDescriptionHelpFormatter
        p.epilog = f"Example: {EXAMPLES[name]}"
        p.add_argument("--quiet", action="store_true", default=argparse.SUPPRESS, help=QUIET_HELP)
