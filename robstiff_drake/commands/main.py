"""The ``robstiff`` command: argument parsing and dispatch only.

Every subcommand lives in its own module with a keyword-only ``run(...)``;
bad input raises InputError, which becomes one line on stderr and exit
status 2 (no traceback).
"""

import argparse
import sys

from robstiff_drake.errors import InputError


class _UsageError(InputError):
    def __init__(self, prog, message):
        super().__init__(message)
        self.prog = prog


class _Parser(argparse.ArgumentParser):
    """argparse with a one-line error (the usage stays under --help)."""

    def error(self, message):
        raise _UsageError(self.prog, message)


def parse_vector(text, n, what):
    """'X,Y,Z' -> list of n floats, with an error that names the bad part."""
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
        values.append(v)
    return values


def _add_robot_option(p):
    p.add_argument("--robot", metavar="YAML", default=None,
                   help="robot parameter file (default: models/irb6400.yaml)")


def _add_tool_option(p, default_help):
    p.add_argument("--tool", metavar="X,Y,Z", default=None,
                   help="tool point in the flange frame (DH frame 6), mm; "
                        f"{default_help}. Write negative values as --tool=-10,0,350")


def build_parser():
    parser = _Parser(prog="robstiff", description="Joint-stiffness models and compensation for machining robots.")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    sub.required = True

    p = sub.add_parser("stiffness", help="Cartesian compliance and stiffness at one configuration")
    p.add_argument("q", nargs="*", metavar="Q", help="six joint angles in degrees (controller convention, Table 1)")
    _add_tool_option(p, "default: the origin of DH frame 6")
    p.add_argument("--kx", action="store_true",
                   help="also print the 6x6 Cartesian stiffness K_x (an error at a singular pose)")
    p.add_argument("--json", metavar="OUT", help="write a JSON object to OUT ('-' for stdout)")
    _add_robot_option(p)

    p = sub.add_parser("stiffness-map", help="PNG map of the deflection under a tool force over the workspace")
    p.add_argument("--out", default="robstiff-out/stiffness_map.png", help="PNG path (default: %(default)s)")
    p.add_argument("--force-N", type=float, default=500.0, help="force magnitude at the tool (default: %(default)s N)")
    p.add_argument("--resolution", type=int, default=41, help="grid points per side (default: %(default)s)")
    _add_tool_option(p, "default: the spindle's tool point from the robot file")
    _add_robot_option(p)

    p = sub.add_parser("kg-study", help="how much the CCT term K_g changes the deflection over machining poses")
    p.add_argument("--grid", type=int, default=5, help="grid points per axis of the workspace box (default: %(default)s)")
    p.add_argument("--force-N", type=float, default=500.0, help="tool force magnitude (default: %(default)s N)")
    p.add_argument("--payload-kg", type=float, default=150.0, help="payload mass (default: %(default)s kg)")
    p.add_argument("--json", metavar="OUT", help="write the results as JSON ('-' for stdout)")
    _add_robot_option(p)

    p = sub.add_parser("make-urdf", help="regenerate models/irb6400/ (URDF and package.xml) from the YAML")
    p.add_argument("--check", action="store_true", help="only check that the files on disk are up to date")
    _add_robot_option(p)

    p = sub.add_parser("demo", help="the main job: stiffness at the machining pose, K_g check and stiffness map")
    p.add_argument("--out", default="robstiff-out", help="output folder (default: %(default)s)")
    return parser


def _dispatch(args):
    if args.command == "stiffness":
        from robstiff_drake.commands import stiffness

        return stiffness.run(q=args.q, tool=args.tool, kx=args.kx, json_out=args.json, robot_yaml=args.robot)
    if args.command == "stiffness-map":
        from robstiff_drake.commands import stiffness_map

        return stiffness_map.run(out=args.out, force_N=args.force_N, resolution=args.resolution,
                                 tool=args.tool, robot_yaml=args.robot)
    if args.command == "kg-study":
        from robstiff_drake.commands import kg_study

        return kg_study.run(grid=args.grid, force_N=args.force_N, payload_kg=args.payload_kg,
                            json_out=args.json, robot_yaml=args.robot)
    if args.command == "make-urdf":
        from robstiff_drake.commands import make_urdf

        return make_urdf.run(check=args.check, robot_yaml=args.robot)
    if args.command == "demo":
        from robstiff_drake.commands import demo

        return demo.run(out=args.out)
    raise AssertionError(args.command)


def main(argv=None):
    try:
        args = build_parser().parse_args(argv)
        return _dispatch(args) or 0
    except InputError as e:
        prog = getattr(e, "prog", "robstiff")
        print(f"{prog}: error: {e}", file=sys.stderr)
        return 2
    except BrokenPipeError:  # e.g. `robstiff demo | head`
        import os

        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    except KeyboardInterrupt:
        print("robstiff: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
