"""Which pose-clustered test the residual diagnosis uses: the same five
figures for each test of identification/diagnosis/clustered_test.py
(REFERENCES: "cr1" the uncorrected CR1 sandwich + F(q, G - 1), as main had;
"htz" CR2 + the HTZ approximate Hotelling T^2 reference; "f_eta" CR2 + the
Wald statistic / q against F(q, eta), HTZ's degrees of freedom without its
Hotelling scaling; "bm" CR2 + a Bell-McCaffrey t per contrast, Bonferroni
over the q tested, the one used),
the whole diagnosis run under each:

  (a) rejections of a true null at a nominal 5 % in 200 draws of the
      synthetic 10-pose regression of tests/clustered_null.py, for q = 1 and
      q = 3 tested parameters (calibrated: about 10 of 200; 3..19 is the 99 %
      band of an exact test);
  (b) pure-spring campaigns of 10 poses x 3 loads where a term is named, 50
      each on the KR 210 R2700 (tool 320 mm) and the IRB 6400
      (studies/small_campaigns.py null_row, same seeds);
  (c) a named effect planted at 4x the noise found on 10 poses x 4 loads,
      3 campaigns per effect (small_campaigns.py planted_row, same seeds);
  (d) the real FANUC R-2000iC campaign (tests/realdata.py; skipped when the
      data are absent): the terms kept, and the first round's clustered p of
      angle_compliance_j1_q2 against the round's level (0.01 / candidates);
  (e) Drake's plant campaign with the declared tool point 20 mm off along z
      (studies/setup_mistakes.py): the terms kept (named: tool_offset kept).

Run: python3 studies/clustered_test_choice.py [--cases 50] [--planted-cases 3] [--docs]
(--docs replaces the clustered_test_choice block of docs/diagnosis.md; about 3 minutes)
"""

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
sys.path.insert(0, str(ROOT / "studies"))

from clustered_null import DRAWS, SEEDS, rejections  # noqa: E402
from generated_blocks import write_block  # noqa: E402
import realdata  # noqa: E402
import setup_errors as se  # noqa: E402
from small_campaigns import KR210_TOOL_M, null_row, planted_row  # noqa: E402

from robstiff_drake.identification.diagnosis import clustered_test as ct  # noqa: E402
from robstiff_drake.identification.diagnosis.campaign_diagnosis import diagnose  # noqa: E402
from robstiff_drake.identification.diagnosis.selection import ALPHA_ROUND  # noqa: E402
from robstiff_drake.model.robot import load_robot  # noqa: E402

LABEL = {"cr1": "CR1 + F(q, G-1) (main)", "htz": "CR2 + HTZ (branch clusterdof)", "f_eta": "CR2 + W/q vs F(q, eta)",
         "bm": "CR2 + Bell-McCaffrey t per contrast, Bonferroni over q (used)"}
FANUC_TERM = "angle_compliance_j1_q2"


def _kept(d):
    return ", ".join(t["name"] for t in d.terms) or "none"


def figures(cases, planted_cases, fanuc):
    """The five figures under the current ct.REFERENCE, as table cells."""
    a = " / ".join(f"{rejections(10, q, SEEDS[q])}/{DRAWS}" for q in (1, 3))
    kr210, irb = load_robot(ROOT / "tests" / "data" / "kr210_r2700.yaml"), load_robot("irb6400")
    b = ", ".join(f"{null_row(robot, tool, 10, cases, 7000 + 100 * 10)[0]}/{cases}"
                  for robot, tool in ((kr210, KR210_TOOL_M), (irb, None)))
    res, undecided = planted_row(irb, 10, planted_cases, 9000 + 1000 * 10)
    c = f"{sum(f for f, _ in res.values())}/{sum(n for _, n in res.values())}"
    d_cell = "absent"
    if fanuc is not None:
        d = diagnose(fanuc[0], fanuc[1], tool_m=fanuc[2], noise_mm=0.03)
        first = d.rounds[0]
        p = next((r.p_grouped for r in first if r.name == FANUC_TERM), float("nan"))
        m = sum(r.status == "ok" for r in first)  # the candidates tried in the round (selection.py)
        d_cell = f"kept: {_kept(d)}; p {p:.2g}, level {ALPHA_ROUND / m:.2g}"
    c_drake = se.make_campaign("none", 11)
    tool = np.asarray(c_drake.declared_tool_m, dtype=float) + np.array([0.0, 0.0, 0.020])
    d = diagnose(load_robot(), c_drake.campaign, tool_m=tool, noise_mm=se.NOISE_MM)
    tp = next((r.p_grouped for r in d.rounds[0] if r.name == "tool_offset"), float("nan"))
    e = f"{'named' if 'tool_offset' in [t['name'] for t in d.terms] else 'not named'} (p {tp:.2g}; kept: {_kept(d)})"
    return [a, b, f"{c} ({undecided} 'too few poses')", d_cell, e]


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", type=int, default=50)
    ap.add_argument("--planted-cases", type=int, default=3)
    ap.add_argument("--only", help="comma-separated REFERENCES (default all)")
    ap.add_argument("--docs", action="store_true", help="replace the clustered_test_choice block of docs/diagnosis.md")
    a = ap.parse_args()
    fanuc = None
    if realdata.missing(realdata.FANUC) is None:
        with tempfile.TemporaryDirectory() as tmp:
            robot, campaign, tool_m, _ = realdata.fanuc_campaign(Path(tmp) / "fanuc.csv")
        fanuc = (robot, campaign, tool_m)
    lines = ["| test | (a) null rejected at 5 %, 10 poses, q = 1 / q = 3 | (b) pure springs, 10 poses, named "
             "(KR 210, IRB 6400) | (c) planted, 10 poses, found | (d) FANUC: kept; j1_q2's p, level | "
             "(e) Drake tool point 20 mm off along z |", "|---|---|---|---|---|---|"]
    used = ct.REFERENCE
    try:
        for ref in (a.only.split(",") if a.only else ct.REFERENCES[::-1]):
            ct.REFERENCE = ref
            lines.append("| " + " | ".join([LABEL[ref]] + figures(a.cases, a.planted_cases, fanuc)) + " |")
            print(lines[-1], flush=True)
    finally:
        ct.REFERENCE = used
    if a.docs:
        # indented: the table sits in a list item of the page
        write_block(ROOT / "docs" / "diagnosis.md", "clustered_test_choice", "\n".join("     " + x for x in lines))
    else:
        print("\n".join(lines))


if __name__ == "__main__":
    main()
