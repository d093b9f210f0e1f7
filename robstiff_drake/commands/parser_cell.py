"""The argument parser's commands that talk to a robot cell over the
network: ``sim-cell`` (the scenario's simulated controller and sensor) and
``compensate`` (the compensator as a process between a real controller
and sensor).  Every option with its range (commands/parser.py builds the
rest and calls ``add_cell_commands`` where these two stand in the help)."""

from robstiff_drake.cell.correction_bound import DEFAULT_MAX_CORRECTION_DEG, DEFAULT_MAX_CORRECTION_MM
from robstiff_drake.cell.sensor_checks import DEFAULT_START_TOLERANCE_N, START_TOLERANCE_RANGE_N
from robstiff_drake.commands.options import PROGRAM_MAX_CORRECTION_MM, SCENARIO_HELP, add_robot_option, \
    number_in as _number_in


def add_cell_commands(sub):
    """Add ``sim-cell`` and ``compensate`` to the subparsers ``sub``."""
    p = sub.add_parser("sim-cell", help="the scenario's simulated cell behind EGM and Net F/T (for `compensate`)")
    p.add_argument("scenario", metavar="SCENARIO.yaml", help=SCENARIO_HELP)
    p.add_argument("--compensator", "--egm-to", dest="egm_to", required=True, metavar="HOST:PORT",
                   help="the compensator's side, whatever --controller-protocol (EGM, RSI, Stream Motion): where "
                        "it listens (its --listen-port); for Stream Motion the port this controller listens on "
                        "(the compensator's --controller). --egm-to: the same, its older name")
    p.add_argument("--netft-port", type=_number_in(1, 65535, integer=True), required=True, metavar="PORT",
                   help="UDP port of the simulated Net F/T (RDT)")
    p.add_argument("--wait-s", type=_number_in(0.1, 3600.0, "s"), default=30.0,
                   help="how long to wait at rest for the compensator's first answer (default: %(default)s)")
    p.add_argument("--reference-out", metavar="JOINTS.csv",
                   help="write the path's joint reference, for `compensate --reference`")
    p.add_argument("--scan-out", metavar="SCAN.csv",
                   help="write the machined face as a scanner measures it (scan.csv's columns, no run id), for "
                        "`diagnose-run RUN --scan`")
    p.add_argument("--lockstep", action="store_true",
                   help="step the station only when the compensator has answered the last message (the loop's "
                        "physics without this PC's scheduling; default: real time, as a controller runs)")
    p.add_argument("--period-ms", type=_number_in(0.5, 100.0, "ms"), default=None,
                   help="the controller's cycle (default: the scenario's controller.period_ms; another is a "
                        "warning)")
    p.add_argument("--controller-protocol", dest="protocol", choices=["egm", "rsi", "stream-motion"], default="egm",
                   help="the controller's side of ABB EGM, KUKA RSI or FANUC Stream Motion (default: %(default)s)")
    p.add_argument("--netft-http-port", type=_number_in(1, 65535, integer=True), default=None,
                   help="TCP port of the simulated sensor's calibration page (default: the --netft-port number)")
    p.add_argument("--transport-delay-cycles", type=_number_in(0, 10, integer=True), default=None,
                   help="cycles between a message and the tick its answer acts at, beyond the next one "
                        "(default: the scenario's controller.delay_steps; run compensate with --delay-steps 0)")
    p.add_argument("--answer-timeout-s", type=_number_in(0.1, 3600.0, "s"), default=1.0,
                   help="once engaged, stop when no answer has come for this long (EGM's CommTimeout; a longer one "
                        "lets a loaded PC's stalled compensator catch up in --lockstep; default: %(default)s)")
    p.add_argument("--json", metavar="OUT", help="write the result as JSON ('-' for stdout)")
    add_robot_option(p)

    p = sub.add_parser("compensate", help="the compensator as a process: ABB EGM, KUKA RSI or FANUC Stream Motion "
                                          "and an ATI Net F/T over UDP (docs/real_cell.md)")
    p.add_argument("--listen-port", "--egm-port", dest="listen_port", type=_number_in(0, 65535, integer=True),
                   default=None, metavar="PORT",
                   help="UDP port the controller's messages come to (EGM and RSI: required; Stream Motion: 0, any)")
    p.add_argument("--controller", default="127.0.0.1", metavar="HOST[:PORT]",
                   help="the robot controller: datagrams from anyone else are dropped, never answered (a real cell "
                        "must give it; Stream Motion's port default 60015)")
    p.add_argument("--controller-protocol", dest="protocol", choices=["egm", "rsi", "stream-motion"], default="egm",
                   help="ABB EGM (EGMRunJoint), KUKA RSI (XML, axis corrections) or FANUC Stream Motion (J519)")
    p.add_argument("--netft", required=True, metavar="HOST[:PORT]", help="the Net F/T (RDT port default 49152)")
    add_robot_option(p)
    p.add_argument("--model", required=True, metavar="MODEL.json", help="`robstiff identify --json` output")
    p.add_argument("--payload", required=True, metavar="PAYLOAD.yaml", help="`robstiff calibrate-payload --yaml` output")
    p.add_argument("--reference", metavar="JOINTS.csv", help="joint reference (t_s, q1_deg..q6_deg) streamed from the "
                                                             "first message; waited for up to --wait-s "
                                                             "(default: hold the first position)")
    p.add_argument("--reference-is-corrected", action="store_true",
                   help="--reference is a corrected reference (compensate-program's joint_reference.csv, marked on "
                        "its first line: the model's deflection correction already in it): streamed with the "
                        "online correction held at zero, every check still run. Without it such a file is refused "
                        "(online compensation on top corrects the deflection twice); with it a file without the "
                        "mark is refused")
    p.add_argument("--log", metavar="DIR", help="stream the run's logs into a run folder (diagnose-run reads it)")
    p.add_argument("--period-ms", type=_number_in(0.5, 100.0, "ms"), default=4.0,
                   help="the controller's cycle: EGM 4 (\\SampleRate), RSI 4 (#IPO_FAST) or 12 (#IPO), Stream Motion "
                        "8 or 4 by controller (default: %(default)s, the shortest of every protocol: a wrong one plays "
                        "the path slower, never faster; a controller at another cycle is named after 25 messages with "
                        "the --period-ms to set, the correction held at zero)")
    p.add_argument("--mode", choices=["plain", "preview"], default="plain",
                   help="plain: the measured force's deflection (the paper's chain); preview: also the job's planned "
                        "path through the arm's dynamics, computed before the stream starts (needs --job; "
                        "docs/real_cell.md) (default: %(default)s)")
    p.add_argument("--job", metavar="SCENARIO.yaml",
                   help="--mode preview's job: its path or program, tool, cutting model, servo and damping; its "
                        "planned path is the joint reference (a --reference given too must be that path)")
    p.add_argument("--preview-sync-ms", type=_number_in(1.0, 1000.0, "ms"), default=25.0,
                   help="the preview falls back to plain when the controller's clock or the arm's feedback is "
                        "more than this behind or ahead of the job's plan (default: %(default)s)")
    p.add_argument("--preview-force-bound-N", type=_number_in(1.0, 1e5, "N"), default=150.0,
                   help="the preview falls back to plain when the measured force departs from the job's model by "
                        "more than this plus half the model's force for 0.1 s (default: %(default)s)")
    p.add_argument("--sensor-rate-hz", type=_number_in(1.0, 20000.0, "Hz"), default=1000.0,
                   help="the Net F/T's RDT output rate, for the filter; records more than 20 %% off it on the "
                        "controller's clock are a fault for the run (default: %(default)s)")
    p.add_argument("--start-tolerance-N", type=_number_in(*START_TOLERANCE_RANGE_N, "N"),
                   default=DEFAULT_START_TOLERANCE_N,
                   help="the sensor's reading at the controller's first message (the tool in the air, the spindle "
                        "off) may differ from what the payload calibration predicts there by this much (N; the "
                        "moments by this at the tool's lever); beyond it a fault for the run, zero correction "
                        "(default: %(default)s; cell/sensor_checks.py says why)")
    p.add_argument("--filter", dest="filter_kind", choices=["lowpass", "revolution_average", "none"], default="lowpass")
    # (commands/compensate.DEFAULT_CUTOFF_HZ: why 2 Hz)
    p.add_argument("--cutoff-hz", type=_number_in(0.01, 10000.0, "Hz"), default=2.0,
                   help="low-pass cutoff (default: %(default)s; a loop the model predicts unstable is refused)")
    p.add_argument("--filter-order", type=_number_in(1, 8, integer=True), default=2)
    p.add_argument("--allow-unstable-loop", action="store_true",
                   help="run even when the loop model predicts the correction loop unstable at the start pose "
                        "(a warning in the text, the log's events and summary.json)")
    p.add_argument("--spindle-rpm", type=_number_in(10.0, 60000.0, "rpm"), default=3600.0,
                   help="for --filter revolution_average (default: %(default)s)")
    p.add_argument("--max-jump-N", type=_number_in(1.0, 1e5, "N"), default=1000.0, help="(default: %(default)s)")
    p.add_argument("--max-jump-Nm", type=_number_in(0.1, 1e5, "N*m"), default=None,
                   help="a moment jumping more is refused (default: --max-jump-N times the tool point's distance "
                        "from the sensor, at least 0.1 m)")
    p.add_argument("--saturation-deg", type=_number_in(0.001, 10.0, "deg"), default=0.5, help="(default: %(default)s)")
    p.add_argument("--max-correction-mm", type=_number_in(0.01, 100.0, "mm"), default=DEFAULT_MAX_CORRECTION_MM,
                   help="in real time, every cycle: the most the streamed correction may move the tool point "
                        "from the reference (mm); beyond it a fault: the correction ramps to zero, the run goes "
                        "on (default: %(default)s; cell/correction_bound.py says why). Not `compensate-program "
                        f"--max-correction-mm` (default {PROGRAM_MAX_CORRECTION_MM:g}), the offline refusal of a "
                        "program's predicted correction; a corrected program's correction is in its reference, not "
                        "counted here")
    p.add_argument("--max-correction-deg", type=_number_in(0.001, 10.0, "deg"), default=DEFAULT_MAX_CORRECTION_DEG,
                   help="the most the correction may turn the tool (deg); beyond it a fault (default: %(default)s)")
    p.add_argument("--rate-limit-deg-per-s", type=_number_in(0.001, 1000.0, "deg/s"), default=5.0,
                   help="(default: %(default)s)")
    p.add_argument("--delay-steps", type=_number_in(0, 100, integer=True), default=0,
                   help="extra controller periods of delay (default: %(default)s; the network adds its own)")
    p.add_argument("--netft-counts", metavar="PER_FORCE,PER_TORQUE", default=None,
                   help="override the sensor's calibration: counts per force unit and per torque unit (with "
                        "--netft-units; default: read from the sensor)")
    p.add_argument("--netft-units", metavar="FORCE,TORQUE", default=None,
                   help="the units of --netft-counts, e.g. N,N-mm (N, lbf, klbf, kN, kgf; N-m, N-mm, lbf-in, "
                        "lbf-ft, kgf-cm, kN-m)")
    p.add_argument("--netft-http-port", type=_number_in(1, 65535, integer=True), default=80,
                   help="TCP port of the sensor's calibration page netftapi2.xml (default: %(default)s)")
    p.add_argument("--netft-open-s", type=_number_in(0.1, 600.0, "s"), default=2.0,
                   help="how long to wait for the sensor's first RDT record before refusing it, on this PC's clock "
                        "(default: %(default)s)")
    p.add_argument("--servo", metavar="DELAY_MS,KP,BW_HZ,FF[,KI_HZ]", default=None,
                   help="the controller's servo for the log's compensator.yaml: interpolator dead time (ms), "
                        "position gain (1/s), velocity bandwidth (Hz), velocity feed-forward (0-1) and, "
                        "optionally, the velocity loop's integral corner (Hz, 0-100; default 7.5)")
    p.add_argument("--cutter-diameter-mm", type=_number_in(0.1, 1000.0, "mm"), default=None,
                   help="the cutter's diameter, for the log's compensator.yaml")
    p.add_argument("--wait-s", type=_number_in(0.1, 3600.0, "s"), default=30.0,
                   help="how long to wait for the controller's first message and for --reference (default: %(default)s)")
    p.add_argument("--duration-s", type=_number_in(0.0, 1e6, "s"), default=0.0, help="end after this long (0: never)")
    p.add_argument("--idle-exit-s", type=_number_in(0.0, 3600.0, "s"), default=0.0,
                   help="end when the controller is silent this long (0: never)")
    p.add_argument("--sensor-timeout-ms", type=_number_in(1.0, 10000.0, "ms"), default=20.0,
                   help="a sensor silent or invalid this long ramps the correction to zero (default: %(default)s)")
    p.add_argument("--rt-priority", type=_number_in(0, 99, integer=True), default=0,
                   help="run the loop under SCHED_FIFO at this priority (Linux, needs the privilege; 0: off)")
    p.add_argument("--cpu", type=_number_in(0, 4095, integer=True), default=None,
                   help="keep the loop's thread on this CPU (Linux; a warning and unpinned when not allowed; "
                        "default: where the scheduler puts it)")
    p.add_argument("--cpu-latency-us", type=_number_in(0, 100000, "us", integer=True), default=None,
                   help="ask the kernel to keep every CPU's wake-up latency within this many microseconds while "
                        "the loop runs (Linux PM QoS, /dev/cpu_dma_latency, as cyclictest does; 0: idle CPUs poll, "
                        "using power; needs the privilege: a warning and not held when not allowed; default: "
                        "not asked)")
