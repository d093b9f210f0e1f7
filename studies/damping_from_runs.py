"""Does `diagnose-run` read the arm's damping from a run?  Compensated cuts
of the short block (tests/data/short_block.yaml, plain compensation, 60
mm/s) and of the balanced pass (tests/data/balanced_y_pass.yaml, plain, 40
mm/s) simulated with 2, 5 and 10 % modal damping on every mode, 3 um of
scan noise; `diagnose-run` on each: the ratio it reads (or that it could
not), the interval the face allows, and the fit's residual rms.

    python3 studies/damping_from_runs.py
"""

import json
import shutil
import sys
import tempfile
from pathlib import Path

from robstiff_drake.paths import REPO_ROOT

sys.path.insert(0, str(Path(__file__).parent))
from run_diagnosis_cases import _quiet  # noqa: E402  (studies/ is the script's folder)

SCENARIOS = {"short_block": REPO_ROOT / "tests" / "data" / "short_block.yaml",
             "balanced_y_pass": REPO_ROOT / "tests" / "data" / "balanced_y_pass.yaml"}
RATIOS = (0.02, 0.05, 0.10)


def main():
    out = Path(tempfile.mkdtemp(prefix="robstiff-damping-"))
    print("| pass | plant's modal damping | diagnose-run reads | interval the face allows | residual rms (mm) |")
    print("|---|---|---|---|---|")
    try:
        for name, path in SCENARIOS.items():
            for z in RATIOS:
                sc = out / f"{name}_{z:g}.yaml"
                sc.write_text(path.read_text().replace("modal_damping_ratio: 0.05", f"modal_damping_ratio: {z:g}"))
                run = out / sc.stem
                if _quiet(["simulate", str(sc), "--compensation", "on", "--out", str(run)]) != 0:
                    raise SystemExit(f"simulate {sc} failed")
                rep_path = out / f"{sc.stem}.json"
                if _quiet(["diagnose-run", str(run), "--json", str(rep_path)]) != 0:
                    raise SystemExit(f"diagnose-run {run} failed")
                rep = json.loads(rep_path.read_text())
                d = rep["damping"]
                read = f"{d['ratio']:.0%}" if d.get("ratio") is not None else f"not decided (assumes {d['used']:.0%})"
                print(f"| {name} | {z:.0%} | {read} | {d['interval'][0]:.0%}-{d['interval'][1]:.0%} | "
                      f"{rep['rms_after_mm']:.4f} |", flush=True)
    finally:
        shutil.rmtree(out, ignore_errors=True)


if __name__ == "__main__":
    main()
