"""The option values every command shares: vectors ('X,Y,Z' with their
allowed ranges), numbers in a range, the tool point and the help texts of
the common options.  Command modules import them from here, not from
commands/main.py or commands/parser.py (main imports the command modules: no circle)."""

import argparse
import re

from robstiff_drake.errors import InputError


# Allowed ranges of the vector options (a tool 5 m from the flange is no
# robot tool; a stiffness outside 1e3-1e9 N*m/rad is no robot joint).
VECTOR_RANGES = {"--tool": (-5000.0, 5000.0, "mm"), "--com-mm": (-2000.0, 2000.0, "mm"),
                 "--mount-rpy": (-360.0, 360.0, "deg"), "--stiffness": (1e3, 1e9, "N*m/rad"),
                 "--work-offset": (-10000.0, 10000.0, "mm")}

# compensate-program's --max-correction-mm (mm): the largest predicted correction of a programmed point it writes
# into a corrected program (beyond it the job is refused, naming the line); compensate's real-time bound of the
# same name is cell/correction_bound.DEFAULT_MAX_CORRECTION_MM
PROGRAM_MAX_CORRECTION_MM = 1.0


def parse_vector(text, n, what):
    """'X,Y,Z' -> list of n floats, with an error that names the bad part
    (and its allowed range, for the options in VECTOR_RANGES)."""
    parts = [p.strip() for p in str(text).split(",")]
    if len(parts) != n:
        raise InputError(f"{what}: expected {n} comma-separated numbers, got {text!r}")
    values = []
    for i, p in enumerate(parts):
        try:
            v = float(p)
        except ValueError:
            raise InputError(f"{what}: component {i + 1} {p!r} is not a number") from None
        if v != v or v in (float("inf"), float("-inf")):
            raise InputError(f"{what}: component {i + 1} {p!r} is not finite")
        lo, hi, unit = VECTOR_RANGES.get(what, (-float("inf"), float("inf"), ""))
        if not lo <= v <= hi:
            raise InputError(f"{what}: component {i + 1} {p!r} is outside the allowed range [{lo:g}, {hi:g}] {unit}")
        values.append(v)
    return values


def number_in(lo, hi, unit="", integer=False):
    """An argparse type: a finite number (whole, if ``integer``) in [lo, hi],
    with an error that gives the range (argparse names the option)."""
    def parse(text):
        try:
            v = int(text) if integer else float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not a {'whole number' if integer else 'number'}"
                                             f" (allowed: [{lo:g}, {hi:g}]{f' {unit}' if unit else ''})") from None
        if v != v or not lo <= v <= hi:
            raise argparse.ArgumentTypeError(f"{text} is outside the allowed range [{lo:g}, {hi:g}]"
                                             + (f" {unit}" if unit else ""))
        return v
    parse.__name__ = "whole number" if integer else "number"
    return parse


# Ranges of the numeric options (wide enough for any real use, narrow enough
# that a typo cannot start a run of hours or allocate more than the machine has).
FORCE_N = number_in(1e-3, 1e5, "N")
SEED = number_in(0, 2**32 - 1, integer=True)
NOISE_MM = number_in(0.0, 10.0, "mm")


def parse_tool(text):
    """--tool 'X,Y,Z' (mm) -> the tool point in metres (numpy), None when not
    given.  A point within a few mm of the flange but not at it (a length
    written in metres: --tool 0.0069,0.2453,0.3193) is a warning, printed and
    carried into the command's JSON; the same line identify gives for it."""
    if text is None:
        return None
    import numpy as np

    from robstiff_drake.command import input_warning
    from robstiff_drake.identification.stiffness.interval_support import tool_looks_like_metres

    tool_m = np.array(parse_vector(text, 3, "--tool")) / 1000.0
    if tool_looks_like_metres(tool_m):
        input_warning(f"--tool: the tool point ({', '.join(f'{v * 1e3:g}' for v in tool_m)}) mm is "
                      f"{np.linalg.norm(tool_m) * 1e3:g} mm from the flange: a length in metres? (write mm)")
    return tool_m


SCENARIO_HELP = "a scenario file, or the name of a packaged one (`robstiff examples` lists them)"
ROBOT_HELP = "a library robot (see `robstiff robots`) or a robot file (YAML); default: irb6400"


def add_robot_option(p, help_text=ROBOT_HELP):
    """A subcommand's ``--robot NAME|YAML`` option."""
    p.add_argument("--robot", metavar="NAME|YAML", default=None, help=help_text)


TOOL_DEFAULT = "the robot file's payload.tool_point_mm"


# other options whose value may start with a minus sign (import-urdf's "-1,1,1,-1,1,-1:0,-90,90,0,0,0")
NEGATIVE_LIST_OPTIONS = {"--controller-map"}


def vector_values_kept(argv):
    """argv with a negative vector value joined to its option
    (``--tool -10,0,350`` -> ``--tool=-10,0,350``): argparse takes a value
    that starts with '-' and is not a plain number for an option."""
    out, i = [], 0
    argv = list(argv)
    while i < len(argv):
        a = argv[i]
        if a == "--":
            return out + argv[i:]
        if (a in VECTOR_RANGES or a in NEGATIVE_LIST_OPTIONS) and i + 1 < len(argv) and \
                _NEGATIVE_LIST.match(argv[i + 1]):
            out.append(f"{a}={argv[i + 1]}")
            i += 2
            continue
        out.append(a)
        i += 1
    return out


_NEGATIVE_LIST = re.compile(r"^-\s*(\d|\.\d|inf|nan)", re.IGNORECASE)


# The real-time interface each maker's controller offers (docs/real_cell.md): the protocol a cell of that
# maker's arm streams with.
PROTOCOL_OF_MAKER = {"ABB": "egm", "KUKA": "rsi", "FANUC": "stream-motion"}
PROTOCOL_NAMES = {"egm": "ABB's EGM", "rsi": "KUKA's RSI", "stream-motion": "FANUC's Stream Motion"}


def protocol_warning(robot, protocol):
    """A warning (printed, carried into the command's JSON) when the robot
    file's manufacturer is one whose controller speaks another protocol than
    ``protocol`` (--controller-protocol, default egm: a FANUC or KUKA cell
    left at the default would wait for EGM messages that never come)."""
    from robstiff_drake.command import input_warning

    maker = str(getattr(robot, "manufacturer", "") or "").strip().upper()
    expected = PROTOCOL_OF_MAKER.get(maker)
    if expected is None or expected == protocol:
        return None
    return input_warning(f"{robot.name} is a {maker} arm ({robot.source}) and --controller-protocol is {protocol} "
                         f"({PROTOCOL_NAMES[protocol]}; the default is egm): a {maker} controller streams with "
                         f"{PROTOCOL_NAMES[expected]}, --controller-protocol {expected}")

