"""Benchmark: what each Python system of the closed loop costs per
controller tick, beside the whole tick, in the same run.

The block pass (diagrams/block_milling.yaml; plain and predictive
compensation) is run twice per repeat: as it is (the whole tick: CPU time
/ controller ticks), and with every callback that the project's own
LeafSystems declare (output calculations, periodic updates) wrapped in a
timer.  A block's figure is its exclusive time: a callback's time
less the time spent in other timed callbacks it pulled through its input
ports (Drake computes an input when a block reads it), so the blocks add
up without counting twice.  What is left of the whole tick is Drake's own
work (the MultibodyPlant's step, the weld reaction, filters, holds, delays,
servo, loggers) and the calls from C++ into Python.  The timers add a
little to the instrumented run; its whole tick is printed too.

Best of ``REPEATS`` runs (the machine is shared): the whole tick's best,
each block's best.  Times are CPU time (the whole run's: the process's; a
callback's: its thread's), so that other jobs on a shared machine do not
count: what an idle machine's wall clock would show, about.  The
simulation alone is timed (the pass to the path's end).  With numba the
blocks' arithmetic runs compiled (model/jit.py: the line "compiled
kernels" says whether); ROBSTIFF_NO_JIT=1 times the plain-Python
references.  No target: figures only.
Run: python3 benchmarks/bench_block_costs.py
"""

import copy
import os
import importlib
import pkgutil
import sys
import time
from collections import defaultdict

from pydrake.systems.framework import LeafSystem

import robstiff_drake.systems
from robstiff_drake.diagrams import station  # noqa: F401  (ToolPose)
from robstiff_drake.diagrams.milling_cell import build_milling_cell, make_simulator
from robstiff_drake.diagrams.scenario import load_scenario
from robstiff_drake.model import jit
from robstiff_drake.model.robot import load_robot
from robstiff_drake.paths import DIAGRAMS_DIR

REPEATS = int(__import__("os").environ.get("REPEATS", 5))
DECLARATIONS = ("DeclareVectorOutputPort", "DeclareAbstractOutputPort", "DeclarePeriodicDiscreteUpdateEvent",
                "DeclarePeriodicUnrestrictedUpdateEvent", "DeclarePeriodicPublishEvent",
                "DeclarePerStepPublishEvent", "DeclareForcedPublishEvent")


class CallbackTimer:
    """Exclusive CPU time (s, the thread's) and calls per system of every wrapped callback."""

    def __init__(self):
        self.seconds = defaultdict(float)
        self.calls = defaultdict(int)
        self._stack = []  # [system, seconds spent in nested timed callbacks]
        self.enabled = False

    def wrap(self, system, fn):
        def timed(*args, **kwargs):
            if not self.enabled:
                return fn(*args, **kwargs)
            self._stack.append([system, 0.0])
            t0 = time.thread_time()
            try:
                return fn(*args, **kwargs)
            finally:
                dt = time.thread_time() - t0
                _, nested = self._stack.pop()
                self.seconds[system] += dt - nested
                self.calls[system] += 1
                if self._stack:
                    self._stack[-1][1] += dt

        return timed

    def reset(self):
        self.seconds.clear()
        self.calls.clear()


def project_leaf_systems():
    """The project's LeafSystem classes (robstiff_drake.systems and the station's)."""
    for mod in pkgutil.iter_modules(robstiff_drake.systems.__path__):
        importlib.import_module(f"robstiff_drake.systems.{mod.name}")
    found, todo = [], list(LeafSystem.__subclasses__())
    while todo:
        cls = todo.pop()
        todo.extend(cls.__subclasses__())
        if cls.__module__.startswith("robstiff_drake."):
            found.append(cls)
    return found


def instrument(timer):
    """Make every Declare* of the project's systems wrap its callback."""
    for cls in project_leaf_systems():
        for name in DECLARATIONS:
            original = getattr(LeafSystem, name, None)
            if original is None or name in cls.__dict__:
                continue

            def declare(self, *args, _original=original, **kwargs):
                args = [timer.wrap(self, a) if callable(a) and not isinstance(a, type) else a for a in args]
                kwargs = {k: timer.wrap(self, v) if callable(v) and not isinstance(v, type) else v
                          for k, v in kwargs.items()}
                return _original(self, *args, **kwargs)

            setattr(cls, name, declare)


def one_run(sc, robot, timer=None):
    """(CPU s, controller ticks, {block: (us per tick, calls per tick)}) of
    one compensated pass: the simulation alone (the path's end)."""
    cell = build_milling_cell(sc, robot, compensation=True)
    sim = make_simulator(cell)
    t_end = float(cell.q_ref_times[-1])
    if timer is not None:
        timer.reset()
        timer.enabled = True
    c0 = time.process_time()
    try:
        sim.AdvanceTo(t_end)
    finally:
        cpu = time.process_time() - c0
        if timer is not None:
            timer.enabled = False
    ticks = t_end / (sc.controller.period_ms / 1e3)
    blocks = {}
    if timer is not None:
        for system, s in timer.seconds.items():
            name = system.get_name() or type(system).__name__
            blocks[name] = (s / ticks * 1e6, timer.calls[system] / ticks)
    return cpu, ticks, blocks


def main():
    robot = load_robot()
    base = load_scenario(DIAGRAMS_DIR / "block_milling.yaml")
    cases = []
    for mode in ("plain", "predictive"):
        sc = copy.deepcopy(base)
        sc.controller.mode = mode
        cases.append((mode, sc))
    timer = CallbackTimer()
    plain_runs = {label: min(one_run(sc, robot)[:2] for _ in range(REPEATS)) for label, sc in cases}
    instrument(timer)  # from here on, new systems are built with timed callbacks
    print(f"load average {os.getloadavg()[0]:.2f} / {os.getloadavg()[1]:.2f} / {os.getloadavg()[2]:.2f}; compiled "
          f"kernels: {'yes (numba)' if jit.available() else 'no (numba not installed or ROBSTIFF_NO_JIT set)'}")
    print(f"closed-loop block pass, compensation on, best of {REPEATS} runs; microseconds per controller tick "
          f"({base.controller.period_ms:g} ms), exclusive time of each Python block:")
    for label, sc in cases:
        wall, ticks = plain_runs[label]
        whole_us = wall / ticks * 1e6
        timed = [one_run(sc, robot, timer) for _ in range(REPEATS)]
        t_wall = min(r[0] for r in timed)
        blocks = {name: min((r[2][name] for r in timed), key=lambda v: v[0]) for name in timed[0][2]}
        total = sum(us for us, _ in blocks.values())
        print(f"\n  {label} compensation: whole tick {whole_us:6.1f} us (uninstrumented; "
              f"{sc.plant_config.time_step * 1e3:g} ms plant step, sensor {sc.sensor.rate_hz:g} Hz)")
        for name, (us, calls) in sorted(blocks.items(), key=lambda kv: -kv[1][0]):
            print(f"    {name:24s} {us:6.1f} us  ({calls:4.1f} calls per tick)   {us / whole_us:6.1%} of the tick")
        print(f"    {'all Python blocks':24s} {total:6.1f} us                        {total / whole_us:6.1%}")
        rest = whole_us - total
        print(f"    {'the rest (Drake, C++)':24s} {rest:6.1f} us                        {rest / whole_us:6.1%}   "
              f"(instrumented whole tick {t_wall / ticks * 1e6:.1f} us)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
