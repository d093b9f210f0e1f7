"""The machining-run loop closed three times: a compensated cut whose plant
carries something the compensator lacks is simulated, `robstiff diagnose-run`
traces the residual surface error from the run's own data (force estimate,
commanded joint angles, laser scan), fixes the compensator and cuts again.

  softer joint 3   block test, the plant's joint 3 20 % softer than the model
  lost motion      block test, 40 urad of backlash on joints 1-3
  loop lag         interrupted_cut, plain compensation at a 24 ms period

Prints the before/after table; writes each case's run and diagnosis under
OUT (default: a temporary folder) and copies the plots to docs/ with --docs.
The README's table comes from `python3 studies/run_diagnosis_cases.py --docs`.
"""

import argparse
import shutil
import tempfile
from pathlib import Path

from robstiff_drake.commands.main import main as robstiff
from robstiff_drake.diagrams.run_diagnosis import diagnose_run
from robstiff_drake.model.robot import load_robot
from robstiff_drake.paths import DIAGRAMS_DIR, REPO_ROOT

BLOCK = (DIAGRAMS_DIR / "block_milling.yaml").read_text()
CASES = {
    "softer_joint_3": BLOCK.replace("plant:\n", "plant:\n  joint_stiffness_Nm_per_rad: [1.5e6, 1.1e6, 6.4e5, "
                                    "3.0e5, 3.0e5, 2.0e5]\n", 1),
    "lost_motion": BLOCK.replace("plant:\n", "plant:\n  lost_motion_rad: [4.0e-5, 4.0e-5, 4.0e-5, 0.0, 0.0, 0.0]\n", 1),
    "loop_lag": (DIAGRAMS_DIR / "interrupted_cut.yaml").read_text(),
}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=None)
    ap.add_argument("--docs", action="store_true", help="copy the before/after plots to docs/")
    args = ap.parse_args()
    out = Path(args.out or tempfile.mkdtemp(prefix="robstiff-run-diagnosis-"))
    robot = load_robot()
    print("| case (what the plant has) | traced cause (fitted) | fix | before: mean / max abs (mm) | "
          "after: mean / max abs (mm) |")
    print("|---|---|---|---|---|")
    for name, text in CASES.items():
        sc = out / f"{name}.yaml"
        sc.write_text(text)
        run_dir = out / name
        robstiff(["simulate", str(sc), "--compensation", "on", "--out", str(run_dir)])
        rep, before, after = diagnose_run(run_dir, robot)
        cause = rep.get("cause", rep["selected"][0] if rep["selected"] else "none")
        params = rep["params"].get(cause) or next(
            (r["params"] for r in rep["rounds"][0] if r["name"] == cause and r["status"] == "ok"), {})
        fitted = ", ".join(f"{k} = {v:.3g}" for k, v in params.items())
        b, a = rep["surface_error_before_mm"], rep.get("surface_error_after_mm", {})
        alt = (f" (from the one pass: {rep['selected'][0]} first, {', '.join(rep['also_consistent_with'])} as "
               "good; the second cut with each fix decided)") if rep.get("also_consistent_with") else ""
        print(f"| {name} | {cause} ({fitted}){alt} | {rep['fix']} | {b['mean']:+.3f} / {b['max_abs']:.3f} | "
              f"{a.get('mean', float('nan')):+.3f} / {a.get('max_abs', float('nan')):.3f} |")
        if args.docs:
            from robstiff_drake.commands.diagnose_run import plot

            plot(before, after, REPO_ROOT / "docs" / f"run_diagnosis_{name}.png", f"{name}: fix = {rep['fix']}")
    if args.out is None:
        shutil.rmtree(out, ignore_errors=True)


if __name__ == "__main__":
    main()
