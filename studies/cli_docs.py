"""Regenerates the example outputs of docs/cli.md and README.md from what
the commands print, or checks that they still match.

Every fenced block marked ``<!-- run -->`` (tests/doc_blocks.py) whose
commands carry the ``$ `` prompt is run, page by page in a temporary folder
of its own (the files a block writes stay for the next, as the wheel test
runs them; a block's ``setup`` clause first), and the lines after each
``$ command`` up to the next are replaced by what the command printed
(standard output and standard error, as a terminal shows them).  Blocks
marked ``skip``, or ``shorten`` (their shown output is of the longer run),
are left as they are.

``--check`` writes nothing: it reports each block whose shown output no
longer matches, where matching means the same text and every number equal
to the printed one within one unit of its last printed digit (numbers of
wall-clock time, real-time factors, run ids and dates are not compared:
they change from run to run).  ``--only TEXT`` keeps the blocks whose
commands contain TEXT (repeatable); ``--page`` picks the pages.

Run: python3 studies/cli_docs.py [--check] [--page cli.md|README.md] [--only TEXT]
"""

import argparse
import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from doc_blocks import blocks  # noqa: E402

PAGES = {"cli.md": "cli.md", "README.md": "../README.md"}  # as doc_blocks names them (relative to docs/)
NUMBER = re.compile(r"[-+]?(?:\d+\.\d*|\.\d+|\d+)(?:[eE][-+]?\d+)?")
# what changes from run to run: not compared
PROGRESS_LINE = re.compile(r"robstiff: .*: [\d.]+(/[\d.]+)? .*after \d+ s\s*$")
VOLATILE = [re.compile(p) for p in (
    r"in [\d.]+( \+ [\d.]+)* s wall", r"[\d.]+ s wall", r"\([\d.]+x real time\)", r"[\d.]+x real time",
    r"run[_ ]id:? ?[0-9a-f-]+", r"\([0-9a-f]{12}\)", r"\d{4}-\d{2}-\d{2}(T[\d:]+)?", r"in [\d.]+ s\b",
    r"\([\d.]+ MB", r"[\d.]+ MB", r"\d(\.\d+)?e-(1\d|[2-9]\d)")]  # ... and numbers below 1e-9: rounding
TIMEOUT_S = 1800


def _mask(text):
    for pat in VOLATILE:
        text = pat.sub("<volatile>", text)
    return text


def _numbers_match(a, b):
    """None when line b is line a with each number within one unit of a's last printed digit."""
    if NUMBER.sub("#", a) != NUMBER.sub("#", b):
        return f"shown {a!r}, printed {b!r}"
    for x, y in zip(NUMBER.findall(a), NUMBER.findall(b)):
        mantissa, _, exponent = x.lower().partition("e")
        digits = len(mantissa.split(".")[1]) if "." in mantissa else 0
        unit = 10.0 ** (-digits) * (10.0 ** int(exponent) if exponent else 1.0)
        if abs(float(x) - float(y)) > 1.0001 * unit:
            return f"shown {x} in {a!r}, printed {y}"
    return None


def _line_match(a, b):
    if "\u2026" in a:  # '…' in a shown line stands for any text (a path, say)
        pattern = ".*".join(re.escape(part) for part in a.split("\u2026"))
        return None if re.fullmatch(pattern, b) else f"shown {a!r}, printed {b!r}"
    return _numbers_match(a, b)


def align(shown, printed):
    """(None, printed lines aligned to the shown ones) when ``printed``
    matches ``shown``: text equal, each number within one unit of its last
    printed digit, a shown line '...' standing for any printed lines, '…'
    in a line for any text; else (the first difference, None).  Volatile
    numbers (VOLATILE) are not compared."""
    a_lines = [line.rstrip() for line in shown.strip("\n").splitlines()]
    b_raw = [line.rstrip() for line in printed.strip("\n").splitlines()]
    b_lines = [_mask(line) for line in b_raw]
    out, j = [], 0
    for i, a in enumerate(a_lines):
        if a.strip() == "...":
            nxt = next((x for x in a_lines[i + 1:] if x.strip() != "..."), None)
            if nxt is None:
                j = len(b_lines)
                out.append(a)
                continue
            k = j
            while k < len(b_lines) and _line_match(_mask(nxt), b_lines[k]) is not None:
                k += 1
            if k == len(b_lines):
                return f"nothing printed matches the shown line {nxt!r}", None
            j = k
            out.append(a)
            continue
        if j >= len(b_lines):
            return f"shown {a!r}, nothing more printed", None
        diff = _line_match(_mask(a), b_lines[j])
        if diff is not None:
            return diff, None
        out.append(b_raw[j] if "\u2026" not in a else a)
        j += 1
    if j < len(b_lines):
        return f"{len(b_lines) - j} more line(s) printed than shown (first: {b_raw[j]!r})", None
    return None, out


def same_output(shown, printed):
    return align(shown, printed)[0]


def run(command, folder):
    """What ``command`` prints in ``folder`` (stdout then stderr, as lines come), and its exit status."""
    env = dict(os.environ, COLUMNS="120", PYTHONWARNINGS="ignore")
    p = subprocess.run(["bash", "-c", command], cwd=folder, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                       text=True, timeout=TIMEOUT_S, env=env)
    # a long task's progress lines off a terminal (robstiff_drake/progress.py, one every 5 s) depend on the
    # machine's speed: a terminal shows a bar that ends cleared, the docs show neither
    kept = [line for line in p.stdout.splitlines(keepends=True) if not PROGRESS_LINE.match(line)]
    return "".join(kept), p.returncode


def segments(block):
    """[(command line index in the body, its command, the shown output text)] of a prompted block."""
    out, i, body = [], 0, block.body
    while i < len(body):
        if body[i].startswith("$ "):
            start = i
            command = body[i][2:].strip()
            while command.endswith("\\") and i + 1 < len(body):
                i += 1
                command = command[:-1].rstrip() + " " + body[i].strip()
            j = i + 1
            while j < len(body) and not body[j].startswith("$ "):
                j += 1
            out.append((start, i, re.sub(r"\s+#(\s.*)?$", "", command), "\n".join(body[i + 1:j])))
            i = j
        else:
            i += 1
    return out


def process(page, check, only):
    """Run the page's blocks; returns (new text of the page, [(where, difference)])."""
    path = ROOT / "docs" / PAGES[page]
    lines = path.read_text(encoding="utf-8").split("\n")
    problems, replacements = [], []
    with tempfile.TemporaryDirectory() as folder:
        for b in blocks(PAGES[page]):  # the page's example files first, as the wheel test writes them
            if b.example_file:
                (Path(folder) / b.example_file).write_text("\n".join(b.body) + "\n", encoding="utf-8")
        for b in blocks(PAGES[page]):
            if b.marker is None or "skip" in b.clauses or "exit" in b.clauses or not b.shows_commands():
                continue
            segs = segments(b)
            if not segs:
                continue
            wanted = not only or any(o in " ".join(s[2] for s in segs) for o in only)
            if "setup" in b.clauses and wanted:
                run(b.clauses["setup"], folder)
            for start, last, command, shown in segs:
                if not wanted:
                    continue
                printed, code = run(command, folder)
                if "shorten" in b.clauses:
                    continue
                where = f"{page}:{b.line + 1 + start}"
                if code != 0:
                    problems.append((where, f"`{command}` exited {code}: {printed.strip()[-300:]}"))
                    continue
                if not shown.strip():  # the page shows no output for this command
                    continue
                diff, _ = align(shown, printed)
                if diff is not None:
                    problems.append((where, diff))
                    first = b.line + last + 1  # 0-based index of the line after the command
                    new = printed.rstrip("\n").split("\n") if printed.strip() else []
                    replacements.append((first, first + len(shown.split("\n")), new))
    for a, z, new in sorted(replacements, reverse=True):
        lines[a:z] = new
    return "\n".join(lines), problems


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--check", action="store_true", help="compare only; write nothing")
    ap.add_argument("--page", action="append", choices=sorted(PAGES), help="(default: both)")
    ap.add_argument("--only", action="append", help="only the blocks whose commands contain this text")
    args = ap.parse_args(argv)
    bad = 0
    for page in args.page or sorted(PAGES):
        text, problems = process(page, args.check, args.only)
        for where, what in problems:
            print(f"{where}: {what}")
        bad += len(problems)
        if problems and not args.check:
            (ROOT / "docs" / PAGES[page]).write_text(text, encoding="utf-8")
            print(f"wrote {page}: {len(problems)} output(s) regenerated")
    if args.check:
        print("the docs' outputs match what the commands print" if not bad else f"{bad} output(s) differ")
    return 1 if bad and args.check else 0


if __name__ == "__main__":
    sys.exit(main())
