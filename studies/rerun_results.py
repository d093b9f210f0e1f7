"""Every figure-producing command behind docs/results.md, by name, with its
approximate run time, and a rerun of a chosen subset: after a change to the
plant (its gears, damping, cutting law), rerun the figures it moves and
compare them with the document.

    python studies/rerun_results.py --list                 # names, times, the section each feeds
    python studies/rerun_results.py --only finishing_pass --only posted_program
    python studies/rerun_results.py --only sweeps          # a group: every name it lists
    python studies/rerun_results.py --all                  # everything (hours on a shared 2-core machine)

Each command's output goes to OUT/NAME.txt (``--out``, default
robstiff-rerun/), written through a temporary file and renamed; files a
command writes (JSON, plots) go to OUT as well, never over docs/.  The run
times are wall times measured on the shared 2-core machine (load 2-8) on
2026-11-28 (or, where marked, as docs/results.md states them); a quiet
machine is faster.
"""

import argparse
import os
import shlex
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PY = [sys.executable]
CLI = [sys.executable, "-m", "robstiff_drake"]

# (name, section of docs/results.md, approximate wall time, command; "{out}" is the output folder)
FIGURES = [
    ("demo", "1. The block-milling test", "10 s", CLI + ["demo", "--out", "{out}/demo"]),
    ("paper_forces", "The paper's forces", "10 s", CLI + ["simulate", "block_milling_paper_forces", "--out",
                                                           "{out}/paper_forces"]),
    ("cylinder_head", "The cylinder head", "15 s", CLI + ["simulate", "cylinder_head", "--out", "{out}/cylinder_head"]),
    ("model_error", "How much the compensator's model matters", "2 min",
     PY + ["studies/compensation_model_error.py"]),
    ("face_and_contour", "A job with turns (roughing and finishing tables)", "4 min",
     PY + ["studies/face_and_contour.py"]),
    ("finishing_pass", "A job with turns: the finishing pass only", "2 min",
     PY + ["studies/face_and_contour.py", "--finishing"]),
    ("posted_program", "A job with turns: the posted program", "1 min", PY + ["studies/face_and_contour.py", "--posted"]),
    ("plant_physics", "The plant's own cutting physics", "10 min", PY + ["studies/plant_physics_mismatch.py"]),
    ("chip_direction", "The plant's own cutting physics: the chip's direction from the tool's own motion", "8 min",
     PY + ["studies/chip_direction.py"]),
    ("chip_coupling", "The plant's own cutting physics: the arm with its own chip, linearised (physics or numerics)",
     "15 min", PY + ["studies/chip_coupling_stability.py", "--face-and-contour", "--drake", "--drake-play"]),
    ("regenerative_chatter", "The plant's own cutting physics: the chip that follows the tool, as a plant option",
     "5 min", PY + ["studies/regenerative_chatter.py"]),
    ("regenerative_onset", "The same: the onset at 0.125 ms (a short window)", "1 min",
     PY + ["studies/regenerative_chatter.py", "--paper", "--step-ms", "0.125", "--until-s", "2.6"]),
    ("chatter_check", "The plant's own cutting physics: the check robstiff simulate runs (chatter)", "1 min",
     PY + ["studies/chatter_check_scenarios.py", "--dense", "--slow-feed", "--simulate-timing"]),
    ("fc_budget", "The error budget (face and contour)", "30-60 min (results.md)",
     CLI + ["simulate", "diagrams/face_and_contour.yaml", "--compensation", "on", "--budget", "--out", "{out}/fc_budget"]),
    ("paper_reproduction", "The paper's figures from stated imperfections", "10 min",
     PY + ["studies/paper_reproduction.py", "--no-budget"]),
    ("paper_cylinder_head", "The paper's figures: the cylinder head's readings only", "5 min",
     PY + ["studies/paper_reproduction.py", "--no-budget", "--part", "cylinder head"]),
    ("paper_cylinder_head_deck", "The cylinder head as a four-cylinder deck (mastering draw 0)", "10 min",
     PY + ["studies/cylinder_head_deck.py", "--draw", "0"]),
    ("paper_cylinder_head_raw_deck", "The cylinder head as a four-cylinder deck: a raw casting's tilted deck "
     "(mastering draw 0, the published tolerance's upper end)", "20-40 min",
     PY + ["studies/cylinder_head_deck.py", "--deck-only", "--draw", "0", "--raw-deck-tilt", "1.5"]),
    ("deck_zigzag_trace", "The cylinder head as a four-cylinder deck: why the zigzag pass cuts deeper compensated",
     "4 min", PY + ["studies/deck_pass_trace.py", "--zigzag"]),
    ("paper_budgets", "The paper's figures: the budgets' field split", "25 min",
     PY + ["studies/paper_reproduction.py", "--budget-only", "--one-at-a-time"]),
    ("paper_budgets_ordered", "The paper's figures: the ordered budgets", "40 min (results.md)",
     PY + ["studies/paper_reproduction.py", "--budget-only"]),
    ("robot_library", "The block test on every robot of the library", "30 s",
     PY + ["studies/robot_library_block_test.py"]),
    ("cutting_forces", "The cutting forces", "10 s", PY + ["studies/cutting_force_calibration.py"]),
    ("time_step", "The plant's step: stability and convergence", "6 min", PY + ["studies/time_step_convergence.py"]),
    ("table2", "2. The paper's Table 2", "30 s", CLI + ["table2", "--plot", "{out}/table2.png"]),
    ("stiffness_map", "3. Stiffness map", "30 s", CLI + ["stiffness-map", "--out", "{out}/stiffness_map.png"]),
    ("kg_study", "3. The K_g study", "30 s", CLI + ["kg-study"]),
    ("sweep_interrupted_cut", "4. The sweep (60 runs)", "6 min",
     CLI + ["sweep", "interrupted_cut", "--period-ms", "2,4,8,12,16,24,32,48,64,100", "--cutoff-hz", "2,5,20",
            "--mode", "plain,predictive", "--json", "{out}/sweep_interrupted_cut.json",
            "--plot", "{out}/sweep_interrupted_cut.png"]),
    ("interrupted_cut", "4. The sampling-delay study: the scenario's single run", "10 s",
     CLI + ["simulate", "diagrams/interrupted_cut.yaml", "--out", "{out}/interrupted_cut"]),
    ("sweep_block", "4. The block test at the paper's own settings (18 runs)", "1 min",
     CLI + ["sweep", "block_milling", "--period-ms", "4", "--delay-steps", "0,1,2", "--cutoff-hz", "2,5,10",
            "--mode", "plain,predictive"]),
    ("stability_boundary", "4. The stability boundary (56 runs)", "6 min",
     PY + ["studies/stability_boundary.py", "--json", "{out}/sweep_low_damping_boundary.json",
           "--plot", "{out}/sweep_low_damping_boundary.png"]),
    ("aliasing", "4. Aliasing", "5 min", PY + ["studies/aliasing.py"]),
]
GROUPS = {
    "sweeps": ["sweep_interrupted_cut", "sweep_block", "stability_boundary"],
    "paper": ["paper_reproduction", "paper_budgets"],
    "quick": ["demo", "paper_forces", "cylinder_head", "cutting_forces", "table2", "stiffness_map", "kg_study"],
    "cutting_law": ["demo", "paper_forces", "cylinder_head", "finishing_pass", "posted_program", "robot_library",
                    "paper_reproduction", "interrupted_cut", "sweep_block"],
}
NAMES = {f[0]: f for f in FIGURES}


def selected(only):
    """The entries named (a group expands to its names), in the list's order;
    a name that does not exist: a one-line error, exit 2."""
    want = set()
    for name in only:
        if name in GROUPS:
            want.update(GROUPS[name])
        elif name in NAMES:
            want.add(name)
        else:
            print(f"rerun_results: --only {name}: no such figure (names: {', '.join(NAMES)}; groups: "
                  f"{', '.join(GROUPS)})", file=sys.stderr)
            sys.exit(2)
    return [f for f in FIGURES if f[0] in want]


def command_of(entry, out):
    return [part.replace("{out}", str(out)) for part in entry[3]]


def shown(cmd):
    cmd = ["python" if c == sys.executable else c for c in cmd]
    if cmd[:3] == ["python", "-m", "robstiff_drake"]:
        cmd = ["robstiff"] + cmd[3:]
    return shlex.join(cmd)


def run(entry, out):
    """Run one figure's command in the repository; its output to OUT/NAME.txt."""
    name = entry[0]
    cmd = command_of(entry, out)
    print(f"== {name}: {shown(cmd)} (about {entry[2]})", flush=True)
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    dt = time.perf_counter() - t0
    fd, tmp = tempfile.mkstemp(dir=out, prefix=f".{name}.", suffix=".txt")
    with os.fdopen(fd, "w") as f:
        f.write(f"$ {shown(cmd)}\n{proc.stdout}")
    os.chmod(tmp, 0o644)
    os.replace(tmp, out / f"{name}.txt")
    print(f"   exit {proc.returncode}, {dt:.0f} s wall -> {out / (name + '.txt')}", flush=True)
    return proc.returncode


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--list", action="store_true", help="list the figures' names, times and commands")
    ap.add_argument("--only", action="append", default=[], metavar="NAME", help="rerun this figure or group")
    ap.add_argument("--all", action="store_true", help="rerun every figure")
    ap.add_argument("--out", default="robstiff-rerun", help="folder for the outputs (default robstiff-rerun/)")
    args = ap.parse_args(argv)
    entries = FIGURES if args.all else selected(args.only)
    if args.list or not entries:
        for name, section, t, _ in FIGURES:
            print(f"{name:24s} {t:>24s}  {section}")
            print(f"{'':24s} {'':>24s}  $ {shown(command_of(NAMES[name], args.out))}")
        print("groups: " + "; ".join(f"{g}: {', '.join(v)}" for g, v in GROUPS.items()))
        return 0
    out = Path(args.out).resolve()
    out.mkdir(parents=True, exist_ok=True)
    failed = [e[0] for e in entries if run(e, out) != 0]
    if failed:
        print(f"rerun_results: failed: {', '.join(failed)} (their outputs in {out})", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
