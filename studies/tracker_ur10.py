"""A real laser-tracker data set (a UR10, two series a year apart, measured
by third parties: tests/realdata.py, ROBSTIFF_REALDATA) diagnosed as a user
would: the robot file a user writes from UR's published DH table
(tests/data/ur10_user.yaml), series A (2020, 11,911 poses) diagnosed with
--validate on series B (2021, 1,495 other poses), and series B alone.
Prints the held-out 3D errors (5 pose-grouped folds), the periodic joint
errors found, and what carries over from A to B.  Stops with the reason when
the data are absent.  With --docs, replaces the ``ur10`` block of
docs/diagnosis.md with the report of A validated on B.

Run: python3 studies/tracker_ur10.py [--docs]
"""

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
from generated_blocks import replace_block  # noqa: E402
import realdata  # noqa: E402

ROBOT = ROOT / "tests" / "data" / "ur10_user.yaml"
COMMANDS = ["python3 tests/realdata.py ur10 A ur10_A.csv", "python3 tests/realdata.py ur10 B ur10_B.csv",
            "robstiff diagnose ur10_A.csv --robot tests/data/ur10_user.yaml --validate ur10_B.csv "
            "--write-robot ur10_calibrated.yaml"]


def diagnose(folder, data, *extra):
    out = folder / (Path(data).stem + ".json")
    t0 = time.perf_counter()
    res = subprocess.run([sys.executable, "-m", "robstiff_drake", "diagnose", str(data), "--robot", str(ROBOT),
                          "--json", str(out), *map(str, extra)], cwd=folder, capture_output=True, text=True)
    if res.returncode != 0:
        sys.exit(res.stderr)
    # the robot file as the command above names it (relative to the clone), not this checkout's absolute path
    return json.loads(out.read_text()), res.stdout.replace(str(ROBOT), "tests/data/ur10_user.yaml"), \
        time.perf_counter() - t0


def summary(name, rep, seconds):
    e = rep["error_3d_mm"]
    per = rep["periodic_errors"]
    lines = [f"{name}: {rep['n_measurements']} poses ({len(rep['outliers'])} gross outliers left out), held-out mean "
             f"3D error {e['before']['mean']:.3f} -> {e['after']['mean']:.3f} mm (rms {e['before']['rms']:.3f} -> "
             f"{e['after']['rms']:.3f}, max {e['before']['max']:.3f} -> {e['after']['max']:.3f}); "
             f"{len(per)} periodic joint errors; residual map "
             f"{'kept' if rep['residual_map'] and rep['residual_map']['kept'] else 'not kept'}; {seconds:.0f} s",
             "  effects: " + ", ".join(rep["selected_effects"]),
             "  largest periodic errors: " + "; ".join(p["text"] for p in per[:6])]
    v = rep.get("validation")
    if v:
        vr = v["error_3d_mm_reregistered"]
        lines.append(f"  on {Path(v['data']).name}, registration refitted: mean {vr['before']['mean']:.3f} (robot "
                     f"file's arm) -> {vr['after']['mean']:.3f} mm (fitted model)")
        lines += [f"    {t['text']}" for t in v["transfer"]]
    return "\n".join(lines)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--docs", action="store_true", help="replace the ur10 block of docs/diagnosis.md")
    args = ap.parse_args()
    reason = realdata.missing(realdata.IPA_UR10)
    if reason:
        sys.exit(f"skipped: {reason}")
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        a = realdata.ipa_ur10_campaign_csv("A", folder / "ur10_A.csv")
        b = realdata.ipa_ur10_campaign_csv("B", folder / "ur10_B.csv")
        rep_a, text_a, s_a = diagnose(folder, a.name, "--validate", b.name, "--write-robot", "ur10_calibrated.yaml")
        rep_b, _, s_b = diagnose(folder, b.name)
        print(summary("series A (2020), validated on B (2021)", rep_a, s_a))
        print(summary("series B (2021) alone", rep_b, s_b))
        if args.docs:
            doc = ROOT / "docs" / "diagnosis.md"
            numbers = summary("series A (2020), validated on B (2021)", rep_a, s_a) + "\n" + summary(
                "series B (2021) alone", rep_b, s_b)
            text = replace_block(doc.read_text(), "ur10", "```\n" + text_a.strip() + "\n```")
            doc.write_text(replace_block(text, "ur10_summary", "```\n" + numbers + "\n```"))
            print(f"wrote {doc}")


if __name__ == "__main__":
    main()
