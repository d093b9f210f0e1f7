"""docs/cli.md, the command reference, cannot silently fall behind the
code: every subcommand has its section (and no section names a command
that does not exist), every option of a subcommand appears in its section's
option table with the parser's default, every key of the scenario schema
is in the scenario table with its default, and the example input files the
reference shows are read by the commands they are for."""

import argparse
import json
import re
from dataclasses import MISSING, fields, is_dataclass
from pathlib import Path

import pytest

from robstiff_drake.commands.main import _subcommands, build_parser, main

DOC = Path(__file__).resolve().parents[1] / "docs" / "cli.md"
HEADING = re.compile(r"^(#{2,3}) `robstiff ([a-z0-9 -]+)`\s*$")
NUMBER = re.compile(r"[-+]?(\d+(\.\d*)?|\.\d+)([eE][-+]?\d+)?")
GLOBAL_OPTIONS = {"-h", "--help", "--quiet"}


def _doc_lines():
    return DOC.read_text(encoding="utf-8").splitlines()


def headings(lines):
    """(line index, level, text) of the Markdown headings, not counting
    '#' lines inside fenced code blocks (comments of example files)."""
    out, in_code = [], False
    for i, line in enumerate(lines):
        if line.startswith("```"):
            in_code = not in_code
        elif not in_code and line.startswith("#"):
            out.append((i, len(line) - len(line.lstrip("#")), line))
    return out


def command_sections():
    """{'synth stiffness': section text, ...} from the `## `robstiff NAME`` and
    `### `robstiff NAME`` headings; a section runs to the next heading (a
    command's subcommands have sections of their own)."""
    lines = _doc_lines()
    starts = [(i, level, HEADING.match(text)) for i, level, text in headings(lines)]
    sections = {}
    for k, (i, level, m) in enumerate(starts):
        if m is None:
            continue
        name = m.group(2).strip()
        end = starts[k + 1][0] if k + 1 < len(starts) else len(lines)
        assert name not in sections, f"docs/cli.md: two sections for `robstiff {name}`"
        sections[name] = "\n".join(lines[i:end])
    return sections


def option_rows(section):
    """{'--force-N': default cell} of a section's option table (rows whose
    first cell starts with an option in backticks)."""
    rows = {}
    for line in section.splitlines():
        m = re.match(r"^\| `(--[A-Za-z0-9-]+)[^|]*\|.*\|([^|]*)\|\s*$", line.replace("\\|", "/"))
        if m:
            rows[m.group(1)] = m.group(2).strip()
    return rows


def parser_options(parser):
    """(option string, default) of a parser's own options, without -h/--quiet."""
    out = []
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction) or not action.option_strings:
            continue
        name = max(action.option_strings, key=len)
        if name in GLOBAL_OPTIONS:
            continue
        out.append((name, action.default))
    return out


def test_every_subcommand_has_a_section_and_every_section_a_subcommand():
    documented = set(command_sections())
    existing = {name for name, _ in _subcommands(build_parser())}
    assert existing - documented == set(), f"subcommands without a section in docs/cli.md: {existing - documented}"
    assert documented - existing == set(), f"docs/cli.md documents commands that do not exist: {documented - existing}"


def test_every_option_is_in_its_section_with_the_parsers_default():
    sections = command_sections()
    for name, parser in _subcommands(build_parser()):
        rows = option_rows(sections[name])
        for option, default in parser_options(parser):
            assert option in rows, f"docs/cli.md: `robstiff {name}` has no row for {option}"
            cell = rows[option]
            if isinstance(default, bool) or default is None or default is argparse.SUPPRESS:
                continue
            if isinstance(default, (int, float)):
                m = NUMBER.search(cell)
                assert m and float(m.group(0)) == pytest.approx(float(default)), \
                    f"docs/cli.md: `robstiff {name}` {option}: default {default}, the table says {cell!r}"
            else:
                assert str(default) in cell, \
                    f"docs/cli.md: `robstiff {name}` {option}: default {default!r}, the table says {cell!r}"
        # and no row for an option the command does not have
        known = {o for a in parser._actions for o in a.option_strings}
        assert set(rows) - known == set(), f"docs/cli.md: `robstiff {name}` documents unknown options {set(rows) - known}"


def test_global_options_are_documented():
    text = DOC.read_text(encoding="utf-8")
    for option in ("--quiet", "--version", "--help"):
        assert option in text
    for status in ("| 0 |", "| 2 |", "| 130 |", "| 143 |"):
        assert status in text


def _scenario_leaves(cls, prefix=""):
    """(dotted key, default) of every leaf key of the scenario schema; Drake's
    config structs as one entry each."""
    for f in fields(cls):
        if f.metadata.get("internal"):
            continue
        default = f.default if f.default is not MISSING else f.default_factory()
        kind = f.metadata.get("schema", {}).get("kind")
        if is_dataclass(default) and kind != "drake":
            yield from _scenario_leaves(type(default), prefix + f.name + ".")
        else:
            yield prefix + f.name, default, kind


def test_every_scenario_key_is_in_the_scenario_table_with_its_default():
    from robstiff_drake.diagrams.scenario_schema import Scenario

    lines = _doc_lines()
    start = lines.index("## Scenario files")
    end = next(i for i, level, _ in headings(lines) if i > start and level <= 2)
    rows = [ln for ln in lines[start:end] if ln.startswith("| `")]
    for key, default, kind in _scenario_leaves(Scenario):
        section, _, leaf = key.rpartition(".")
        if kind == "drake":  # Drake's own struct: its step and solver are documented as keys
            assert any(f"`{key}." in r.split("|")[1] for r in rows), f"scenario table: no row for {key}"
            continue
        # a row names the key in full, or a section.key followed by sibling leaves (`a.x`, `y`, ...)
        exact = [r for r in rows if f"`{key}`" in r.split("|")[1]]
        hits = exact or [r for r in rows if (section and f"`{section}." in r.split("|")[1]
                                             and f"`{leaf}`" in r.split("|")[1])
                         or (not section and f"`{leaf}`" in r.split("|")[1])]
        assert hits, f"docs/cli.md: the scenario table has no row for {key}"
        if isinstance(default, (int, float)) and not isinstance(default, bool):
            cells = hits[0].split("|")
            names = [n.strip(" `") for n in cells[1].split(",")]
            position = next(i for i, n in enumerate(names) if n in (key, leaf, f"{section}.{leaf}"))
            values = [v.strip() for v in cells[2].split(",")]
            got = NUMBER.search(values[position] if len(values) == len(names) else values[0])
            assert got and float(got.group(0)) == pytest.approx(float(default)), \
                f"docs/cli.md: scenario key {key}: default {default}, the table says {cells[2].strip()!r}"


def example_files():
    """{name: text} of the input files the reference shows, each after a
    `<!-- example-file: NAME -->` line, in the fenced block that follows."""
    text = DOC.read_text(encoding="utf-8")
    found = re.findall(r"<!-- example-file: (\S+) -->\n```[a-z]*\n(.*?)```", text, flags=re.S)
    return dict(found)


def test_example_input_files_are_read_by_their_commands(tmp_path, capsys):
    files = example_files()
    assert set(files) == {"campaign.csv", "payload.csv", "minimal.yaml", "joint_reference.csv"}
    for name, body in files.items():
        (tmp_path / name).write_text(body)
    assert main(["identify", str(tmp_path / "campaign.csv"), "--json", "-"]) == 0
    fit = json.loads(capsys.readouterr().out)
    assert fit["n_measurements"] == 12 and fit["identifiable"] == [True] * 5 + [False]
    assert fit["tool_mm"] == [0.0, 0.0, 350.0]
    assert main(["calibrate-payload", str(tmp_path / "payload.csv"), "--json", "-"]) == 0
    pay = json.loads(capsys.readouterr().out)
    assert pay["n_configurations"] == 5 and abs(pay["mass_kg"] - 40.0) < 1.0  # made with 40 kg

    from robstiff_drake.commands.compensate import read_reference
    from robstiff_drake.diagrams.scenario import load_scenario
    from robstiff_drake.model.robot import load_robot

    sc = load_scenario(tmp_path / "minimal.yaml")
    assert sc.name == "minimal" and len(sc.workpiece.boxes_mm) == 1
    t, q = read_reference(tmp_path / "joint_reference.csv", load_robot(None))
    assert t.tolist() == [0.0, 1.0, 2.0] and q.shape == (3, 6)
