"""Benchmark: what a system costs the closed loop per 4 ms controller tick
just by being in the diagram, beside the bare station measured in the same
run (diagrams/block_milling.yaml's arm, drives and plant step, held at its
first pose: benchmarks/bench_closed_loop.py's reference).

Added to the bare station, ``N`` at a time: Python LeafSystems with no port
and no event (what every Python system costs whether or not anything reads
it: Drake's bookkeeping every plant step, the witness functions after each
unrestricted update and the event collections, through the Python
bindings), the same with one periodic discrete update per tick that does
nothing (that plus one call from C++ into Python a tick), and C++
PassThroughs (a C++ system's share of the same bookkeeping).  Prints, per
kind, the CPU time per tick of the bare station and with the systems, and
the cost of one system (us per tick).  It tells which of "fewer systems"
and "less arithmetic" pays in the closed loop: the block pass has five
Python systems on the plain path (milling force, wrist sensor, guard,
compensator tick; tool pose until it was built only where read).

Best of ``REPEATS`` runs each (CPU time: the machine is shared).  No
target: figures only.
Run: python3 benchmarks/bench_system_overhead.py
"""

import os
import sys

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402 (after the thread settings)
from pydrake.systems.framework import LeafSystem  # noqa: E402
from pydrake.systems.primitives import PassThrough  # noqa: E402

from bench_closed_loop import bare_plant_rtf  # noqa: E402 (the bare station, as that benchmark's reference)
from robstiff_drake.diagrams.path_references import planned_path  # noqa: E402
from robstiff_drake.diagrams.scenario import load_scenario  # noqa: E402
from robstiff_drake.model.robot import load_robot  # noqa: E402
from robstiff_drake.paths import DIAGRAMS_DIR  # noqa: E402

REPEATS = int(os.environ.get("REPEATS", 3))
N = 5  # systems added at a time
SIM_S = 5.0  # simulated seconds per run


class Idle(LeafSystem):
    """No port; with ``tick_s``, a periodic discrete update that does nothing."""

    def __init__(self, tick_s=None):
        super().__init__()
        if tick_s is not None:
            self.DeclareDiscreteState(1)
            self.DeclarePeriodicDiscreteUpdateEvent(tick_s, 0.0, lambda context, state: None)


def us_per_tick(sc, robot, q0, tick_s, add):
    """CPU time per controller tick (us) of the bare station with ``N`` systems ``add()`` added (none: None)."""
    _, rtf_cpu = bare_plant_rtf(sc, robot, q0, SIM_S, extra=[add() for _ in range(N if add else 0)])
    return tick_s / rtf_cpu * 1e6


def main():
    robot = load_robot()
    sc = load_scenario(DIAGRAMS_DIR / "block_milling.yaml")
    _, _, q_ref = planned_path(sc, robot, robot.tool_point(where="the closed loop"))
    q0 = np.asarray(q_ref[0], dtype=float)
    tick_s = sc.controller.period_ms / 1e3
    kinds = (("bare station", None), (f"+{N} Python systems, no port, no event", Idle),
             (f"+{N} Python systems, one empty update a tick", lambda: Idle(tick_s)),
             (f"+{N} C++ PassThroughs", lambda: PassThrough(6)))
    best = {label: min(us_per_tick(sc, robot, q0, tick_s, add) for _ in range(REPEATS)) for label, add in kinds}
    print(f"load average {os.getloadavg()[0]:.2f}; {SIM_S:g} s simulated per run, plant step "
          f"{sc.plant_config.time_step * 1e3:g} ms; CPU time per {tick_s * 1e3:g} ms tick, best of {REPEATS}:")
    bare = best["bare station"]
    for label, _ in kinds:
        extra = "" if label == "bare station" else f"   {(best[label] - bare) / N:5.2f} us a tick per system"
        print(f"  {label:48s} {best[label]:6.1f} us{extra}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
