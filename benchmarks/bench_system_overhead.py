"""Benchmark: what a system costs the closed loop per 4 ms controller tick
just by being in the diagram, beside the bare station measured in the same
run (diagrams/block_milling.yaml's arm, drives and plant step, held at its
first pose: benchmarks/bench_closed_loop.py's reference).

The bare station also follows the block pass's path (its joint
references, as the cell's path source commands them: the interpolator's
latch and the gravity model then see a moving command), with no cut: what
the arm's motion alone costs the bare station.  Added to the bare station
(held), ``N`` at a time: Python LeafSystems with no port
and no event (what every Python system costs whether or not anything reads
it: Drake's bookkeeping every plant step, the witness functions after each
unrestricted update and the event collections, through the Python
bindings), the same with one periodic discrete update per tick that does
nothing (that plus one call from C++ into Python a tick), the same
derived from the project's LeafSystem (systems/leaf_system.py, which the
project's systems derive from: Drake's question for witness functions
after each plant step answered without a failed Python attribute
look-up), and C++ PassThroughs (a C++ system's share of the same bookkeeping).  Prints, per
kind, the CPU time per tick of the bare station and with the systems, and
the cost of one system (us per tick).  It tells which of "fewer systems"
and "less arithmetic" pays in the closed loop: the block pass has five
Python systems on the plain path (milling force, wrist sensor, guard,
compensator tick; tool pose until it was built only where read).

Best of ``REPEATS`` runs each (CPU time: the machine is shared).  No
target: figures only.

``--perf``: where the closed loop's time goes, by library and by kind of
work, beside the bare station's: Linux ``perf record`` (/usr/bin/perf, or
``PERF``) samples this process at 2 kHz while it runs the block pass (plain
compensation, built once) ``PERF_RUNS`` times, then the bare station as
long; each sample is counted where the CPU was (``perf report
--no-children --sort dso,sym``: self time, no call graph, so nothing
depends on unwinding through Python), and the shares are turned into us
per 4 ms tick with the runs' CPU time.  pydrake's libdrake.so is stripped
but exports its C++ symbols, which is what sorts Drake's own work into the
multibody physics (``drake::multibody``, Eigen, geometry), cache
invalidation (``DependencyTracker``, ``CacheEntry``, ``ContextBase``),
events and the simulator loop (event collections, next update time,
witness functions, dispatch) and the rest (ports, primitives, loggers).
Then Drake's pieces with what they call (``perf report --children``: the
plant's step, the gravity models, the interpolator's latch, the path, the
loggers, advancing the time, the next event, the witness functions; a
lower bound where a piece calls into Python, whose frames perf cannot
walk), and how often each of Drake's computations runs per tick in each
diagram (uprobes on libdrake.so's exported functions, ``perf probe`` as
root, removed again after: one run each), which shows whether anything is
computed more often than it is read.  Without perf (or where the kernel
refuses it) it says so and exits 0.
Run: python3 benchmarks/bench_system_overhead.py [--perf]
"""

import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import time

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402 (after the thread settings)
from pydrake.systems.framework import LeafSystem  # noqa: E402
from pydrake.systems.primitives import PassThrough  # noqa: E402

from bench_closed_loop import bare_plant_rtf, bare_station_simulator  # noqa: E402 (the bare station: its reference)
from robstiff_drake.diagrams.milling_cell import build_milling_cell, make_simulator  # noqa: E402
from robstiff_drake.diagrams.path_references import planned_path  # noqa: E402
from robstiff_drake.diagrams.scenario import load_scenario  # noqa: E402
from robstiff_drake.model.robot import load_robot  # noqa: E402
from robstiff_drake.paths import DIAGRAMS_DIR  # noqa: E402
from robstiff_drake.systems.leaf_system import LeafSystem as ProjectLeafSystem  # noqa: E402

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


class ProjectIdle(Idle, ProjectLeafSystem):
    """Idle on the project's LeafSystem (systems/leaf_system.py: Drake's
    question for witness functions answered without a Python look-up)."""


def us_per_tick(sc, robot, q0, tick_s, add, path=None):
    """CPU time per controller tick (us) of the bare station with ``N`` systems ``add()`` added (none: None),
    following ``path`` (bare_plant_rtf's) if given."""
    _, rtf_cpu = bare_plant_rtf(sc, robot, q0, SIM_S, extra=[add() for _ in range(N if add else 0)], path=path)
    return tick_s / rtf_cpu * 1e6


PERF_RUNS = int(os.environ.get("PERF_RUNS", 4))
PERF_HZ = 2000

# Self time by kind of work: (label, library test, symbol pattern or None), the first that matches.
KINDS = (
    ("Drake: multibody physics", "libdrake", r"drake::multibody|Eigen::|drake::geometry"),
    ("Drake: cache invalidation", "libdrake", r"DependencyTracker|CacheEntry|ContextBase|Propagate"),
    ("Drake: events, simulator loop", "libdrake", r"Event|NextUpdateTime|Witness|Dispatch|Simulator|Integrat"),
    ("Drake: ports, primitives, loggers", "libdrake", None),
    ("C/C++ runtime (malloc, dynamic_cast)", r"^lib(c|stdc\+\+|m|gcc_s)[.-]", None),
    ("Python interpreter", r"^libpython", None),
    ("numpy", r"_multiarray|_umath", None),
    ("numba kernels and dispatch", r"^\[JIT\]|_dispatcher|_helperlib|_nrt_python|llvmlite", None),
    ("pydrake bindings (pybind11)", r"^[a-z_]+\.so$", None),
    ("other (kernel, ...)", r"", None),
)


def perf_report(data, children, sort):
    """The lines of ``perf report`` on ``data`` (``children``: --children or --no-children; ``sort``: its keys)."""
    return subprocess.run([PERF, "report", "-i", data, children, "--sort", sort, "--stdio", "-g", "none"],
                          capture_output=True, text=True, check=True).stdout.splitlines()


def perf_kinds(data):
    """{kind: share of the samples in ``data`` (0-1)} by KINDS."""
    shares = dict.fromkeys((k[0] for k in KINDS), 0.0)
    for line in perf_report(data, "--no-children", "dso,sym"):
        m = re.match(r"\s*([\d.]+)%\s+(\S+)\s+\[.\]\s+(.*)", line)
        if not m:
            continue
        pct, dso, sym = float(m.group(1)) / 100, m.group(2), m.group(3)
        for label, lib, pattern in KINDS:
            if re.search(lib, dso) and (pattern is None or re.search(pattern, sym)):
                shares[label] += pct
                break
    return shares


# Drake's pieces, their time with what they call (perf report --children: a lower bound where a piece calls
# into Python, whose frames perf cannot walk through)
PIECES = (
    ("the plant's step (MultibodyPlant)", "drake::multibody::MultibodyPlant<double>::CalcStepUnrestricted"),
    ("  of which its reaction forces", "drake::multibody::MultibodyPlant<double>::CalcReactionForces"),
    ("the gravity models (InverseDynamics)", "drake::systems::controllers::InverseDynamics<double>::CalcOutputForce"),
    ("the interpolator's latch (ZeroOrderHold)", "drake::systems::ZeroOrderHold<double>::LatchInputVectorToState"),
    ("the path (TrajectorySource)", "drake::systems::TrajectorySource<double>::DoCalcVectorOutput"),
    ("the loggers' publish", "drake::systems::Simulator<double>::HandlePublish"),
    ("advancing the time (SetTime)", "drake::systems::Simulator<double>::IntegrateContinuousState"),
    ("the next event's time", "drake::systems::System<double>::CalcNextUpdateTime"),
    ("the witness functions", "drake::systems::Simulator<double>::RedetermineActiveWitnessFunctionsIfNecessary"),
    ("cache invalidation (NotifySubscribers)", "drake::systems::DependencyTracker::NotifySubscribers"),
)


def perf_pieces(data):
    """{symbol: share of the samples in ``data`` with it on the stack (0-1)} for PIECES."""
    wanted = {sym for _, sym in PIECES}
    shares = dict.fromkeys(wanted, 0.0)
    for line in perf_report(data, "--children", "sym"):
        m = re.match(r"\s*([\d.]+)%\s+[\d.]+%\s+\[.\]\s+(.*)", line)
        if m and m.group(2).strip() in wanted:
            shares[m.group(2).strip()] = max(shares[m.group(2).strip()], float(m.group(1)) / 100)
    return shares


# Drake functions whose calls are counted (uprobes: perf probe, as root) per controller tick: how often what runs
CALLS = (
    ("the plant's step", "MultibodyPlantIdE20CalcStepUnrestricted"),
    ("the reaction forces", "MultibodyPlantIdE18CalcReactionForces"),
    ("a gravity model (InverseDynamics)", "InverseDynamicsIdE15CalcOutputForce"),
    ("the interpolator's latch", "ZeroOrderHoldIdE23LatchInputVectorToState"),
    ("an AffineSystem's output (gains, drives)", "AffineSystemIdE11CalcOutputY"),
    ("a Multiplexer's output", "MultiplexerIdE21CombineInputsToOutput"),
    ("a Demultiplexer's output", "DemultiplexerIdE12CopyToOutput"),
    ("the path (TrajectorySource)", "TrajectorySourceIdE18DoCalcVectorOutput"),
    ("a logger's write", "VectorLogSinkIdE10WriteToLog"),
)


def counted(runs, lib):
    """[calls of each CALLS function in each of ``runs`` (functions)], or None where perf cannot probe (the
    probes, group robstiff_bench, are removed again in any case)."""
    nm = subprocess.run(["nm", "-D", lib], capture_output=True, text=True).stdout
    events = []
    try:
        for i, (_, pattern) in enumerate(CALLS):
            addr = next((ln.split()[0] for ln in nm.splitlines() if pattern in ln and "_ZNK5drake" in ln), None)
            if addr is None or subprocess.run([PERF, "probe", "-x", lib, "-a", f"robstiff_bench:f{i}=0x{addr}"],
                                              capture_output=True).returncode != 0:
                return None
            events.append(f"robstiff_bench:f{i}")
        out = []
        for run in runs:
            with tempfile.NamedTemporaryFile(suffix=".txt") as f:
                stat = subprocess.Popen([PERF, "stat", "-x", ",", "-o", f.name, "-p", str(os.getpid())]
                                        + [a for e in events for a in ("-e", e)],
                                        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
                time.sleep(1.5)
                run()
                stat.send_signal(signal.SIGINT)
                stat.wait(timeout=60)
                counts = {}
                for line in open(f.name):
                    parts = line.strip().split(",")
                    if len(parts) > 2 and parts[2] in events and parts[0].isdigit():
                        counts[parts[2]] = int(parts[0])
                out.append([counts.get(e) for e in events])
        return out
    finally:
        subprocess.run([PERF, "probe", "-d", "robstiff_bench:*"], capture_output=True)


def sampled(run, data):
    """CPU seconds of ``run()``, sampled by perf into ``data``."""
    rec = subprocess.Popen([PERF, "record", "-g", "-F", str(PERF_HZ), "-p", str(os.getpid()), "-o", data],
                           stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    time.sleep(1.5)  # (attached: this process sleeps, no samples)
    c0 = time.process_time()
    run()
    cpu = time.process_time() - c0
    rec.send_signal(signal.SIGINT)
    # (perf ends on the signal it was stopped with, after writing its data: -SIGINT is its normal exit)
    if rec.wait(timeout=60) not in (0, -signal.SIGINT) or not os.path.exists(data):
        raise RuntimeError(f"perf record exited with {rec.returncode}")
    return cpu


def perf_split():
    """Print the split of the block pass's time and the bare station's (--perf)."""
    robot = load_robot()
    sc = load_scenario(DIAGRAMS_DIR / "block_milling.yaml")
    cell = cell_ = build_milling_cell(sc, robot, compensation=True)
    t_end = cell.path.duration_s + 0.1  # (experiment.RUN_OUT_S)
    make_simulator(cell).AdvanceTo(0.5)  # (first calls: kernels and caches loaded)
    sims = [make_simulator(cell) for _ in range(PERF_RUNS)]
    bare_plant_rtf(sc, robot, cell.q_ref[0], 0.5)
    bares = [bare_station_simulator(sc, robot, cell.q_ref[0]) for _ in range(PERF_RUNS)]  # (built before sampling)
    ticks = PERF_RUNS * t_end / (sc.controller.period_ms / 1e3)
    with tempfile.TemporaryDirectory() as tmp:
        cell_cpu = sampled(lambda: [s.AdvanceTo(t_end) for s in sims], os.path.join(tmp, "cell.data"))
        bare_cpu = sampled(lambda: [s.AdvanceTo(t_end) for s, _ in bares], os.path.join(tmp, "bare.data"))
        cell, bare = perf_kinds(os.path.join(tmp, "cell.data")), perf_kinds(os.path.join(tmp, "bare.data"))
        pieces = perf_pieces(os.path.join(tmp, "cell.data")), perf_pieces(os.path.join(tmp, "bare.data"))
    to_us = (cell_cpu / ticks * 1e6, bare_cpu / ticks * 1e6)
    print(f"load average {os.getloadavg()[0]:.2f}; the block pass (plain compensation, {t_end:.2f} s) and the bare "
          f"station, {PERF_RUNS} runs each under perf record at {PERF_HZ} Hz; self time, us per "
          f"{sc.controller.period_ms:g} ms tick:")
    print(f"  {'':40s} {'block pass':>10s} {'bare':>8s} {'extra':>8s}")
    for label, _, _ in KINDS:
        a, b = cell[label] * to_us[0], bare[label] * to_us[1]
        print(f"  {label:40s} {a:10.1f} {b:8.1f} {a - b:+8.1f}")
    drake = [sum(v for k, v in d.items() if k.startswith("Drake")) * u for d, u in ((cell, to_us[0]), (bare, to_us[1]))]
    print(f"  {'all of Drake (libdrake.so)':40s} {drake[0]:10.1f} {drake[1]:8.1f} {drake[0] - drake[1]:+8.1f}")
    print(f"  {'whole tick (CPU time of the runs)':40s} {to_us[0]:10.1f} {to_us[1]:8.1f} {to_us[0] - to_us[1]:+8.1f}")
    print("  Drake's pieces with what they call (a lower bound where they call into Python):")
    for label, sym in PIECES:
        a, b = pieces[0][sym] * to_us[0], pieces[1][sym] * to_us[1]
        print(f"  {label:40s} {a:10.1f} {b:8.1f} {a - b:+8.1f}")
    import pydrake
    lib = os.path.join(os.path.dirname(pydrake.__file__), "lib", "libdrake.so")
    sim_cell, (sim_bare, _arm) = make_simulator(cell_), bare_station_simulator(sc, robot, cell_.q_ref[0])
    calls = counted([lambda: sim_cell.AdvanceTo(t_end), lambda: sim_bare.AdvanceTo(t_end)], lib)
    if calls is None:
        print("  (calls not counted: perf probe needs root and uprobes)")
        return 0
    n = t_end / (sc.controller.period_ms / 1e3)
    print("  calls per tick (perf probe; one run each):")
    for (label, _), a, b in zip(CALLS, *calls):
        print(f"  {label:40s} {a / n:10.2f} {b / n:8.2f} {(a - b) / n:+8.2f}")
    return 0


PERF = os.environ.get("PERF") or shutil.which("perf") or "/usr/bin/perf"


def main():
    if "--perf" in sys.argv[1:]:
        if not os.path.exists(PERF):
            print(f"--perf: no perf at {PERF} (install linux-perf, or set PERF): nothing measured")
            return 0
        try:
            return perf_split()
        except (RuntimeError, subprocess.CalledProcessError, subprocess.TimeoutExpired) as e:
            print(f"--perf: perf could not sample this process ({e}; kernel.perf_event_paranoid?): nothing measured")
            return 0
    robot = load_robot()
    sc = load_scenario(DIAGRAMS_DIR / "block_milling.yaml")
    _, t_ref, q_ref = planned_path(sc, robot, robot.tool_point(where="the closed loop"))
    q0 = np.asarray(q_ref[0], dtype=float)
    tick_s = sc.controller.period_ms / 1e3
    moving = "bare station following the pass's path"  # (the command the cell's path source gives, no cut)
    kinds = (("bare station", None, None), (moving, None, (t_ref, q_ref)),
             (f"+{N} Python systems, no port, no event", Idle, None),
             (f"+{N} Python systems, one empty update a tick", lambda: Idle(tick_s), None),
             (f"+{N} the same on the project's LeafSystem", lambda: ProjectIdle(tick_s), None),
             (f"+{N} C++ PassThroughs", lambda: PassThrough(6), None))
    best = {label: min(us_per_tick(sc, robot, q0, tick_s, add, path) for _ in range(REPEATS))
            for label, add, path in kinds}
    print(f"load average {os.getloadavg()[0]:.2f}; {SIM_S:g} s simulated per run, plant step "
          f"{sc.plant_config.time_step * 1e3:g} ms; CPU time per {tick_s * 1e3:g} ms tick, best of {REPEATS}:")
    bare = best["bare station"]
    for label, _, _ in kinds:
        extra = ("" if label == "bare station" else f"   {best[label] - bare:+5.2f} us a tick" if label == moving
                 else f"   {(best[label] - bare) / N:5.2f} us a tick per system")
        print(f"  {label:48s} {best[label]:6.1f} us{extra}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
