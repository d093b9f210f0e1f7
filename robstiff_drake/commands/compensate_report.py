"""The end of a ``robstiff compensate`` run: its lines on standard error
(the cycles, the preview, the health verdict) and, with ``--log``, its
summary.json (commands/compensate.py runs the loop; this says what it did)."""

import sys

from robstiff_drake.progress import wrote


def report(loop, link, guard, background, stream_log, *, log, job, inputs, notes, missing):
    """Say how the run went.  ``inputs``: summary.json's description of the
    run (protocol first, then the endpoints, files and settings); ``notes``:
    (the play's warning or None, the play's summary, the correction bound's
    warning or None, the payload calibration's warnings: a list);
    ``missing``: (--servo, --cutter-diameter-mm) as given."""
    play_line, play_summary, bound_line, start_warnings = notes
    stats = loop.stats()
    cm = stats["compute_ms"]
    print(f"robstiff: compensate: {stats['messages']} messages, {stats['answered']} answered; computation per message "
          f"median {cm['median']:.3f} ms, p99 {cm['p99']:.3f} ms, max {cm['max']:.3f} ms{_response(stats)}; correction "
          f"age median "
          f"{stats['correction_age_ms']['median']:.2f} ms; {stats['late']} late, {stats['unanswered']} unanswered; "
          f"{stats['fault_onsets']} faults; {stats['strangers_dropped']} datagrams from strangers dropped",
          file=sys.stderr)
    checks = _sensor_check_lines(stats["sensor_checks"])
    for line in checks:
        print(f"robstiff: warning: compensate: {line}", file=sys.stderr)
    h = stats["health"]
    table = "disk cache" if job is not None and background is None else background.note() if background else None
    if background is not None and loop.preview is None:
        print(f"robstiff: warning: compensate: preview: the job's table {table}", file=sys.stderr)
    if loop.preview is not None:
        pv = loop.preview.summary()
        fb = pv["fallback"]
        until = "to the end" if fb is None else f"until t = {fb['t_s']:.3f} s ({fb['why']})"
        print(f"robstiff: compensate: preview {until}; force scales "
              f"{', '.join(f'{v:.2f}' for v in pv['force_scales'])}; the arm's offset from the plan at most "
              f"{pv['max_plan_offset_ms']:.1f} ms; the force's departure from the model at most "
              f"{pv['max_force_departure_N']:.0f} N", file=sys.stderr)
    print(f"robstiff: {'warning: ' if h['verdict'] != 'good' else ''}compensate: {h['line']}", file=sys.stderr)
    if stream_log is None:
        return
    rest = {key: v for key, v in inputs.items() if key != "protocol"}
    summary = {"command": "compensate", "protocol": inputs["protocol"], "listen_port": link.port, **rest,
               "preview": loop.preview.summary() if loop.preview is not None else None,
               "preview_table": table,
               "cycles": stats, "health": h, "loop_check": guard.result, "play": play_summary,
               "warnings": ([h["line"]] if h["verdict"] != "good" else []) + ([guard.warning] if guard.warning else [])
               + list(start_warnings) + ([play_line] if play_line else []) + ([bound_line] if bound_line else [])
               + checks}
    written = stream_log.close(summary)
    if written:
        wrote(log, ", ".join(written), folder=True, to_stderr=True)
    else:  # (stopped before its start had opened the folder: an earlier run's folder there is as it was)
        print(f"robstiff: warning: compensate: the run ended before its log folder {log} was opened: no log written",
              file=sys.stderr)
    servo, cutter_diameter_mm = missing
    if servo is None or cutter_diameter_mm is None:
        print("robstiff: note: compensator.yaml lacks " + " and ".join(
            x for x, v in (("the controller's servo (--servo)", servo),
                           ("tool.cutter_diameter_mm (--cutter-diameter-mm)", cutter_diameter_mm)) if v is None)
              + "; diagnose-run needs them", file=sys.stderr)


def _response(stats):
    """The end line's part on the time from a datagram's arrival at this PC
    (the kernel's stamp) to its answer ("" where the system gives none)."""
    r = stats["response_ms"]
    if not r["stamped"]:
        return ""
    return (f" (from its arrival at this PC, with the wait to be read: p99 {r['p99']:.3f} ms, max {r['max']:.3f} ms, "
            f"{r['over_period']} over a period)")


def _sensor_check_lines(checks):
    """The lines (warnings) of the sensor's checks that held the correction
    at zero for the run (cell/sensor_checks.py): [] when both passed (a
    scale the start's pose could not check is a note of the run's course,
    kept in summary.json's sensor_checks.start.unchecked)."""
    out = []
    st, rate = checks["start"], checks["rate"]
    if st is not None and not st["passed"]:
        out.append(f"the sensor's reading at the start was {st['apart_N']:.4g} N and {st['apart_Nm']:.4g} N*m from "
                   f"the payload calibration's prediction (at most {st['tolerance_N']:g} N, "
                   f"{st['tolerance_Nm']:.3g} N*m): the correction was held at zero for the run")
    if rate is not None and rate["fault"] is not None:
        out.append(f"the sensor's records came at {rate['fault']:.4g} Hz, not the {rate['configured_hz']:g} Hz "
                   "configured (--sensor-rate-hz): the correction was held at zero from then on")
    return out
