"""The outputs docs/cli.md shows are what the commands print
(studies/cli_docs.py: the same text, every number within one unit of its
last printed digit; wall-clock times, run ids and dates not compared).  The
fast commands' outputs are compared where tests/test_wheel_install.py runs
the page from the wheel (its PRINTS_AS_SHOWN: one run of each command
serves both); all of them, the long ones too (the demo, simulate, sweep,
diagnose-run: minutes), only here with ROBSTIFF_DOC_BLOCKS=all, and
`python3 studies/cli_docs.py` regenerates them all."""

import os
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "studies"))

import cli_docs  # noqa: E402


@pytest.mark.skipif(os.environ.get("ROBSTIFF_DOC_BLOCKS") != "all",
                    reason="the long examples (demo, simulate, sweep, diagnose-run: minutes): ROBSTIFF_DOC_BLOCKS=all")
def test_every_example_prints_what_the_reference_shows():
    _, problems = cli_docs.process("cli.md", True, None)
    assert not problems, "\n".join(f"{w}: {d}" for w, d in problems)


def test_the_comparison_can_fail():
    """A number off by more than its last digit, a changed word, a missing
    line: each is a difference; the elisions ('...', '…') and wall times are not."""
    shown = "surface error +0.202 mm, max 0.21\nwrote /…/run1\n...\nsimulated in 2.39 + 2.27 s wall (17.6x real time)"
    assert cli_docs.same_output(shown, "surface error +0.2025 mm, max 0.21\nwrote /tmp/x/run1\na\nb\n"
                                       "simulated in 9.1 + 8.0 s wall (3.2x real time)") is None
    assert cli_docs.same_output(shown, "surface error +0.204 mm, max 0.21\nwrote /a/run1\nsimulated in 1 s wall") \
        is not None
    assert cli_docs.same_output("max 0.21", "min 0.21") is not None
    assert cli_docs.same_output("a\nb", "a") is not None
    assert cli_docs.same_output("1.5e-03", "1.6e-03") is None and cli_docs.same_output("1.5e-03", "1.7e-03")
