"""The ``robstiff`` command: dispatch only (the parser is
commands/parser.py).

Every subcommand lives in its own module with a keyword-only ``run(...)``;
bad input raises InputError, which becomes one line on stderr and exit
status 2 (no traceback).
"""

import signal
import sys

from robstiff_drake.commands.help_examples import EXAMPLES  # noqa: F401 (re-exported for tests and tools)
from robstiff_drake.commands.options import parse_vector, vector_values_kept
from robstiff_drake.commands.parser import _subcommands, build_parser  # noqa: F401 (_subcommands: re-exported)
from robstiff_drake.errors import INTERRUPTED, InputError, Terminated, excerpt, interrupted, one_line

def _dispatch(args):
    if args.command == "robots":
        from robstiff_drake.commands import robots

        return robots.run(json_out=args.json)
    if args.command == "fk":
        from robstiff_drake.commands import fk

        return fk.run(q=args.q, tool=args.tool, json_out=args.json, robot_yaml=args.robot)
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
                            json_out=args.json, robot_yaml=args.robot, show_progress=args.progress)
    if args.command == "make-urdf":
        from robstiff_drake.commands import make_urdf

        return make_urdf.run(check=args.check, out=args.out, robot_yaml=args.robot)
    if args.command == "import-urdf":
        from robstiff_drake.commands import import_urdf

        return import_urdf.run(urdf=args.urdf, out=args.out, template=args.template, name=args.name,
                               controller_map=args.controller_map)
    if args.command == "identify":
        from robstiff_drake.commands import identify

        return identify.run(data=args.data, tool=args.tool, json_out=args.json, plot=args.plot,
                            robust=args.robust, robot_yaml=args.robot, noise_mm=args.noise_mm)
    if args.command == "calibrate-payload":
        from robstiff_drake.commands import calibrate_payload

        return calibrate_payload.run(data=args.data, json_out=args.json, yaml_out=args.yaml,
                                     mount_rpy=args.mount_rpy, robot_yaml=args.robot)
    if args.command == "synth":
        from robstiff_drake.commands import synth

        if args.kind == "stiffness":
            return synth.run_stiffness(out=args.out, n=args.n, loads_per_pose=args.loads_per_pose,
                                       force_N=args.force_N, noise_mm=args.noise_mm, seed=args.seed, tool=args.tool,
                                       effects=args.effect, stiffness=args.stiffness, robot_yaml=args.robot)
        if args.kind == "tracker":
            return synth.run_tracker(out=args.out, n=args.n, noise_mm=args.noise_mm, seed=args.seed,
                                     export=args.export, robot_yaml=args.robot)
        return synth.run_payload(out=args.out, n=args.n, mass_kg=args.mass_kg, com=args.com_mm,
                                 noise_N=args.noise_N, noise_Nm=args.noise_Nm, seed=args.seed, robot_yaml=args.robot)
    if args.command == "diagnose":
        from robstiff_drake.commands import diagnose

        return diagnose.run(data=args.data, tool=args.tool, json_out=args.json, report=args.report,
                            plots=args.plots, robot_yaml=args.robot, noise_mm=args.noise_mm,
                            validate=args.validate, write_robot=args.write_robot)
    if args.command == "diagnose-run":
        from robstiff_drake.commands import diagnose_run

        return diagnose_run.run(run_dir=args.run_dir, json_out=args.json, out=args.out, noise_mm=args.noise_mm,
                                verify=args.verify, robot_yaml=args.robot, scan=args.scan)
    if args.command == "plan-poses":
        from robstiff_drake.commands import plan_poses

        return plan_poses.run(n=args.n, candidates=args.candidates, force_N=args.force_N, noise_mm=args.noise_mm,
                              tool=args.tool, seed=args.seed, out=args.out, json_out=args.json,
                              robot_yaml=args.robot, separate=args.separate, campaign=args.campaign)
    if args.command == "table2":
        from robstiff_drake.commands import table2

        return table2.run(json_out=args.json, plot_out=args.plot)
    if args.command == "simulate":
        from robstiff_drake.commands import simulate

        return simulate.run(scenario=args.scenario, compensation=args.compensation, json_out=args.json,
                            out=args.out, compensator=args.compensator, noise_seed=args.noise_seed,
                            robot_yaml=args.robot, toolpath=args.toolpath, work_offset=args.work_offset,
                            replay=args.replay, progress=args.progress, advise=args.advise,
                            advise_out=args.advise_out, budget=args.budget, budget_metric=args.budget_metric, budget_split=args.budget_split,
                            tolerance_mm=args.tolerance_mm, stock=args.stock)
    if args.command == "sweep":
        from robstiff_drake.commands import sweep

        return sweep.run(scenario=args.scenario, periods=args.period_ms, delays=args.delay_steps,
                         cutoffs=args.cutoff_hz, modes=args.mode, json_out=args.json, plot_out=args.plot,
                         workers=args.workers, scheduler=args.scheduler, plant_step_ms=args.plant_step_ms,
                         predict=not args.no_predict, progress=args.progress, robot_yaml=args.robot)
    if args.command == "sim-cell":
        from robstiff_drake.commands import sim_cell

        return sim_cell.run(scenario=args.scenario, egm_to=args.egm_to, netft_port=args.netft_port, wait_s=args.wait_s,
                            reference_out=args.reference_out, json_out=args.json, robot_yaml=args.robot,
                            period_ms=args.period_ms, lockstep=args.lockstep, protocol=args.protocol,
                            netft_http_port=args.netft_http_port, scan_out=args.scan_out,
                            transport_delay_cycles=args.transport_delay_cycles,
                            answer_timeout_s=args.answer_timeout_s)
    if args.command == "compensate":
        from robstiff_drake.commands import compensate

        counts = parse_vector(args.netft_counts, 2, "--netft-counts") if args.netft_counts else None
        units = [u.strip() for u in args.netft_units.split(",")] if args.netft_units else None
        if units is not None and len(units) != 2:
            raise InputError(f"--netft-units: expected FORCE,TORQUE (e.g. N,N-mm), got {args.netft_units!r}")
        n_servo = 5 if args.servo and args.servo.count(",") == 4 else 4
        if args.servo and args.servo.count(",") not in (3, 4):
            raise InputError(f"--servo: expected 4 or 5 comma-separated numbers (DELAY_MS,KP,BW_HZ,FF[,KI_HZ]), got "
                             f"{excerpt(args.servo)}")
        servo = parse_vector(args.servo, n_servo, "--servo") if args.servo else None
        if servo is not None and (min(servo[:3]) <= 0 or not 0 <= servo[3] <= 1 or servo[0] > 1000
                                  or (n_servo == 5 and not 0 <= servo[4] <= 100)):
            raise InputError(f"--servo {args.servo}: expected a dead time in (0, 1000] ms, a gain > 0 1/s, a "
                             "bandwidth > 0 Hz, a feed-forward in [0, 1] and, optionally, an integral corner "
                             "in [0, 100] Hz")
        if args.filter_kind == "lowpass" and not args.cutoff_hz < 0.5 * args.sensor_rate_hz:
            raise InputError(f"--cutoff-hz: cutoff {args.cutoff_hz:g} Hz must be between 0 and the Nyquist rate "
                             f"{0.5 * args.sensor_rate_hz:g} Hz (half --sensor-rate-hz)")
        if not args.sensor_timeout_ms > 1e3 / args.sensor_rate_hz:
            # (every gap between two records would be a silence: the sensor's fault would begin again after
            # each record and, three times in a row, hold the correction at zero as a stream too slow)
            raise InputError(f"--sensor-timeout-ms {args.sensor_timeout_ms:g}: must be longer than the time between "
                             f"two records at --sensor-rate-hz {args.sensor_rate_hz:g} "
                             f"({1e3 / args.sensor_rate_hz:.4g} ms)")
        if args.listen_port is None and args.protocol != "stream-motion":
            raise InputError(f"--listen-port (--egm-port) is required for --controller-protocol {args.protocol}")
        return compensate.run(listen_port=args.listen_port or 0, netft=args.netft, robot_yaml=args.robot,
                              model=args.model, payload=args.payload, reference=args.reference, log=args.log,
                              period_ms=args.period_ms, sensor_rate_hz=args.sensor_rate_hz,
                              filter_kind=args.filter_kind, cutoff_hz=args.cutoff_hz, filter_order=args.filter_order,
                              spindle_rpm=args.spindle_rpm, max_jump_N=args.max_jump_N, max_jump_Nm=args.max_jump_Nm,
                              saturation_deg=args.saturation_deg, rate_limit_deg_per_s=args.rate_limit_deg_per_s,
                              max_correction_mm=args.max_correction_mm, max_correction_deg=args.max_correction_deg,
                              delay_steps=args.delay_steps, netft_counts=counts, netft_units=units,
                              netft_http_port=args.netft_http_port,
                              netft_open_s=args.netft_open_s, wait_s=args.wait_s, duration_s=args.duration_s,
                              idle_exit_s=args.idle_exit_s, sensor_timeout_ms=args.sensor_timeout_ms,
                              rt_priority=args.rt_priority, cpu=args.cpu, cpu_latency_us=args.cpu_latency_us,
                              controller=args.controller,
                              protocol=args.protocol,
                              servo=servo, cutter_diameter_mm=args.cutter_diameter_mm,
                              allow_unstable_loop=args.allow_unstable_loop, mode=args.mode, job=args.job,
                              preview_sync_ms=args.preview_sync_ms,
                              preview_force_bound_N=args.preview_force_bound_N,
                              reference_is_corrected=args.reference_is_corrected,
                              start_tolerance_N=args.start_tolerance_N)
    if args.command == "compensate-program":
        from robstiff_drake.commands import compensate_program

        return compensate_program.run(job=args.job, out=args.out, json_out=args.json, chord_mm=args.chord_mm,
                                      max_correction_mm=args.max_correction_mm, robot_yaml=args.robot,
                                      simulate=not args.no_simulate, show_progress=args.progress,
                                      rounds=args.refine_rounds, advise=args.advise)
    if args.command == "examples":
        from robstiff_drake.commands import examples

        return examples.run(copy=args.copy)
    if args.command == "demo":
        from robstiff_drake.commands import demo

        return demo.run(out=args.out, robot_yaml=args.robot)
    raise AssertionError(args.command)


# An error is one line of at most this many characters (a message that
# quotes a file name or a value is escaped and shortened, whatever they hold).
MAX_ERROR_CHARS = 1000


def _error_text(e):
    text = one_line(e)
    return text if len(text) <= MAX_ERROR_CHARS else text[:MAX_ERROR_CHARS - 3] + "..."


# An error's detail (an InputError's ``why``: the numbers behind a refusal whose line says what is wrong and the
# fix, e.g. the plant step's, diagrams/plant_step.py) follows its line, indented, wrapped to this width.
WHY_WIDTH = 100


def _why_text(e):
    """The error's indented 'why' section ('' when it has none)."""
    why = getattr(e, "why", None)
    if not why:
        return ""
    import textwrap

    return textwrap.fill(one_line(why)[:4 * MAX_ERROR_CHARS], width=WHY_WIDTH, initial_indent="  why: ",
                         subsequent_indent="       ", break_on_hyphens=False)


def _on_sigterm(signum, frame):
    raise Terminated()


STOP_TRACE_ENV = "ROBSTIFF_STOP_TRACE"


def _stop_trace(e):
    """With ROBSTIFF_STOP_TRACE set (the tests' scripted runs set it), where
    the SIGTERM that ended the command landed, innermost first: a run that
    should have ended on it by itself (compensate's loop) but did not says
    where it was (a diagnosis aid; nothing is said without the variable)."""
    import os

    if not os.environ.get(STOP_TRACE_ENV):
        return
    import traceback

    frames = traceback.extract_tb(e.__traceback__)[::-1][:6]
    print("robstiff: (stop trace) " + " <- ".join(f"{os.path.basename(f.filename)}:{f.lineno} {f.name}"
                                                  for f in frames), file=sys.stderr)


def main(argv=None):
    try:
        previous = signal.signal(signal.SIGTERM, _on_sigterm)
    except ValueError:  # not the main thread (e.g. called from a worker): leave signals alone
        previous = None
    from robstiff_drake.progress import set_quiet

    was_quiet = None
    try:
        args = build_parser().parse_args(vector_values_kept(sys.argv[1:] if argv is None else argv))
        was_quiet = set_quiet(getattr(args, "quiet", False))
        from robstiff_drake.commands.preflight import check_inputs

        check_inputs(args)  # the named inputs exist, before any heavy import
        from robstiff_drake.command import command_scope

        with command_scope():
            return _dispatch(args) or 0
    except InputError as e:
        prog = getattr(e, "prog", "robstiff")
        print(f"{prog}: error: {_error_text(e)}", file=sys.stderr)
        why = _why_text(e)
        if why:
            print(why, file=sys.stderr)
        return 2
    except BrokenPipeError:  # e.g. `robstiff demo | head`
        import os

        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    except KeyboardInterrupt:
        print("robstiff: interrupted", file=sys.stderr)
        return 130
    except ImportError as e:
        # a Ctrl-C inside a command's own lazy import (Drake's, seconds into `simulate` on a loaded machine):
        # the extension module turns it into "ImportError: initialization failed" (was a traceback, exit 1)
        if not interrupted(e):
            raise
        print("robstiff: interrupted", file=sys.stderr)
        return INTERRUPTED
    except Terminated as e:
        print("robstiff: terminated", file=sys.stderr)
        _stop_trace(e)
        return 143
    except MemoryError:
        print("robstiff: error: out of memory", file=sys.stderr)
        return 2
    finally:
        if was_quiet is not None:
            set_quiet(was_quiet)
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)


if __name__ == "__main__":
    sys.exit(main())
