"""Benchmark: `robstiff diagnose` on a 120-row stiffness campaign, the
dictionary search included (about 170-270 candidate fits on pose-grouped
folds, the outlier screens, the lack-of-fit test), beside the plain
identification (`robstiff identify`'s least squares) of the same campaign,
measured in the same run.

Campaigns (robstiff synth, 30 poses x 4 loads, noise 0.01 mm, fixed seeds):
no effect; lost motion in joints 1-3 (the worked example's effect); a tool
offset (a Gauss-Newton term, the slowest of the named library); and the
Drake-made out-of-library campaign with the most search rounds (the play of
joint 1, tests/open_world.py).

Target: at most 2 s per diagnosis.  Prints the median of
``--repeats`` runs per campaign, the identification's median, their ratio
and PASS/FAIL (exit status 1 on FAIL).  Run: python3 benchmarks/bench_diagnosis.py
"""

import argparse
import statistics
import sys
import time
from pathlib import Path

from robstiff_drake.identification.stiffness import synth
from robstiff_drake.identification.diagnosis.campaign_diagnosis import diagnose
from robstiff_drake.identification.stiffness.joint_stiffness import identify
from robstiff_drake.model.robot import load_robot

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
import open_world as ow  # noqa: E402

TARGET_S = 2.0


def median_s(fn, repeats):
    samples = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        samples.append(time.perf_counter() - t0)
    return statistics.median(samples)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args()
    robot = load_robot()
    cases = {
        "no effect": (synth.stiffness_campaign(robot, n=120, noise_mm=0.01, seed=5).to_campaign(), None),
        "lost motion 0.03 mm": (synth.stiffness_campaign(robot, n=120, noise_mm=0.01, seed=5,
                                                         effects={"lost_motion": 0.03}).to_campaign(), None),
        "tool offset 0.03 mm": (synth.stiffness_campaign(robot, n=120, noise_mm=0.01, seed=5,
                                                         effects={"tool_offset": 0.03}).to_campaign(), None),
        "joint-1 play (Drake)": (ow.make_campaign("hysteresis", 5).campaign, ow.TOOL_M),
    }
    worst = 0.0
    print(f"{'campaign':24s} {'diagnose':>10s} {'identify':>10s} {'ratio':>8s}   terms kept")
    for name, (camp, tool) in cases.items():
        d = diagnose(robot, camp, tool_m=tool, noise_mm=0.01)  # warm-up, and what it found
        t_diag = median_s(lambda: diagnose(robot, camp, tool_m=tool, noise_mm=0.01), args.repeats)
        t_id = median_s(lambda: identify(robot, camp, tool_m=tool), 20 * args.repeats)
        worst = max(worst, t_diag)
        kept = ", ".join(t["name"] for t in d.terms) or "none"
        print(f"{name:24s} {t_diag * 1e3:8.0f} ms {t_id * 1e3:8.2f} ms {t_diag / t_id:8.0f}   {kept}")
    ok = worst <= TARGET_S
    print(f"\nslowest diagnosis {worst:.2f} s, target <= {TARGET_S:g} s: {'PASS' if ok else 'FAIL'}")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
