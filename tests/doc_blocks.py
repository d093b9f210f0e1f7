"""The command blocks of docs/*.md, as tests/test_wheel_install.py runs them.

A fenced block that shows commands (lines ``$ robstiff ...``, or bare
``robstiff ...``, ``python3 ...``, ``pip ...`` lines) carries a marker on the
line just above its fence, an HTML comment the rendered page does not show
(as README.md's ``ci:test-command``):

``<!-- run -->``
    run its commands, in order, in the page's own folder (empty at the
    page's first block; the files a block writes stay for the next ones).
``<!-- run: skip REASON -->``
    not run; the test prints the reason (a real cell, a study of the clone,
    a benchmark).
``<!-- run: setup COMMANDS -->``
    run COMMANDS (shell) first: they make the files the page says the
    reader brings (``my_robot.yaml``, a measured plan), from the packaged
    examples.
``<!-- run: shorten --OPTION VALUE ... -->``
    run the block's commands that have these options with these values
    instead (a sweep of 60 runs as 4): options the commands document.
``<!-- run: exit 2 -->``
    every command of the block must fail with exit status 2 and one line
    (and, for a refusal with a detail, its indented ``why:`` lines).
``<!-- run: share -->``
    the block reads nothing from its page's folder: it runs once per test
    session in an empty folder of its own, by the first page to reach it,
    and its status, output and files (and the files it put in the package's
    cache) are every page's whose block has the same commands, exactly
    (``robstiff demo --out robstiff-out``: results.md's and cli.md's, also
    the help's example).

Clauses combine with ``;;`` (``<!-- run: setup ... ;; shorten ... -->``).
A usage line (``robstiff simulate SCENARIO.yaml [--out DIR]``: placeholders
in capitals or options in brackets) needs no marker.  Lines after ``$ ...``
in a block are the output the page shows; they are not compared (numbers
move with every model change; the commands must run).  An
``<!-- example-file: NAME -->`` block is written to NAME in the page's
folder before the page's commands run (the reference's input files).
"""

import re
from dataclasses import dataclass, field
from pathlib import Path

DOCS = Path(__file__).resolve().parents[1] / "docs"
MARKER = re.compile(r"^<!--\s*run(?::\s*(.*?))?\s*-->\s*$")
EXAMPLE_FILE = re.compile(r"^<!--\s*example-file:\s*(\S+)\s*-->\s*$")
COMMAND = re.compile(r"^(\$ |robstiff |python3? |pip3? )")
PLACEHOLDER = re.compile(r"\[--|\b[A-Z][A-Z0-9_]*[A-Z](\.[a-z]+)?\b")


@dataclass
class Block:
    page: str
    line: int  # 1-based line of the opening fence
    body: list
    marker: str = None  # None: no marker; "" : plain run; else the clauses
    example_file: str = None
    clauses: dict = field(default_factory=dict)

    @property
    def where(self):
        return f"docs/{self.page}:{self.line}"

    def commands(self):
        """The block's commands (continuation lines joined), without the
        '$ ' prompt and without a trailing '# comment'."""
        prompted = any(line.startswith("$ ") for line in self.body)
        out, pending = [], None
        for line in self.body:
            if pending is not None:
                pending += " " + line.strip()
            elif prompted and line.startswith("$ "):
                pending = line[2:].strip()
            elif not prompted and COMMAND.match(line.strip()):
                pending = line.strip()
            else:
                continue
            if pending.endswith("\\"):
                pending = pending[:-1].rstrip()
                continue
            out.append(_strip_comment(pending))
            pending = None
        return out

    def is_usage(self):
        """A usage line (placeholders), not a command to run."""
        cmds = [c for c in (line.strip() for line in self.body) if COMMAND.match(c) and not c.startswith("$ ")]
        return bool(cmds) and not any(line.startswith("$ ") for line in self.body) and all(
            PLACEHOLDER.search(c) for c in cmds)

    def shows_commands(self):
        return any(COMMAND.match(line.strip()) for line in self.body) and not self.is_usage()


def _strip_comment(command):
    """``robstiff robots   # the library`` -> ``robstiff robots`` (a '#' after
    whitespace and before a space: the page's comments)."""
    return re.sub(r"\s+#(\s.*)?$", "", command)


def parse_clauses(marker):
    """'setup A ;; shorten --x 1' -> {'setup': 'A', 'shorten': '--x 1'}."""
    out = {}
    for clause in (marker or "").split(";;"):
        clause = clause.strip()
        if not clause:
            continue
        key, _, rest = clause.partition(" ")
        if key not in ("skip", "setup", "shorten", "exit", "share"):
            raise ValueError(f"unknown run-marker clause {key!r} (skip, setup, shorten, exit, share)")
        out[key] = rest.strip()
    return out


def blocks(page):
    """Every fenced block of docs/PAGE with the marker or example-file line above it."""
    lines = (DOCS / page).read_text(encoding="utf-8").splitlines()
    out, i = [], 0
    while i < len(lines):
        if lines[i].startswith("```"):
            start = i
            j = i + 1
            while j < len(lines) and not lines[j].startswith("```"):
                j += 1
            above = lines[start - 1] if start > 0 else ""
            m, ex = MARKER.match(above), EXAMPLE_FILE.match(above)
            b = Block(page, start + 1, lines[start + 1:j], marker=None if m is None else (m.group(1) or ""),
                      example_file=ex.group(1) if ex else None)
            if m is not None:
                b.clauses = parse_clauses(b.marker)
            out.append(b)
            i = j + 1
        else:
            i += 1
    return out


def pages():
    return sorted(p.name for p in DOCS.glob("*.md"))


def shortened(command, shorten):
    """``command`` with the values of those options of ``shorten`` ('--a 1 --b 2') it has replaced
    (a block's other commands keep theirs)."""
    for option, value in shorten_options(shorten).items():
        command = re.sub(rf"(?<=\s){re.escape(option)}(\s+|=)\S+", f"{option} {value}", command)
    return command


def shorten_options(shorten):
    """'--a 1 --b 2' -> {'--a': '1', '--b': '2'}."""
    words = (shorten or "").split()
    return dict(zip(words[::2], words[1::2]))
