"""A compensator run's figures and its health verdict, from the loop's
counters (cell/health.py): the dict summary.json and the last lines
print."""

from robstiff_drake.cell.health import BIN_MS, verdict


def loop_stats(loop):
    """The run's figures and its health (a dict for the JSON) of ``loop``
    (a cell/compensate.CompensatorLoop after its run)."""
    n, T = loop.n, loop.s.period_s
    unanswered = n.skipped + n.unanswered_refused + n.lost
    cycles = n.received + n.lost
    lost = n.lost_estimate.fraction()
    sensor_faults = n.sensor_faults
    seen = (f"seen of the controller: {n.received} messages ({n.start_backlog} waiting at the start, before "
            f"its first target: not late), {n.lost} lost on the way, {n.gaps_over} gaps over "
            f"1.5 periods; of the sensor: {n.sensor_records} records, {sensor_faults} sensor faults; the "
            "controller sees only the answers (its own verdict counts those), not the correction this side "
            "ramped down for its faults")
    late = n.late + n.over_deadline
    deadline_ms = loop.deadline_s * 1e3
    word, reasons, line = verdict(cycles=cycles, answered=n.answered, late=late, unanswered=unanswered,
                                  faults=n.fault_onsets, lost_fraction=lost, refused=n.refused, seen=seen,
                                  over_deadline=n.over_deadline, deadline_ms=deadline_ms)
    # late: every answer the controller's next cycle came without: the next message already waiting when it
    # left (late_next_waiting), or it left more than the controller's cycle after its own arrival at this PC,
    # the kernel's stamp (late_over_deadline: the controller runs on its own clock)
    return {"messages": n.received, "cycles": cycles, "answered": n.answered, "late": late,
            "late_next_waiting": n.late, "late_over_deadline": n.over_deadline, "answer_deadline_ms": deadline_ms,
            "start_backlog": n.start_backlog,
            "unanswered": unanswered, "skipped": n.skipped, "lost_in_network": n.lost,
            "duplicates_dropped": n.duplicates,
            "between_cycles_dropped": n.between_cycles, "old_dropped": n.old, "sequence_jumps": n.jumps,
            "clock_faults": n.clock_faults, "strangers_dropped": loop.link.strangers,
            "controller_port_switches": getattr(loop.link, "port_switches", 0),
            "malformed": loop.link.malformed, "targets_refused": n.refused,
            "compute_ms": n.compute_ms.summary(), "correction_age_ms": n.age_ms.summary(),
            # (from the datagram's arrival at this PC, the kernel's stamp: with the wait to be read; the answers
            # later than a period after it, the controller's cycle)
            "response_ms": dict(n.response_ms.summary(), stamped=n.response_ms.n,
                                over_period=int(sum(n.response_ms.counts[int(T * 1e3 / BIN_MS):]))),
            "message_gap_ms": n.gap_ms.summary(),
            "gc_ms": dict(n.gc_ms.summary(), collections=n.gc_ms.n), "missed_cycles": int(n.skipped + late),
            "controller_gaps": n.gaps_over, "over_budget": int(sum(n.compute_ms.counts[int(T * 1e3 / BIN_MS):])),
            "sensor_records": n.sensor_records, "sensor_clipped": n.sensor_clipped,
            "moment_spikes": n.moment_spikes, "saturated_cycles": n.saturated_cycles,
            "stale_correction_s": n.stale_s,
            # (the played reference's stops and restarts within the robot's accelerations: cell/reference_rate.py;
            # None: the allowance played as it is, no acceleration limits or a held reference)
            "reference_rate": loop.rate.summary() if getattr(loop, "rate", None) is not None else None,
            "fault_onsets": n.fault_onsets, "ended_by": loop.ended_by,
            # (the correction's tool-motion bound: faults, cycles beyond, the largest sent; cell/correction_bound.py)
            "correction_bound": loop.bound.summary() if getattr(loop, "bound", None) is not None else None,
            # (the start's reading against the payload calibration, the record rate: cell/sensor_checks.py)
            "sensor_checks": {"start": getattr(loop, "start_check", None), "rate": getattr(loop, "rate_check", None)},
            "faults": [{"t_s": t, "t_controller_s": tc, "event": e} for t, tc, e in n.events], "events_dropped": n.events_dropped,
            "health": {"verdict": word, "reasons": reasons, "compensation_lost_fraction": lost, "line": line,
                       "seen_of_the_other_side": {"controller_messages": n.received, "lost_on_the_way": n.lost,
                                                  "controller_gaps": n.gaps_over,
                                                  "sensor_records": n.sensor_records,
                                                  "sensor_faults": sensor_faults}}}
