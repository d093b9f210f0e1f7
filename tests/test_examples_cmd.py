"""Scenarios by name and `robstiff examples`: a packaged scenario is found
by its name from any folder (a path that exists wins), a name that is
neither is one line listing the packaged names; `examples --copy DIR`
copies every packaged scenario, program, robot file and example campaign,
never overwriting anything and never leaving half a copy; the example
campaigns are what the command in their first lines makes."""

import os
import shlex
import sys
from pathlib import Path

import pytest

from robstiff_drake.commands.examples import packaged_files
from robstiff_drake.commands.main import main
from robstiff_drake.paths import DIAGRAMS_DIR, examples_dir, find_scenario, packaged_scenarios, scenario_file


def run(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def test_a_scenario_by_name_from_any_folder_and_a_path_wins(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert "block_milling" in packaged_scenarios() and "short_block" in packaged_scenarios()
    assert find_scenario("block_milling") == scenario_file("block_milling")
    assert find_scenario("block_milling.yaml") == scenario_file("block_milling")
    (tmp_path / "block_milling.yaml").write_text("name: mine\n")  # the reader's own file of that name
    assert find_scenario("block_milling.yaml") == Path("block_milling.yaml")
    assert find_scenario("block_milling") == scenario_file("block_milling")  # no such file: the packaged one
    assert find_scenario("diagrams/block_milling.yaml") is None  # a path that does not exist is not a name
    assert find_scenario("no_such") is None


def test_a_name_that_is_neither_is_one_line_naming_the_packaged_ones(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    code, out, err = run(capsys, "simulate", "block_miling", "--out", "x")
    lines = err.strip().splitlines()
    assert code == 2 and len(lines) == 1 and "block_miling: no such scenario file" in lines[0]
    assert all(name in lines[0] for name in packaged_scenarios()) and not (tmp_path / "x").exists()


def test_examples_lists_and_copies_every_packaged_file(tmp_path, capsys):
    code, out, _ = run(capsys, "examples")
    assert code == 0 and "block_milling.yaml" in out and "campaign.csv" in out and "kr240_r2900.yaml" in out
    files = packaged_files()
    assert {f"scenarios/{p.name}" for p in DIAGRAMS_DIR.glob("*.yaml")} <= set(files)
    assert {"README.md", "scenarios/contour_with_arcs.nc", "robots/irb6400.yaml", "campaigns/campaign.csv",
            "campaigns/payload.csv"} <= set(files)
    code, out, _ = run(capsys, "examples", "--copy", tmp_path / "mine")
    assert code == 0 and out.startswith(f"wrote {tmp_path / 'mine'}/: README.md, scenarios/")
    for rel, src in files.items():
        assert (tmp_path / "mine" / rel).read_bytes() == src.read_bytes(), rel
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no temporary folder left


def test_examples_copy_never_overwrites_and_never_leaves_half_a_copy(tmp_path, capsys):
    dest = tmp_path / "cell"
    (dest / "scenarios").mkdir(parents=True)
    mine = dest / "scenarios" / "block_milling.yaml"
    mine.write_text("my own edits\n")
    (dest / "notes.txt").write_text("mine\n")
    code, _, err = run(capsys, "examples", "--copy", dest)
    assert code == 2 and len(err.strip().splitlines()) == 1 and "already exists" in err and "nothing is overwritten" in err
    assert mine.read_text() == "my own edits\n"
    assert sorted(p.relative_to(dest).as_posix() for p in dest.rglob("*")) == [
        "notes.txt", "scenarios", "scenarios/block_milling.yaml"]  # nothing written
    mine.unlink()
    code, out, _ = run(capsys, "examples", "--copy", dest)  # an existing folder: the files go in beside the others
    assert code == 0 and (dest / "notes.txt").read_text() == "mine\n" and (dest / "robots" / "irb6400.yaml").is_file()
    blocker = tmp_path / "a_file"
    blocker.write_text("x\n")
    code, _, err = run(capsys, "examples", "--copy", blocker)
    assert code == 2 and "is a file, not a folder" in err


def test_a_file_that_appears_during_the_copy_stops_it_and_what_was_moved_is_taken_back(tmp_path, monkeypatch,
                                                                                        capsys):
    from robstiff_drake.commands import examples

    dest = tmp_path / "cell"
    dest.mkdir()
    real_link = os.link
    done = []

    def link_then_race(src, dst):
        if len(done) == 3:  # another program writes the next file in between
            Path(dst).write_text("theirs\n")
        real_link(src, dst)
        done.append(dst)

    monkeypatch.setattr(examples.os, "link", link_then_race)
    code, _, err = run(capsys, "examples", "--copy", dest)
    assert code == 2 and "already exists; nothing is overwritten" in err
    left = sorted(p.relative_to(dest).as_posix() for p in dest.rglob("*") if p.is_file())
    assert len(left) == 1 and (dest / left[0]).read_text() == "theirs\n"  # theirs kept, ours taken back
    assert not [p for p in dest.iterdir() if p.name.startswith(".")]


@pytest.mark.parametrize("name", ["campaign.csv", "payload.csv"])
def test_the_example_campaigns_are_what_their_command_makes(tmp_path, monkeypatch, capsys, name):
    """The first lines of an example campaign say how it was made; making it again gives the same file
    (the robot file's path aside).  When the model changes, remake it with that command in examples/."""
    packaged = examples_dir() / name
    lines = packaged.read_text().splitlines()
    made_with = next(line for line in lines if line.startswith("# Made with: "))[len("# Made with: "):]
    argv = shlex.split(made_with)
    assert argv[0] == "robstiff" and name in argv
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(sys, "argv", argv)  # the file's first lines quote the command line
    assert main(argv[1:] + ["--quiet"]) == 0
    again = (tmp_path / name).read_text().splitlines()

    def same(line):
        return "models/irb6400.yaml" if "irb6400.yaml (" in line else line

    assert [same(x) for x in again] == [same(x) for x in lines], \
        f"examples/{name} is not what `{made_with}` makes now; remake it (cd examples && {made_with})"


def test_examples_copy_writes_only_inside_the_folder(tmp_path, capsys, monkeypatch):
    """A symbolic link inside DIR (DIR/scenarios -> elsewhere) is refused
    (before: 17 files written where it pointed); an empty DIR is refused
    (before: the files went into the current folder)."""
    outside = tmp_path / "outside"
    outside.mkdir()
    dest = tmp_path / "cell"
    dest.mkdir()
    (dest / "scenarios").symlink_to(outside, target_is_directory=True)
    code, _, err = run(capsys, "examples", "--copy", dest)
    assert code == 2 and len(err.strip().splitlines()) == 1 and "is a symbolic link to" in err, err
    assert list(outside.iterdir()) == [] and sorted(p.name for p in dest.iterdir()) == ["scenarios"]
    here = tmp_path / "here"
    here.mkdir()
    monkeypatch.chdir(here)
    code, _, err = run(capsys, "examples", "--copy", "")
    assert code == 2 and "an empty folder name" in err, err
    assert list(here.iterdir()) == []
