"""Regenerates the examples of docs/diagnosis.md from the commands they
show: each block between ``<!-- generated: NAME -->`` and ``<!-- end NAME
-->`` is replaced by the output of the commands written above it (run here
in a temporary folder, so the paths printed are the ones a user types), and
docs/diagnosis_example/ (the worked example's campaign, report and plots)
is written again.  With ``--studies`` it also runs
studies/diagnosis_confusion.py (30 campaigns per row, about half an hour),
studies/tracker_campaigns.py and the two benchmarks, and replaces the
``confusion``, ``tracker_study`` and ``speed`` blocks (``--confusion FILE``
takes the confusion study's output from a file instead of running it).  The FANUC example needs the real data
(tests/realdata.py; ROBSTIFF_REALDATA), as does its rerun over fold
assignments (studies/fanuc_folds.py): without it those blocks are left as
they were and the script says so.

Every block of the page that shows commands gets its run marker
(tests/doc_blocks.py) from MARKERS here, so the regenerated page carries
them: the wheel test (tests/test_wheel_install.py) runs the worked example
and skips, with the reason, the blocks that need files of a clone (tests/,
benchmarks/) or the real data; a command block no entry matches stops the
script.

``--only NAMES`` (comma-separated block names) regenerates those blocks
alone; the setup-mistake table (``setup``) comes from
studies/setup_findings.py.

Run: python3 studies/diagnosis_docs.py [--studies [--confusion FILE]] [--only NAMES]
"""

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DOC = ROOT / "docs" / "diagnosis.md"
EXAMPLE = ROOT / "docs" / "diagnosis_example"
sys.path.insert(0, str(ROOT / "tests"))

from generated_blocks import replace_block  # noqa: E402


# (a text any of a command block's commands contains, its run marker), first match wins
CLONE = "needs {} of a clone (no wheel holds it)"
MARKERS = (
    ("tests/open_world.py", "run: skip " + CLONE.format("tests/open_world.py")),
    ("robstiff synth tracker", "run: skip a 3000-pose tracker diagnosis (a minute or more)"),
    ("benchmarks/", "run: skip benchmarks of a clone (minutes, timed against the machine's load)"),
    ("fanuc.csv", "run: skip needs the real FANUC campaign (python3 tests/realdata.py fanuc fanuc.csv from a clone, "
                  "with the data in ROBSTIFF_REALDATA)"),
    ("robstiff synth stiffness campaign.csv", "run"),
    ("tests/realdata.py ur10", "run: skip needs the real UR10 series (tests/realdata.py of a clone, with the data in "
                               "ROBSTIFF_REALDATA)"),
)


def mark(text):
    """The page with every command block's run marker (MARKERS) on the line
    above its fence; a command block no entry matches stops the script."""
    from doc_blocks import MARKER, Block

    lines, out, i = text.split("\n"), [], 0
    while i < len(lines):
        if not lines[i].startswith("```"):
            out.append(lines[i])
            i += 1
            continue
        j = i + 1
        while j < len(lines) and not lines[j].startswith("```"):
            j += 1
        b = Block("diagnosis.md", len(out) + 1, lines[i + 1:j])
        if b.shows_commands():
            marker = next((m for key, m in MARKERS if any(key in c for c in b.commands())), None)
            if marker is None and not (out and MARKER.match(out[-1])):
                raise SystemExit(f"docs/diagnosis.md:{len(out) + 1}: a command block without a run marker "
                                 f"({b.commands()[0]}); give it one in MARKERS of studies/diagnosis_docs.py")
            if marker is not None:
                if out and MARKER.match(out[-1]):
                    out.pop()
                out.append(f"<!-- {marker} -->")
        out.extend(lines[i:j + 1])
        i = j + 1
    return "\n".join(out)


def sh(cmd, cwd, env=None):
    """Run a shell line; its stdout (and, for a failure, an error)."""
    proc = subprocess.run(cmd, shell=True, cwd=cwd, capture_output=True, text=True, env=env)
    if proc.returncode != 0:
        raise SystemExit(f"{cmd}: exit {proc.returncode}\n{proc.stderr[-2000:]}")
    return proc.stdout


def block(lines):
    """A generated block's contents: ``lines`` fenced as output."""
    return f"```\n{lines.rstrip()}\n```"


replace = replace_block  # (studies/generated_blocks.py: the block's contents replaced, the markers kept)


def worked_example(tmp):
    """The worked example: synth, diagnose with plots and report; copied to docs/diagnosis_example/."""
    out = sh("robstiff synth stiffness campaign.csv --effect lost_motion=0.03 --seed 5", tmp)
    out += sh("robstiff diagnose campaign.csv --noise-mm 0.01 --plots plots --report report.md 2>/dev/null", tmp)
    if EXAMPLE.exists():
        shutil.rmtree(EXAMPLE)
    EXAMPLE.mkdir()
    shutil.copy(Path(tmp) / "campaign.csv", EXAMPLE / "campaign.csv")
    shutil.copy(Path(tmp) / "report.md", EXAMPLE / "report.md")
    shutil.copytree(Path(tmp) / "plots", EXAMPLE / "plots", ignore=shutil.ignore_patterns("RUN_ID"))
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--studies", action="store_true", help="also run the studies and benchmarks (slow)")
    ap.add_argument("--confusion", metavar="FILE", help="with --studies: diagnosis_confusion.py's output, already run")
    ap.add_argument("--only", help="comma-separated generated blocks to regenerate (default: all)")
    args = ap.parse_args()
    only = set(args.only.split(",")) if args.only else None

    def want(name):
        return only is None or name in only

    text = DOC.read_text(encoding="utf-8")
    env = dict(os.environ, PYTHONPATH=str(ROOT / "tests") + os.pathsep + os.environ.get("PYTHONPATH", ""))
    with tempfile.TemporaryDirectory() as tmp:
        import json

        if want("worked"):
            text = replace(text, "worked", block(worked_example(tmp)))
        if want("open_world"):
            sh(f"python3 {ROOT}/tests/open_world.py hysteresis 5 hyst.csv", tmp, env)
            text = replace(text, "open_world", block(sh("robstiff diagnose hyst.csv --noise-mm 0.01 2>/dev/null",
                                                        tmp)))
        if want("floor"):
            sh("robstiff synth stiffness quiet.csv --seed 5", tmp)
            res = json.loads(sh("robstiff diagnose quiet.csv --noise-mm 0.1 --json - 2>/dev/null", tmp))
            text = replace(text, "floor", block(f"verdict: {res['verdict']}\nfloor_check: "
                                                f"{json.dumps(res['floor_check'])}"))
        if want("setup"):
            out = sh(f"python3 {ROOT}/studies/setup_findings.py --only synth --seeds 1 2 3 2>/dev/null", ROOT, env)
            out += sh(f"python3 {ROOT}/studies/setup_findings.py --only drake --seeds 1 2 3 2>/dev/null", ROOT, env)
            out += sh(f"python3 {ROOT}/studies/setup_findings.py --only beyond --seeds 1 2>/dev/null", ROOT, env)
            text = replace(text, "setup", block(out))
        if want("tracker"):
            sh("robstiff synth tracker tracker.csv --n 3000 --seed 7", tmp, env)
            text = replace(text, "tracker", block(sh("robstiff diagnose tracker.csv --noise-mm 0.03 --write-robot "
                                                      "irb6400_corrected.yaml 2>/dev/null", tmp)))
        import realdata

        reason = realdata.missing(realdata.FANUC)
        if not (want("fanuc") or want("fanuc_folds")):
            pass
        elif reason:
            print(f"FANUC example and its fold study left as they were: {reason}")
        else:
            sh(f"python3 {ROOT}/tests/realdata.py fanuc fanuc.csv", tmp, env)
            out = sh("robstiff diagnose fanuc.csv --robot r2000ic_165f --noise-mm 0.03 2>/dev/null", tmp)
            res = json.loads(sh("robstiff diagnose fanuc.csv --robot r2000ic_165f --noise-mm 0.03 --json - "
                                "2>/dev/null", tmp))
            # the pair the verdict names: the best lead's strongest confounding, else the strongest pair
            lead = res["leads"][0]["name"] if res["leads"] else None
            pairs = [c["terms"] for c in res["confounded"] if lead in c["terms"]] or \
                [c["terms"] for c in res["confounded"]] or [("tool_offset", "stiffness_j3")]
            a, b = pairs[0]
            out += "\n$ robstiff plan-poses 24 --robot r2000ic_165f --separate " \
                   f"{a},{b} --campaign fanuc.csv --noise-mm 0.03\n"
            plan = sh(f"robstiff plan-poses 24 --robot r2000ic_165f --separate {a},{b} --campaign fanuc.csv "
                      "--noise-mm 0.03", tmp)
            out += "\n".join(plan.splitlines()[:12]) + "\n  ..."
            text = replace(text, "fanuc", block(out))
            folds = sh(f"python3 {ROOT}/studies/fanuc_folds.py 2>/dev/null", ROOT, env)
            text = replace(text, "fanuc_folds", folds.strip())
    if args.studies:
        out = Path(args.confusion).read_text() if args.confusion else \
            sh(f"python3 {ROOT}/studies/diagnosis_confusion.py 2>/dev/null", ROOT)
        text = replace(text, "confusion", out.strip())
        out = sh(f"python3 {ROOT}/studies/tracker_campaigns.py --rows 2000 --seeds 2 2>/dev/null", ROOT)
        text = replace(text, "tracker_study", out.strip())
        out = "$ python3 benchmarks/bench_diagnosis.py\n" + sh(f"python3 {ROOT}/benchmarks/bench_diagnosis.py || true", ROOT)
        out += "\n$ python3 benchmarks/bench_tracker.py\n" + sh(f"python3 {ROOT}/benchmarks/bench_tracker.py || true", ROOT)
        text = replace(text, "speed", block(out))
    DOC.write_text(mark(text), encoding="utf-8")
    print(f"wrote {DOC} and {EXAMPLE}")


if __name__ == "__main__":
    main()
