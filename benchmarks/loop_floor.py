"""The machine's floor for a real-time answer loop, a reference for
`compensate`'s per-message p99 (benchmarks/bench_compensate.py runs it
after each protocol, at the loop's own median): a process scheduled as the
loop is (one CPU, SCHED_FIFO, the CPU latency request) waits in select()
for a datagram that a second process sends every period, as a controller
does, reads it with the kernel's arrival stamp, runs a fixed Python
workload of ``--work-us`` (a plain arithmetic loop touching no memory to
speak of, calibrated before the run) and answers.  Its computation
(select's return -> the answer's sendto) and response (the kernel's stamp
-> the answer) are what any Python loop of that median gets on this
machine: the spread above the median is the platform's (interrupts, a
virtual machine's host, the wake-up), not a program's.  ``--work-us 0``:
the receive and the send alone.

    python benchmarks/loop_floor.py --work-us 140 --seconds 20 --cpu 0 --rt-priority 50 --cpu-latency-us 0
"""

import argparse
import json
import os
import select
import socket
import struct
import subprocess
import sys
import time

SO_TIMESTAMPNS = getattr(socket, "SO_TIMESTAMPNS", 35)  # (Linux's value; Python's socket module lacks the name)
PERIOD_S = 0.004
SKIP = 10  # the first messages (the sender's and the loop's start) are not counted

# the controller stand-in: a datagram every period on its own schedule (slept to within 0.5 ms, then spun)
SENDER = """
import socket, sys, time
port, seconds, period = int(sys.argv[1]), float(sys.argv[2]), float(sys.argv[3])
s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
t = time.monotonic()
end = t + seconds
while t < end:
    t += period
    while time.monotonic() < t - 0.0005:
        time.sleep(0.0003)
    while time.monotonic() < t:
        pass
    s.sendto(b"m" * 64, ("127.0.0.1", port))
"""


def _work(n):
    s = 0.0
    for i in range(n):
        s += i * 0.5
    return s


def calibrate(work_us):
    """The loop count of ``_work`` that takes ``work_us`` (us; the fastest
    of five tries, so that a stall during calibration does not shrink it)."""
    if work_us <= 0:
        return 0
    n = 2000
    best = min(_timed(n) for _ in range(5))
    return max(1, int(n * work_us * 1e-6 / best))


def _timed(n):
    t0 = time.perf_counter()
    _work(n)
    return time.perf_counter() - t0


def _pct(xs, q):
    xs = sorted(xs)
    return xs[min(len(xs) - 1, int(round(q / 100.0 * (len(xs) - 1))))]


def floor(work_us, seconds, cpu=None, priority=0, cpu_latency_us=None):
    """{work_us, messages, computation_us: {median, p99, max}, response_us:
    {median, p99, max}, scheduling}: the run described in the module docstring."""
    n = calibrate(work_us)
    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    rx.bind(("127.0.0.1", 0))
    rx.setblocking(False)
    rx.setsockopt(socket.SOL_SOCKET, SO_TIMESTAMPNS, 1)
    sched = []
    if cpu is not None:
        try:
            os.sched_setaffinity(0, {cpu})
            sched.append(f"CPU {cpu}")
        except (AttributeError, OSError):
            pass
    if priority:
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
            sched.append(f"SCHED_FIFO {priority}")
        except (AttributeError, OSError):
            sched.append("normal scheduling (SCHED_FIFO not permitted)")
    latency_fd = None
    if cpu_latency_us is not None:
        try:
            latency_fd = os.open("/dev/cpu_dma_latency", os.O_WRONLY)
            os.write(latency_fd, struct.pack("i", int(cpu_latency_us)))
            sched.append(f"CPU latency request {cpu_latency_us} us")
        except OSError:
            sched.append("no CPU latency request (not permitted)")
    sender = subprocess.Popen([sys.executable, "-c", SENDER, str(rx.getsockname()[1]), str(seconds + 0.5),
                               str(PERIOD_S)])
    import gc

    gc.disable()
    comp, resp = [], []
    try:
        t_end = time.monotonic() + seconds
        while time.monotonic() < t_end:
            select.select([rx], [], [], 0.1)
            t_recv, wall = time.monotonic(), time.time()
            try:
                _, anc, _, addr = rx.recvmsg(256, 64)
            except BlockingIOError:
                continue
            stamp = struct.unpack("qq", anc[0][2][:16]) if anc else None
            _work(n)
            rx.sendto(b"a" * 64, addr)
            t_done = time.monotonic()
            comp.append((t_done - t_recv) * 1e6)
            if stamp is not None:
                resp.append((t_done - t_recv + wall - (stamp[0] + stamp[1] * 1e-9)) * 1e6)
    finally:
        gc.enable()
        sender.kill()
        sender.wait()
        rx.close()
        if latency_fd is not None:
            os.close(latency_fd)
    comp, resp = comp[SKIP:], resp[SKIP:]

    def summary(xs):
        return {"median": _pct(xs, 50), "p99": _pct(xs, 99), "max": max(xs)} if xs else None

    return {"work_us": work_us, "messages": len(comp), "computation_us": summary(comp),
            "response_us": summary(resp), "scheduling": ", ".join(sched) or "normal scheduling"}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--work-us", type=float, default=0.0)
    ap.add_argument("--seconds", type=float, default=20.0)
    ap.add_argument("--cpu", type=int, default=None)
    ap.add_argument("--rt-priority", type=int, default=0)
    ap.add_argument("--cpu-latency-us", type=int, default=None)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    r = floor(args.work_us, args.seconds, args.cpu, args.rt_priority, args.cpu_latency_us)
    if args.json:
        print(json.dumps(r))
        return 0
    c, s = r["computation_us"], r["response_us"]
    print(f"a loop of {args.work_us:g} us of fixed work per message ({r['scheduling']}; {r['messages']} messages, "
          f"{args.seconds:g} s; us): computation median {c['median']:.0f}, p99 {c['p99']:.0f}, max {c['max']:.0f}"
          + (f"; response median {s['median']:.0f}, p99 {s['p99']:.0f}, max {s['max']:.0f}" if s else ""))
    return 0


if __name__ == "__main__":
    sys.exit(main())
