"""Runs with no cause: `robstiff diagnose-run` on compensated cuts whose
compensator's model is the plant's (no stiffness error, no lost motion, no
coupling, no set-up offset), across scenarios, compensation modes, noise
seeds and scan-noise levels.

What counts:
  * any cause named (stiffness_error_jN, lost_motion, joint_coupling,
    setup_offset) is a false positive;
  * the arm's own motion error and the loop's tracking error are predicted
    from the logs and always in the model; they are reported apart: the
    loop's fitted scale a (1: as predicted), the face it moves, and whether
    its fix (plain -> predictive) is offered.  To show that this known part
    is what the machine did, and not a fit, the study sets the prediction
    (a = 1) beside the simulation's own tool path (sim_timeseries, which
    diagnose-run never reads): the rms of their difference against the rms
    of the tool's vertical deviation.

Prints one row per run and the counts (docs/run_diagnosis.md):

    python3 studies/run_diagnosis_no_cause.py [--out DIR]
"""

import argparse
import shutil
import tempfile
import time
from pathlib import Path

from run_diagnosis_cases import _quiet, diagnose, nominal_model

from robstiff_drake.paths import DIAGRAMS_DIR, REPO_ROOT

SOURCES = {
    "short_block": REPO_ROOT / "tests" / "data" / "short_block.yaml",  # 60 mm/s, 120 mm block
    "block_milling": DIAGRAMS_DIR / "block_milling.yaml",  # the paper's test, 20 mm/s
    "interrupted_cut": DIAGRAMS_DIR / "interrupted_cut.yaml",  # three ribs, 60 mm/s
    "cylinder_head": DIAGRAMS_DIR / "cylinder_head.yaml",  # four pads, two scan lines, 20 mm/s
    "balanced_y_pass": REPO_ROOT / "tests" / "data" / "balanced_y_pass.yaml",  # along y, scan along the path
}
# (source, controller mode, noise seed, scan noise mm); mode "as is": the scenario's own (plain)
RUNS = [
    ("short_block", "predictive", 1, 0.003), ("short_block", "predictive", 2, 0.003),
    ("short_block", "predictive", 3, 0.001), ("short_block", "predictive", 4, 0.010),
    ("interrupted_cut", "predictive", 1, 0.003), ("interrupted_cut", "predictive", 2, 0.003),
    ("block_milling", "predictive", 1, 0.003), ("block_milling", "predictive", 2, 0.010),
    ("cylinder_head", "predictive", 1, 0.003), ("cylinder_head", "predictive", 2, 0.003),
    ("short_block", "plain", 1, 0.003), ("block_milling", "plain", 1, 0.003), ("block_milling", "plain", 2, 0.001),
    ("cylinder_head", "plain", 1, 0.003), ("interrupted_cut", "plain", 1, 0.003),
    ("balanced_y_pass", "predictive", 1, 0.003), ("balanced_y_pass", "predictive", 2, 0.001),
    ("balanced_y_pass", "plain", 1, 0.003),
]


def scenario_text(source, mode, noise_mm):
    """The source scenario with the controller's mode and the scan's noise set."""
    text = nominal_model(Path(SOURCES[source]).read_text())  # the compensator is the plant
    text = text.replace("controller:\n", f"controller:\n  mode: {mode}\n", 1) if "  mode: plain" not in text \
        else text.replace("  mode: plain", f"  mode: {mode}", 1)
    return text.replace("scan:\n", f"scan:\n  noise_mm: {noise_mm}\n", 1)


def one_run(folder, source, mode, seed, noise_mm):
    name = f"{source}_{mode}_{seed}_{noise_mm:g}mm"
    sc = Path(folder) / f"{name}.yaml"
    sc.write_text(scenario_text(source, mode, noise_mm))
    run_dir = Path(folder) / name
    if _quiet(["simulate", str(sc), "--compensation", "on", "--out", str(run_dir), "--noise-seed", str(seed)]):
        raise SystemExit(f"simulate {sc} failed")
    rep, seconds = diagnose(run_dir)
    return name, rep, seconds


def known_part_vs_truth(run_dir, a):
    """(rms of the predicted known part's difference from the simulated tool
    path's vertical deviation, rms of that deviation) (mm): the motion error
    and a x the loop's tracking error that diagnose-run predicts from the
    logs, against the simulation's truth (its sim_timeseries file)."""
    import numpy as np

    from robstiff_drake.commands.diagnose_run import run_robot
    from robstiff_drake.diagrams.run_arm import ArmModel
    from robstiff_drake.identification.runs.diagnosis import run_signals
    from robstiff_drake.identification.runs.files import load_run_files

    robot = run_robot(run_dir)
    sig = run_signals(load_run_files(run_dir), robot, ArmModel(robot))
    lines = [ln for ln in (Path(run_dir) / "sim_timeseries_compensated.csv").read_text().splitlines()
             if not ln.startswith("#")]
    names = lines[0].split(",")
    data = np.array([[float(v) for v in ln.split(",")] for ln in lines[1:]])
    col = {n: data[:, i] for i, n in enumerate(names)}
    truth = np.interp(sig.t_s, col["t_s"], col["tool_z_mm"] - col["commanded_z_mm"])
    predicted = (sig.dz_motion_m + a * sig.dz_loop_m) * 1e3
    return float(np.sqrt(np.mean((predicted - truth) ** 2))), float(np.sqrt(np.mean(truth**2)))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=None)
    args = ap.parse_args()
    out = Path(args.out or tempfile.mkdtemp(prefix="robstiff-no-cause-"))
    out.mkdir(parents=True, exist_ok=True)
    print("| run (compensator = plant) | scan rms (mm) | noise floor: stated / from the scan (mm) | n_eff | "
          "causes named | the loop's tracking error: a, face (mm), p; fix offered | known part vs the simulated "
          "tool path: rms difference / rms (mm) | residual explained by noise |")
    print("|---|---|---|---|---|---|---|---|")
    named_runs, seconds, n, worst = 0, [], 0, 0.0
    t0 = time.perf_counter()
    for source, mode, seed, noise in RUNS:
        name, rep, s = one_run(out, source, mode, seed, noise)
        n += 1
        seconds.append(s)
        named = [c["name"] for c in rep["causes"]]
        named_runs += bool(named)
        lag = rep["loop_lag"]
        a = lag["params"]["a (x predicted)"] if lag["status"] == "ok" else 0.0
        lag_txt = (f"{a:.2f}, {lag['size_mm']:.4f}, {lag['p_value']:.2g}; {lag.get('fix') or 'none'}"
                   if lag["status"] == "ok" else lag["status"])
        diff, size = known_part_vs_truth(out / name, 1.0)
        worst = max(worst, diff / size)
        print(f"| {name} | {rep['rms_before_mm']:.4f} | {rep['noise_stated_mm']:.4f} / "
              f"{rep['noise_estimated_mm']:.4f} | {rep['n_effective']:.1f} | {', '.join(named) or 'none'} | "
              f"{lag_txt} | {diff:.4f} / {size:.4f} | "
              f"{'yes' if rep['explains_data'] else 'no: ' + format(rep['unexplained_mm'], '.4f')} |", flush=True)
    print(f"\ncause named (false positive): {named_runs} of {n} runs")
    print(f"the known part (a = 1) against the simulated tool path: at most {100 * worst:.0f} % of its rms off")
    print(f"diagnose-run per run (in this process): median {sorted(seconds)[len(seconds) // 2]:.1f} s, "
          f"max {max(seconds):.1f} s; study {time.perf_counter() - t0:.0f} s")
    if args.out is None:
        shutil.rmtree(out, ignore_errors=True)


if __name__ == "__main__":
    main()
