"""The machine's own stalls, a reference for the compensator's worst
cycle (benchmarks/bench_compensate.py runs it before each protocol): a
thread on one CPU under SCHED_FIFO at priority 99 (above everything of
this project's, the compensator's loop included) sleeps 0.2 ms at a time,
as cyclictest does, and records every wake-up that came more than 1 ms
after the one before.  Nothing in the system schedules above it, so such a
gap is the platform's (a virtual machine's CPU not running: its host's
scheduling, or an interrupt storm), not a program's: a compensator on that
CPU cannot answer faster than it.  The CPU's steal time (/proc/stat, in
1/100 s) is printed beside it.

    python benchmarks/stall_probe.py --cpu 0 --seconds 10
"""

import argparse
import json
import os
import sys
import time

SLEEP_S = 0.0002
GAP_S = 0.001  # a wake-up later than this after the one before is a stall (the sleep itself is 0.2 ms)


def steal_jiffies(cpu):
    """The steal time of ``cpu`` so far (1/100 s; None off Linux or in a
    system without it)."""
    try:
        with open("/proc/stat") as f:
            for line in f:
                if line.startswith(f"cpu{cpu} "):
                    fields = line.split()
                    return int(fields[8]) if len(fields) > 8 else None
    except OSError:
        return None
    return None


def probe(cpu, priority, seconds):
    """Run the probe on ``cpu`` for ``seconds``; {wakeups, gaps_over_1ms,
    gaps_over_3ms, max_gap_ms (the longest, None when none was over 1 ms),
    cpu, scheduling (what it got), steal_s (the CPU's steal time meanwhile,
    s; None where unknown), phases_ms (where the wake-ups after a gap over
    3 ms fell on a 100 ms grid of the monotonic clock, ms: a host's CPU
    quota per 100 ms period puts them at one phase)}."""
    sched = "normal"
    try:
        os.sched_setaffinity(0, {cpu})
    except (AttributeError, OSError):
        cpu = None
    if priority:
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
            sched = f"SCHED_FIFO {priority}"
        except (AttributeError, OSError):
            pass
    s0 = steal_jiffies(cpu) if cpu is not None else None
    t_end = time.monotonic() + seconds
    last = time.monotonic()
    over = []  # (the gaps over GAP_S only)
    phases = []  # (the phase of the wake-ups after a gap over 3 ms on a 100 ms grid of time.monotonic, ms)
    n = 0
    while last < t_end:
        time.sleep(SLEEP_S)
        now = time.monotonic()
        if now - last > GAP_S:
            over.append(now - last)
            if now - last > 0.003 and len(phases) < 50:
                phases.append(round((now % 0.1) * 1e3, 1))
        last = now
        n += 1
    s1 = steal_jiffies(cpu) if cpu is not None else None
    return {"wakeups": n, "gaps_over_1ms": len(over), "gaps_over_3ms": sum(g > 0.003 for g in over),
           "max_gap_ms": max(over) * 1e3 if over else None, "cpu": cpu, "scheduling": sched,
           "steal_s": (s1 - s0) / 100.0 if s0 is not None and s1 is not None else None,
           "phases_ms": phases}


def longest(r):
    return f", the longest {r['max_gap_ms']:.2f} ms" if r["max_gap_ms"] is not None else ""


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cpu", type=int, default=0)
    ap.add_argument("--priority", type=int, default=99, help="SCHED_FIFO priority (0: normal scheduling)")
    ap.add_argument("--seconds", type=float, default=10.0)
    ap.add_argument("--json", action="store_true", help="print the summary as JSON")
    a = ap.parse_args()
    r = probe(a.cpu, a.priority, a.seconds)
    if a.json:
        print(json.dumps(r))
    else:
        print(f"CPU {r['cpu']}, {r['scheduling']}, {a.seconds:g} s: {r['wakeups']} wake-ups, {r['gaps_over_1ms']} "
              f"gaps over 1 ms ({r['gaps_over_3ms']} over 3 ms){longest(r)}; steal "
              f"{r['steal_s']} s; load average {os.getloadavg()[0]:.2f}"
              + (f"; the wake-ups after a gap over 3 ms at {', '.join(map(str, r['phases_ms']))} ms of a 100 ms "
                 "grid" if r["phases_ms"] else ""))
    return 0


if __name__ == "__main__":
    sys.exit(main())
