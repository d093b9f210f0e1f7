"""Benchmark: the closed loop's work per 4 ms controller tick counted in
machine instructions, beside the bare station's, by part of Drake's
simulator loop: a figure that the load of a shared machine does not move.

valgrind's callgrind counts every instruction the process executes inside
``Simulator::AdvanceTo`` (nothing of the build) while it simulates the first
``SIM_S`` s of the block pass (diagrams/block_milling.yaml, plain
compensation, the uncompensated scenario's settings otherwise) and, in a
second process, the bare station held at the path's first pose as
benchmarks/bench_closed_loop.py runs it (its reference).  Each is run once:
the count is the same from run to run to a few parts in ten thousand.
Prints, per tick, the inclusive instructions of: the plant's step, the
Python systems' updates (the Python code, its calls into pydrake and the
C++ those calls run, such as the input ports' computations), the C++
systems' updates, applying the updates to the context, advancing the time,
the witness functions, finding the next event, merging and clearing the
event collections, and the loggers' publish.

The time a tick takes is not proportional to its instructions (the cell's
Python, bindings and the larger working set run slower per instruction
than the bare station's C++: benchmarks/bench_closed_loop.py times them).
Needs valgrind (``VALGRIND``, default /usr/bin/valgrind) and
callgrind_annotate; about 10-20 minutes (the two processes run at once; valgrind
runs the build about 50 times slower too).  No target: figures only.
With CALLGRIND_KEEP=FOLDER the callgrind files (cell.callgrind.N,
bare.callgrind.N, N = 1, 2, 3 the windows) are kept there, to read function
by function with ``callgrind_annotate --inclusive=yes
FOLDER/cell.callgrind.3``.

The first ``SIM_S`` s are mostly out of the cut: the block pass's milling
force is zero up to 0.716 s and not from 0.718 s (its logged cutting wrench;
the path dwells 0.2 s and ramps its feed up over 0.5 s before the cutter's
edge reaches the block), so 72 % of those ticks do no cutting, while the
whole pass (12.55 s simulated, 3,138 ticks: the path's 12.45 s and
experiment.RUN_OUT_S) cuts from 0.718 s to 10.092 s, 75 % of its ticks.  So
each process also counts two windows of its own, in the same run (callgrind
writes a profile at the end of each ``AdvanceTo`` call, ``--dump-after``,
and the windows are the calls ``AdvanceTo(OUT_S)``, ``AdvanceTo(SIM_S)``,
``AdvanceTo(SIM_S + IN_CUT_S)``): out of the cut, the ticks up to ``OUT_S``
= 0.7 s (before the engagement at 0.718 s), and in the cut, the ``IN_CUT_S``
= 1 s after ``SIM_S`` (1-2 s: the cutter engaged throughout, entering the
block), printed as a second table with the same rows, then the whole tick of
each window and the bare / block pass ratio of each.  The window is exact:
each window's profile holds only that call's instructions, the startup and
the build are in none of them, and the first table's figures are the sum of
the first two windows (one ``AdvanceTo`` call more than a single call to
``SIM_S``: a few instructions).  The in-cut figure is the one a user's pass
is made of.  The bare station cuts in no window.
Run: python3 benchmarks/instruction_counts.py  (not a bench_*.py: .ci/run gives each of those 4 minutes)
"""

import contextlib
import os
import re
import shutil
import subprocess
import sys
import tempfile
from concurrent.futures import ThreadPoolExecutor

SIM_S = float(os.environ.get("SIM_S", 1.0))
OUT_S = 0.7  # s: the out-of-cut window's end, before the block pass's first cutting force (0.718 s, its log)
IN_CUT_S = float(os.environ.get("IN_CUT_S", 1.0))  # s: the in-cut window's length, after SIM_S
CUT_END_S = 10.092  # s: the block pass's last cutting force (its log); the in-cut window ends before it
WINDOWS = (OUT_S, SIM_S, SIM_S + IN_CUT_S)  # s: each AdvanceTo call's end, one callgrind profile each
VALGRIND = os.environ.get("VALGRIND", "/usr/bin/valgrind")
HERE = os.path.dirname(os.path.abspath(__file__))

_RUN = {
    "cell": """
from robstiff_drake.diagrams.milling_cell import build_milling_cell, make_simulator
from robstiff_drake.diagrams.scenario import load_scenario
from robstiff_drake.model.robot import load_robot
from robstiff_drake.paths import DIAGRAMS_DIR
sc = load_scenario(DIAGRAMS_DIR / "block_milling.yaml")
cell = build_milling_cell(sc, load_robot(), compensation=True)  # (kept while the simulator runs)
sim = make_simulator(cell)
""",
    "bare": """
import numpy as np
from bench_closed_loop import bare_station_simulator
from robstiff_drake.diagrams.path_references import planned_path
from robstiff_drake.diagrams.scenario import load_scenario
from robstiff_drake.model.robot import load_robot
from robstiff_drake.paths import DIAGRAMS_DIR
robot, sc = load_robot(), load_scenario(DIAGRAMS_DIR / "block_milling.yaml")
_, _, q_ref = planned_path(sc, robot, robot.tool_point(where="the closed loop"))
sim, arm = bare_station_simulator(sc, robot, np.asarray(q_ref[0], dtype=float))
""",
}

_ADVANCE = "Simulator<double>::AdvanceTo(double const&) ["
_DUMP_AFTER = "drake::systems::Simulator<double>::AdvanceTo(double const&)"  # (callgrind's full name; no wildcard)
_LEAF_UU = "LeafSystem<double>::DispatchUnrestrictedUpdateHandler("
_LEAF_DU = "LeafSystem<double>::DispatchDiscreteVariableUpdateHandler("
_PY = "pydrake/systems/framework"  # (a Python callback's wrapper lives in the framework bindings)

# (label, [(parent function, callee substring or None for the parent itself)], summed)
ROWS = (
    ("whole tick (Simulator::AdvanceTo)", [(_ADVANCE, None)]),
    ("the plant's step (MultibodyPlant)", [(_LEAF_UU, "DeclarePeriodicUnrestrictedUpdateEvent<drake::multibody")]),
    ("Python updates (milling force; with its calls)", [(_LEAF_UU, _PY)]),
    ("Python updates (sensor, guard, tick; the same)", [(_LEAF_DU, _PY)]),
    ("C++ updates (holds, servo, filter, delay)", [(_LEAF_DU, "DeclarePeriodicDiscreteUpdateEvent<")]),
    ("applying the updates to the context", [("Simulator<double>::HandleUnrestrictedUpdate(", "ApplyUnrestricted"),
                                             ("Simulator<double>::HandleDiscreteUpdate(", "ApplyDiscreteVariable")]),
    ("advancing the time (SetTime)", [("IntegratorBase<double>::IntegrateNoFurtherThanTime(", "SetTime")]),
    ("witness functions (every system's)", [("Simulator<double>::IntegrateContinuousState(",
                                             "RedetermineActiveWitness")]),
    ("the next event's time", [(_ADVANCE, "CalcNextUpdateTime")]),
    ("event collections (merge, clear)", [(_ADVANCE, "DoAddToEnd"), (_ADVANCE, "::Clear()"),
                                          ("Simulator<double>::IntegrateContinuousState(", "::Clear()")]),
    ("the loggers' publish", [(_ADVANCE, "HandlePublish")]),
)


def _count(line):
    return int(re.match(r"\s*([\d,]+)", line).group(1).replace(",", ""))


def inclusive(tree, parent, callee):
    """Inclusive instructions of ``parent`` (callee None) or of its calls
    to functions whose line contains ``callee``, from callgrind_annotate's
    --tree=calling listing (lines)."""
    for i, line in enumerate(tree):
        if parent in line and "*" in line[:40]:
            if callee is None:
                return _count(line)
            total, j = 0, i + 1
            while j < len(tree) and ">" in tree[j][:40]:
                if callee in tree[j]:
                    total += _count(tree[j])
                j += 1
            return total
    return 0


# (label, parent function, callee substring): how many calls a tick, from callgrind's call counts
CALLS = (
    ("callbacks from C++ into Python (updates, outputs)", (_LEAF_UU, _LEAF_DU, "LeafSystem<double>::DispatchPublishHandler(",
                                                          "CacheEntry::Calc("), _PY),
    ("witness queries answered by Python systems", ("System<double>::GetWitnessFunctions(",), _PY),
    ("calls from Python into pydrake's bindings", ("methodobject.c:cfunction_call",), "/pydrake/"),
)


def calls(tree, parents, callee):
    """How many calls the functions ``parents`` made to functions whose
    line contains ``callee`` (callgrind's call counts, "(N x)")."""
    total = 0
    for i, line in enumerate(tree):
        if "*" in line[:40] and any(p in line for p in parents):
            j = i + 1
            while j < len(tree) and ">" in tree[j][:40]:
                m = re.search(r"\(([\d,]+)x\)", tree[j])
                if callee in tree[j] and m:
                    total += int(m.group(1).replace(",", ""))
                j += 1
    return total


def count(kind, folder):
    """callgrind_annotate's calling trees (lists of lines) of one run of
    ``kind``, one per window of WINDOWS (one profile per AdvanceTo call)."""
    out = os.path.join(folder, f"{kind}.callgrind")
    script = os.path.join(folder, f"{kind}.py")
    with open(script, "w") as f:
        f.write("import os, sys\nfor v in ('OPENBLAS_NUM_THREADS', 'OMP_NUM_THREADS', 'MKL_NUM_THREADS'):\n"
                "    os.environ.setdefault(v, '1')\n"
                f"sys.path.insert(0, {HERE!r})\n" + _RUN[kind]
                + "".join(f"sim.AdvanceTo({t!r})\n" for t in WINDOWS))
    subprocess.run([VALGRIND, "--tool=callgrind", f"--callgrind-out-file={out}",
                    "--toggle-collect=*Simulator*AdvanceTo*", f"--dump-after={_DUMP_AFTER}",
                    sys.executable, script],
                   check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    trees = []
    for part in range(1, len(WINDOWS) + 1):  # (out.N: the N-th AdvanceTo call; out itself: nothing after the last)
        tree = subprocess.run(["callgrind_annotate", "--inclusive=yes", "--tree=calling", "--threshold=100",
                               f"{out}.{part}"], check=True, capture_output=True, text=True).stdout
        trees.append(tree.splitlines())
    return trees


def table(trees, ticks):
    """Prints ROWS and CALLS per tick for the block pass's and the bare
    station's trees ({kind: [tree, ...]}, summed over the list)."""
    def inc(kind, parent, callee):
        return sum(inclusive(t, parent, callee) for t in trees[kind])
    print(f"  {'':50s} {'block pass':>10s} {'bare':>8s} {'extra':>8s}")
    for label, parts in ROWS:
        cell, bare = (sum(inc(k, p, c) for p, c in parts) / ticks / 1e3 for k in ("cell", "bare"))
        print(f"  {label:50s} {cell:10.1f} {bare:8.1f} {cell - bare:+8.1f}")
    print("  calls a tick:")
    for label, parents, callee in CALLS:
        cell, bare = (sum(calls(t, parents, callee) for t in trees[k]) / ticks for k in ("cell", "bare"))
        print(f"  {label:50s} {cell:10.1f} {bare:8.1f}")
    return {k: inc(k, _ADVANCE, None) for k in trees}


def main():
    if not (os.path.exists(VALGRIND) and shutil.which("callgrind_annotate")):
        print(f"no valgrind at {VALGRIND} or no callgrind_annotate (install valgrind, or set VALGRIND): "
              f"nothing measured")
        return 0
    if not OUT_S < SIM_S or IN_CUT_S <= 0 or SIM_S + IN_CUT_S > CUT_END_S:
        print(f"SIM_S must be above {OUT_S:g} s (the out-of-cut window's end), IN_CUT_S above 0 s and "
              f"SIM_S + IN_CUT_S at most {CUT_END_S:g} s (the cut's end); got SIM_S={SIM_S:g}, IN_CUT_S={IN_CUT_S:g}",
              file=sys.stderr)
        return 2
    ticks = [round((b - a) / 0.004) for a, b in zip((0.0,) + WINDOWS, WINDOWS)]  # (per window)
    keep = os.environ.get("CALLGRIND_KEEP")  # (a folder that keeps the callgrind files for callgrind_annotate)
    if keep:
        os.makedirs(keep, exist_ok=True)
    with (contextlib.nullcontext(keep) if keep else tempfile.TemporaryDirectory()) as folder, \
            ThreadPoolExecutor(2) as pool:  # (two processes at once)
        runs = {kind: pool.submit(count, kind, folder) for kind in ("cell", "bare")}
        trees = {kind: run.result() for kind, run in runs.items()}
    print(f"instructions per 4 ms tick (thousands; callgrind, inside Simulator::AdvanceTo, the first {SIM_S:g} s): "
          f"the block pass (plain compensation) and the bare station")
    whole = table({k: t[:2] for k, t in trees.items()}, ticks[0] + ticks[1])
    print(f"  ratio bare / block pass by instructions: {whole['bare'] / whole['cell']:.2f}")
    print(f"instructions per 4 ms tick in the cut (thousands; {SIM_S:g}-{SIM_S + IN_CUT_S:g} s, "
          f"the cutter engaged throughout): the block pass and the bare station")
    table({k: t[2:] for k, t in trees.items()}, ticks[2])
    print("the whole tick by window (thousands of instructions per tick; ratio: bare / block pass):")
    print(f"  {'':50s} {'block pass':>10s} {'bare':>8s} {'ratio':>8s}")
    for label, i in ((f"out of the cut (0-{OUT_S:g} s, {ticks[0]} ticks)", 0),
                     (f"the first {SIM_S:g} s ({ticks[0] + ticks[1]} ticks)", None),
                     (f"in the cut ({SIM_S:g}-{SIM_S + IN_CUT_S:g} s, {ticks[2]} ticks)", 2)):
        parts = (0, 1) if i is None else (i,)
        cell, bare = (sum(inclusive(trees[k][j], _ADVANCE, None) for j in parts) / sum(ticks[j] for j in parts)
                      for k in ("cell", "bare"))
        print(f"  {label:50s} {cell / 1e3:10.1f} {bare / 1e3:8.1f} {bare / cell:8.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
