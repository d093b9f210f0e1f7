"""How often `robstiff diagnose` names an effect on a small campaign that
carries none (pure six springs plus noise), and how often it still names a
planted effect on campaigns that can show it.  All campaigns: CMM noise
0.01 mm per component, fixed seeds; the noise is NOT stated to the diagnosis
(as a newcomer runs it) for the pure-spring rows, and stated for the planted
rows (as studies/diagnosis_confusion.py does).

Pure springs: 5 poses x 3 loads (15 rows) and 10 poses x 3 loads (30 rows),
300 N, on the KR 210 R2700 file of tests/data (tool point 320 mm along the
flange axis, as the newcomer's campaign that prompted this study) and on the
shipped IRB 6400; a finding is any term in the final model.
Planted: each named effect in its physical pattern at an RMS beyond the
springs of 0.04 mm (4x the noise, capped at its physical top;
tests/physical_effects.py visible_campaign), 700 N loads, on 5, 10 and 30
poses x 4 loads (30: the confusion study's size), IRB 6400; found when the
effect is a term of the final model; on too few poses the verdict should say
so (and name nothing).

Run: python3 studies/small_campaigns.py [--cases 50] [--planted-cases 3]
"""

import argparse
import collections
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
from physical_effects import visible_campaign  # noqa: E402

from robstiff_drake.identification.diagnosis.campaign_diagnosis import diagnose  # noqa: E402
from robstiff_drake.identification.diagnosis.candidates import CANDIDATES  # noqa: E402
from robstiff_drake.identification.stiffness import synth  # noqa: E402
from robstiff_drake.model.robot import load_robot  # noqa: E402

NOISE_MM = 0.01
KR210_TOOL_M = np.array([0.0, 0.0, 0.32])  # the newcomer's tool point (flange frame, m)


def null_row(robot, tool_m, n_poses, cases, base_seed):
    """(campaigns with a finding, Counter of the terms named)."""
    hits, names = 0, collections.Counter()
    for k in range(cases):
        c = synth.stiffness_campaign(robot, n=3 * n_poses, loads_per_pose=3, noise_mm=NOISE_MM,
                                     seed=base_seed + k, tool_m=tool_m)
        d = diagnose(robot, c.to_campaign(), tool_m=tool_m)
        terms = [t["name"] for t in d.terms]
        hits += bool(terms)
        names.update(terms)
    return hits, names


def planted_row(robot, n_poses, cases, base_seed):
    """{effect: (found, campaigns)} and the campaigns whose verdict says the poses are too few to decide."""
    out, undecided = {}, 0
    for e_i, name in enumerate(CANDIDATES):
        rng = np.random.default_rng([base_seed, e_i])
        found = 0
        for k in range(cases):
            c = visible_campaign(robot, name, rng, 0.04, seed=base_seed + 100 * e_i + k, force_N=700.0,
                                 noise_mm=NOISE_MM, n=4 * n_poses)
            d = diagnose(robot, c.to_campaign(), noise_mm=NOISE_MM)
            found += name in [t["name"] for t in d.terms]
            undecided += d.verdict.startswith("too few poses to decide")
        out[name] = (found, cases)
    return out, undecided


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", type=int, default=50)
    ap.add_argument("--planted-cases", type=int, default=3)
    a = ap.parse_args()
    kr210 = load_robot(ROOT / "tests" / "data" / "kr210_r2700.yaml")
    irb = load_robot("irb6400")
    print("pure springs + noise (no effect planted): campaigns with a term named")
    for label, robot, tool in (("KR 210 R2700, tool 320 mm", kr210, KR210_TOOL_M), ("IRB 6400", irb, None)):
        for n_poses in (5, 10):
            hits, names = null_row(robot, tool, n_poses, a.cases, 7000 + 100 * n_poses)
            top = ", ".join(f"{n} {v}" for n, v in names.most_common(3))
            print(f"  {label}, {n_poses} poses x 3 loads: {hits}/{a.cases}" + (f" ({top})" if top else ""))
    print("one named effect planted (0.04 mm beyond the springs, 700 N), IRB 6400: campaigns where it is found")
    for n_poses in (5, 10, 30):
        res, undecided = planted_row(irb, n_poses, a.planted_cases, 9000 + 1000 * n_poses)
        tot = sum(f for f, _ in res.values()), sum(n for _, n in res.values())
        per = ", ".join(f"{k} {f}/{n}" for k, (f, n) in res.items())
        print(f"  {n_poses} poses x 4 loads: {tot[0]}/{tot[1]} ({per}); verdict 'too few poses to decide': "
              f"{undecided}/{tot[1]}")


if __name__ == "__main__":
    main()
