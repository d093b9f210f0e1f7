"""Benchmark: the plant's cutting law per call, the numpy reference beside
the compiled kernel (model/cutting_kernels.py through model/jit.py), in the
same run: the revolution average (one averaged force update) and the
tooth-resolved wrench at 22 instants (one tooth-resolved update at a 2 ms
plant step), at the block test's mid-pass (diagrams/block_milling.yaml:
the cutter half in the block, 3 mm deep).  Also the largest difference of
the two over 300 random tool points, feeds and wear (relative to the
largest force).  No target: figures only; without numba the compiled
column says so.
Run: python3 benchmarks/bench_cutting_kernels.py
"""

import os
import sys
import time
import timeit

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402

from robstiff_drake.diagrams.scenario import load_scenario  # noqa: E402
from robstiff_drake.diagrams.scenario_models import plant_cutting_setup  # noqa: E402
from robstiff_drake.model import jit  # noqa: E402
from robstiff_drake.paths import DIAGRAMS_DIR  # noqa: E402

N = 2000


def per_call_us(fn):
    return min(timeit.repeat(fn, number=N, repeat=3)) / N * 1e6


def main():
    sc = load_scenario(DIAGRAMS_DIR / "block_milling.yaml")
    _, law, wp = plant_cutting_setup(sc)
    t0 = time.perf_counter()
    law.warm_up()
    load_s = time.perf_counter() - t0
    x0, x1, y0, y1, top = wp.boxes[0]
    p = np.array([0.5 * (x0 + x1), y0 + 0.01, top - 0.003])
    u, feed, travel = (1.0, 0.0), 0.02, 1.0
    ts = np.linspace(0.0, 0.002, 22)
    rng = np.random.default_rng(0)
    worst = 0.0
    for _ in range(300):
        q = np.array([rng.uniform(x0 - 0.05, x1 + 0.05), rng.uniform(y0 - 0.05, y1 + 0.05),
                      top - rng.uniform(-0.001, 0.004)])
        a = rng.uniform(0.0, 2 * np.pi)
        d = (np.cos(a), np.sin(a))
        f, L = rng.uniform(0.0, 0.05), rng.uniform(0.0, 50.0)
        for ref, got in ((law.average_wrench_reference(q, d, wp, f, L), law.average_wrench(q, d, wp, f, L)),
                         (law.tooth_wrenches_reference(ts, q, d, wp, 0.3, f, L),
                          law.tooth_wrenches(ts, q, d, wp, 0.3, f, L))):
            worst = max(worst, float(np.max(np.abs(ref - got))) / max(1e-9, float(np.max(np.abs(ref)))))
    rows = [("revolution average (one averaged update)",
             lambda: law.average_wrench_reference(p, u, wp, feed, travel),
             lambda: law.average_wrench(p, u, wp, feed, travel)),
            ("tooth-resolved wrench, 22 instants",
             lambda: law.tooth_wrenches_reference(ts, p, u, wp, 0.0, feed, travel),
             lambda: law.tooth_wrenches(ts, p, u, wp, 0.0, feed, travel))]
    print(f"the plant's cutting law per call, us (best of 3 x {N}); load average {os.getloadavg()[0]:.2f}; "
          f"compiled kernels: {'yes (numba, loaded in %.2f s)' % load_s if jit.available() else 'no'}")
    for label, ref, fast in rows:
        r = per_call_us(ref)
        if jit.available():
            c = per_call_us(fast)
            print(f"  {label:42s} numpy {r:7.1f} us   compiled {c:6.1f} us   ratio {r / c:5.1f}")
        else:
            print(f"  {label:42s} numpy {r:7.1f} us   compiled: numba not installed")
    if jit.available():
        print(f"  largest difference, compiled against numpy, over 300 cases: {worst:.1e} of the largest force")
    return 0


if __name__ == "__main__":
    sys.exit(main())
