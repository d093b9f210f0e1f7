"""Benchmark: one call of each per-tick update callback of the block pass
that runs compiled (systems/compensator_tick.CompensatorTick's and
systems/milling_force.MillingForceSource's ``_update``), at mid-pass.

The block pass (diagrams/block_milling.yaml, plain compensation) is built
and simulated to ``T_S`` (3.0 s: cutting); then each system's update is
called as Drake calls it (its context in the diagram's, the inputs
already computed and cached; a state of its own to write into, copied
from the context's once, which the repeated calls keep updating) and
timed with timeit: best of ``REPEATS`` (5) rounds of ``NUMBER`` (20000)
calls, microseconds per call (wall clock: run it on a quiet machine;
``uptime`` says how quiet).  With numba the updates run compiled
(model/jit.py: the first line says whether).  No target: figures only.
Run: python3 benchmarks/bench_tick_updates.py
"""

import os
import sys
import timeit

from robstiff_drake.diagrams.milling_cell import build_milling_cell, make_simulator
from robstiff_drake.diagrams.scenario import load_scenario
from robstiff_drake.model import jit
from robstiff_drake.model.robot import load_robot
from robstiff_drake.paths import DIAGRAMS_DIR
from robstiff_drake.systems.compensator_tick import CompensatorTick
from robstiff_drake.systems.milling_force import MillingForceSource

T_S = 3.0
REPEATS = int(os.environ.get("REPEATS", 5))
NUMBER = int(os.environ.get("NUMBER", 20000))


def leaf_systems(diagram):
    """Every leaf system of ``diagram``, nested diagrams opened."""
    for s in diagram.GetSystems():
        if hasattr(s, "GetSystems"):
            yield from leaf_systems(s)
        else:
            yield s


def main():
    sc = load_scenario(DIAGRAMS_DIR / "block_milling.yaml")
    cell = build_milling_cell(sc, load_robot(), compensation=True)
    sim = make_simulator(cell)
    sim.AdvanceTo(T_S)
    root = sim.get_context()
    print(f"load average {os.getloadavg()[0]:.2f} / {os.getloadavg()[1]:.2f} / {os.getloadavg()[2]:.2f}; compiled "
          f"kernels: {'yes (numba)' if jit.available() else 'no'}; at t = {T_S:g} s, best of {REPEATS} x {NUMBER}")
    for system in leaf_systems(cell.diagram):
        if not isinstance(system, (CompensatorTick, MillingForceSource)):
            continue
        context = system.GetMyContextFromRoot(root)
        scratch = system.CreateDefaultContext()
        scratch.SetTimeStateAndParametersFrom(context)
        if isinstance(system, CompensatorTick):
            values = scratch.get_mutable_discrete_state()
        else:
            values = scratch.get_mutable_state()
        update = system._update
        update(context, values)  # (the inputs computed and cached before the timing)
        best = min(timeit.repeat(lambda: update(context, values), number=NUMBER, repeat=REPEATS))
        print(f"  {system.get_name():28s} {type(system).__name__:20s} {best / NUMBER * 1e6:6.2f} us per update")
    return 0


if __name__ == "__main__":
    sys.exit(main())
