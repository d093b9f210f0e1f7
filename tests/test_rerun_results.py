"""studies/rerun_results.py: every figure-producing command of docs/results.md
is in its list, and a name it does not know is refused."""

import re
import shlex
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "studies"))

import rerun_results as rr  # noqa: E402


def _program(words):
    """('studies/x.py' or the robstiff subcommand) of a command's words."""
    if words[0] in ("python", "python3"):
        return words[1]
    return words[1] if words[0] == "robstiff" else None


def test_every_figure_command_of_results_md_is_listed():
    listed = {_program(shlex.split(rr.shown(rr.command_of(e, "OUT")))) for e in rr.FIGURES}
    for script in listed:
        assert not script.endswith(".py") or (ROOT / script).is_file(), script
    missing = []
    for line in (ROOT / "docs" / "results.md").read_text().splitlines():
        m = re.match(r"^\$ (.*)$", line)
        if not m:
            continue
        words = shlex.split(m.group(1).split("#")[0])
        prog = _program(words)
        if prog and not prog.startswith("benchmarks/") and prog not in listed:
            missing.append(m.group(1))
    assert not missing, missing


def test_list_and_a_bad_name(capsys):
    assert rr.main(["--list"]) == 0
    out = capsys.readouterr().out
    assert all(name in out for name in rr.NAMES)
    with pytest.raises(SystemExit) as e:
        rr.main(["--only", "no_such_figure"])
    assert e.value.code == 2
    assert "no such figure" in capsys.readouterr().err


def test_a_group_expands_to_its_names():
    assert [e[0] for e in rr.selected(["sweeps"])] == ["sweep_interrupted_cut", "sweep_block", "stability_boundary"]
