"""Benchmark: `robstiff compensate --reference` on a long joint reference
(default 1,005,000 rows: a 67-minute path at the 4 ms controller period,
about 84 MB of CSV), as a separate process against the simulated cell
(cell/sim_cell.py, its stand-in arm holding the path's start): the time
from the process's start to its "waiting for ... messages" line (the
reference read, checked and prepared; the loop starts after it), to the
first answer the cell receives, and the process's peak resident memory.

The references of the same run: the same command with a 100-row
reference (the process's fixed cost: imports, sensor, model) and
numpy.loadtxt reading the long file (the maintained parser's time and
peak memory, in a child process).  Targets: the long path's extra peak
(over the short one's) at most 400 bytes a row and the whole peak at most
1 GB; its extra time before the loop at most 8 x numpy.loadtxt's.  Exit
status 1 when one is missed.  (Before the one-pass reader: 3.2 GB and
54 s before the loop at a million rows.)

    python benchmarks/bench_long_reference.py              # 1,005,000 rows
    python benchmarks/bench_long_reference.py --rows 200000

The machine is shared (2 cores): the load average is printed with the
figures.
"""

import argparse
import os
import resource
import subprocess
import sys
import tempfile
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "tests"))
import cell_helpers as h  # noqa: E402

from robstiff_drake.model.robot import load_robot  # noqa: E402

BYTES_PER_ROW, PEAK_MB, TIME_RATIO = 400.0, 1024.0, 8.0


def write_reference(path, q0_deg, rows, period_s=0.004):
    """A slow joint path (each joint +-3 deg over a minute) around
    ``q0_deg``, ``rows`` rows at ``period_s``, written in blocks."""
    with open(path, "w") as f:
        f.write("# benchmark: a long slow joint path\nt_s," + ",".join(f"q{j}_deg" for j in range(1, 7)) + "\n")
        for start in range(0, rows, 100000):
            t = np.arange(start, min(start + 100000, rows)) * period_s
            q = q0_deg + 3.0 * np.sin(2 * np.pi * t[:, None] / 60.0 + np.arange(6))
            q -= 3.0 * np.sin(np.arange(6))  # the path starts at q0
            block = np.column_stack([t, q])
            np.savetxt(f, block, fmt=["%.4f"] + ["%.9f"] * 6, delimiter=",")


def loadtxt_reference(path):
    """(seconds, peak MB) of numpy.loadtxt on the file, in a child process."""
    code = ("import resource, time, numpy as np, sys; t0 = time.perf_counter(); "
            "a = np.loadtxt(sys.argv[1], delimiter=',', comments='#', skiprows=2); "
            "print(time.perf_counter() - t0, resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0)")
    out = subprocess.run([sys.executable, "-c", code, path], capture_output=True, text=True, check=True).stdout
    s, mb = out.split()
    return float(s), float(mb)


def run_compensate(folder, robot, ref_path, q0_rad):
    """(s to the 'waiting for' line, s to the process's end, peak MB, return code, stderr's last lines)."""
    model, payload, _, _ = h.write_inputs(folder, robot, duration_s=0.1)
    egm_port, netft_port = h.free_udp_port(), h.free_udp_port()
    th, net = h.start_cell(robot, lambda t: q0_rad, egm_port=egm_port, netft_port=netft_port, duration_s=600.0)
    cmd = h.compensate_cmd(model, payload, ref_path, egm_port=egm_port, netft_port=netft_port,
                           extra=["--duration-s", "0.5", "--wait-s", "600"])
    before = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, cwd=h.ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    ready_s, lines = None, []
    for line in proc.stderr:
        lines.append(line.rstrip())
        if ready_s is None and "waiting for" in line:
            ready_s = time.perf_counter() - t0
    proc.wait()
    end_s = time.perf_counter() - t0
    peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    net.stop = True
    th.join(30)
    net.close()
    if peak <= before:
        print("note: an earlier child's peak was higher; this figure is that peak (an upper bound)")
    return ready_s, end_s, peak / 1024.0, proc.returncode, lines[-3:]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rows", type=int, default=1005000)
    args = ap.parse_args(argv)
    robot = load_robot()
    with tempfile.TemporaryDirectory() as tmp:
        _, _, _, ref_fn = h.write_inputs(tmp, robot, duration_s=0.1)
        q0 = ref_fn(0.0)
        short, path = os.path.join(tmp, "short.csv"), os.path.join(tmp, "long.csv")
        write_reference(short, np.degrees(q0), 100)
        base = run_compensate(tmp, robot, short, q0)
        write_reference(path, np.degrees(q0), args.rows)
        size_mb = os.path.getsize(path) / 1e6
        ref_s, ref_mb = loadtxt_reference(path)
        ready_s, end_s, peak_mb, rc, tail = run_compensate(tmp, robot, path, q0)
    load = os.getloadavg()
    print(f"reference {args.rows} rows, {size_mb:.1f} MB; load average {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}")
    print(f"numpy.loadtxt on it (a reference): {ref_s:.2f} s, peak {ref_mb:.0f} MB")
    if base[0] is None or ready_s is None:
        print(f"compensate did not reach its loop (exit {rc}): " + " | ".join(tail if ready_s is None else base[4]))
        return 1
    print(f"compensate with a 100-row reference (the fixed cost): ready for the loop after {base[0]:.2f} s, "
          f"peak {base[2]:.0f} MB")
    extra_s, extra_mb = ready_s - base[0], peak_mb - base[2]
    per_row = extra_mb * 1024 * 1024 / args.rows
    print(f"compensate with {args.rows} rows: ready for the loop after {ready_s:.2f} s (+{extra_s:.2f} s: "
          f"{extra_s / ref_s:.2f} x numpy.loadtxt's), ended after {end_s:.2f} s (exit {rc}); peak {peak_mb:.0f} MB "
          f"(+{extra_mb:.0f} MB: {per_row:.0f} bytes a row)")
    ok = per_row <= BYTES_PER_ROW and peak_mb <= PEAK_MB and extra_s <= TIME_RATIO * ref_s
    print(f"{'PASS' if ok else 'FAIL'}: targets +{BYTES_PER_ROW:g} bytes a row and <= {PEAK_MB:g} MB at peak, "
          f"time before the loop <= {TIME_RATIO:g} x numpy.loadtxt's")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
