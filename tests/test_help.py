"""Help that helps, and output a user controls: an example in every
subcommand's --help (each one parses), Table 2's grouping in its --help,
negative vector values (--tool -10,0,350), a ';'-separated campaign from a
spreadsheet with decimal commas read and noted, progress bars on
sweeps and simulations (off off a terminal, forced with --progress,
silenced with --quiet), and --quiet keeping results and warnings."""

import json
import shlex

import pytest

from robstiff_drake import progress
from robstiff_drake.commands.main import EXAMPLES, _subcommands, build_parser, main, vector_values_kept
from robstiff_drake.paths import DIAGRAMS_DIR


def run(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def test_every_subcommand_has_an_example_that_parses(capsys):
    parser = build_parser()
    names = [name for name, _ in _subcommands(parser)]
    assert set(names) == set(EXAMPLES)
    for name in names:
        with pytest.raises(SystemExit):
            main([*name.split(), "--help"])
        out = capsys.readouterr().out
        assert out.rstrip().endswith(f"Example: {EXAMPLES[name]}"), name
        for command in EXAMPLES[name].split("&&"):
            argv = shlex.split(command)
            assert argv[0] == "robstiff"
            args = build_parser().parse_args(vector_values_kept(argv[1:]))  # raises on a bad example
            assert " ".join([args.command] + ([args.kind] if getattr(args, "kind", None) else [])) in \
                (name, "synth stiffness", "synth payload", "simulate", "make-urdf")


# the examples that run in about a second (the others simulate, identify
# or wait for a network peer)
QUICK_EXAMPLES = ["robots", "fk", "stiffness", "synth", "synth stiffness", "synth payload", "identify",
                  "calibrate-payload", "plan-poses", "table2"]


@pytest.mark.parametrize("name", QUICK_EXAMPLES)
def test_quick_examples_run(capsys, tmp_path, monkeypatch, name):
    """What a reader copies from --help works as written (in an empty folder)."""
    monkeypatch.chdir(tmp_path)
    for command in EXAMPLES[name].split("&&"):
        code, out, err = run(capsys, *vector_values_kept(shlex.split(command)[1:]))
        assert code == 0, (command, err)


def test_table2_help_gives_the_grouping(capsys):
    from robstiff_drake.identification.stiffness.table2_grouping import GROUPS

    with pytest.raises(SystemExit):
        main(["table2", "--help"])
    out = capsys.readouterr().out
    assert "assumption" in out and "A1 (rows 1-3)" in out
    for name in GROUPS:
        assert f"  {name}: rows" in out
    code, out, _ = run(capsys, "table2")
    assert code == 0 and "grouping of the rows by pose: see `robstiff table2 --help`" in out


@pytest.mark.parametrize("argv, value", [
    (["stiffness", "0", "30", "20", "0", "40", "0", "--tool"], "-10,0,350"),
    (["fk", "0", "30", "20", "0", "40", "0", "--tool"], "-1e3,0,-5"),
    (["fk", "0", "-30", "20", "0", "40", "0", "--tool"], "-.5,-0,350"),
])
def test_negative_vector_values_in_both_forms(capsys, argv, value):
    code, spaced, err = run(capsys, *argv, value, "--json", "-")
    assert code == 0, err
    code, joined, err = run(capsys, *argv[:-1], f"--tool={value}", "--json", "-")
    assert code == 0, err
    assert json.loads(spaced) == json.loads(joined)
    assert json.loads(spaced)["tool_mm"] == pytest.approx([float(v) for v in value.split(",")])


def test_negative_values_of_other_vectors(capsys, tmp_path):
    out = tmp_path / "payload.csv"
    code, _, err = run(capsys, "synth", "payload", out, "--com-mm", "-10,0,250", "--quiet")
    assert code == 0, err and out.is_file()
    assert vector_values_kept(["fk", "--tool", "-1,2,3", "--", "--tool", "-4,5,6"]) == \
        ["fk", "--tool=-1,2,3", "--", "--tool", "-4,5,6"]
    assert vector_values_kept(["sweep", "s.yaml", "--period-ms", "-1"]) == ["sweep", "s.yaml", "--period-ms", "-1"]
    code, _, err = run(capsys, "stiffness", "0", "30", "20", "0", "40", "0", "--tool", "-10,0")
    assert code == 2 and "--tool: expected 3 comma-separated numbers" in err


def test_semicolon_campaign_with_decimal_commas_is_read(capsys, tmp_path):
    """A spreadsheet in a locale with a decimal comma saves ';'-separated
    cells with ',' decimals: the ';' is recognised and the commas read, said
    in a note (tests/test_decimal_commas.py: what stays refused)."""
    data = tmp_path / "campaign.csv"
    assert run(capsys, "synth", "stiffness", data, "--n", "12", "--quiet")[0] == 0
    lines = data.read_text().splitlines()
    semi = [ln if ln.startswith("#") else ln.replace(",", ";") for ln in lines]
    (tmp_path / "semi.csv").write_text("\n".join(semi) + "\n")
    code, out, err = run(capsys, "identify", tmp_path / "semi.csv", "--json", "-")
    assert code == 0, err and json.loads(out)["joint_stiffness_Nm_per_rad"]
    assert "decimal commas" not in err
    euro = [ln if ln.startswith("#") else ln.replace(".", ",") for ln in semi]
    (tmp_path / "euro.csv").write_text("\n".join(euro) + "\n")
    code, out2, err = run(capsys, "identify", tmp_path / "euro.csv", "--json", "-")
    assert code == 0, err
    assert json.loads(out2)["joint_stiffness_Nm_per_rad"] == json.loads(out)["joint_stiffness_Nm_per_rad"]
    assert "robstiff: note: " in err and "euro.csv: read with decimal commas" in err, err


def test_quiet_keeps_results_and_warnings(capsys, tmp_path):
    data = tmp_path / "campaign.csv"
    code, out, _ = run(capsys, "synth", "stiffness", data, "--n", "12")
    assert code == 0 and out.startswith(f"wrote {data}")
    code, out, err = run(capsys, "synth", "stiffness", data, "--n", "12", "--quiet")
    assert code == 0 and out == "" and err == ""
    lines = data.read_text().splitlines()
    first = next(i for i, ln in enumerate(lines) if not ln.startswith("#")) + 1
    (tmp_path / "copy.csv").write_text("\n".join(lines + [lines[first]]) + "\n")  # a copied row: a warning
    code, out, err = run(capsys, "identify", tmp_path / "copy.csv", "--quiet")
    assert code == 0 and "identified from" in out and "robstiff: warning:" in err
    assert not progress.quiet()  # main() restores the setting


def test_bar_is_on_when_asked_off_when_quiet(monkeypatch):
    assert progress.bar_enabled(True) and not progress.bar_enabled(False)
    assert not progress.bar_enabled(None)  # pytest's stderr is no terminal
    monkeypatch.setattr("sys.stderr.isatty", lambda: True, raising=False)
    assert progress.bar_enabled(None)
    previous = progress.set_quiet(True)
    try:
        assert not progress.bar_enabled(True) and not progress.bar_enabled(None)
    finally:
        progress.set_quiet(previous)


@pytest.fixture(scope="module")
def short_scenario(tmp_path_factory):
    """The block test's pass ending 20 mm into the block, no dwell (a 2 s run)."""
    text = (DIAGRAMS_DIR / "block_milling.yaml").read_text()
    assert "    - [1717.5, 0.0, 700.0]" in text and "dwell_s: 0.2" in text  # the block test's pass
    text = text.replace("    - [1717.5, 0.0, 700.0]", "    - [1540.0, 0.0, 700.0]").replace("dwell_s: 0.2",
                                                                                        "dwell_s: 0.0")
    path = tmp_path_factory.mktemp("short") / "short_block.yaml"
    path.write_text(text)
    return path


def test_simulation_progress_bar(capsys, tmp_path, short_scenario):
    argv = ["simulate", short_scenario, "--compensation", "off", "--json", tmp_path / "s.json"]
    code, _, err = run(capsys, *argv, "--out", tmp_path / "a", "--progress")
    assert code == 0 and "uncompensated: 100%" in err and "s simulated" in err
    sim_s = json.loads((tmp_path / "s.json").read_text())["sim_seconds"]
    assert f"{sim_s:.1f}/{sim_s:.1f} s simulated" in err
    code, _, err = run(capsys, *argv, "--out", tmp_path / "b")  # stderr is no terminal: no bar
    assert code == 0 and "simulated" not in err
    code, out, err = run(capsys, *argv, "--out", tmp_path / "c", "--progress", "--quiet")
    assert code == 0 and "simulated" not in err and "wrote " not in out and "surface error" in out


def test_sweep_progress_bar_and_one_period_plot(capsys, tmp_path, short_scenario):
    code, out, err = run(capsys, "sweep", short_scenario, "--period-ms", "4", "--cutoff-hz", "5,10", "--workers", "1",
                         "--no-predict", "--progress", "--plot", tmp_path / "sweep.png")
    assert code == 0, err
    assert "sweep: 100%" in err and "2/2" in err
    assert (tmp_path / "sweep.png").stat().st_size > 10_000


def test_diagnosis_search_bar_on_a_terminal(capsys, tmp_path, monkeypatch):
    """The dictionary search shows a bar per round on a terminal, none with --quiet."""
    data = tmp_path / "campaign.csv"
    assert run(capsys, "synth", "stiffness", data, "--n", "36", "--quiet")[0] == 0
    monkeypatch.setattr("sys.stderr.isatty", lambda: True, raising=False)
    code, out, err = run(capsys, "diagnose", data)
    assert code == 0 and "diagnosis, round 1" in err and "term" in err
    code, out, err = run(capsys, "diagnose", data, "--quiet")
    assert code == 0 and "diagnosis, round" not in err and out


def test_progress_off_a_terminal_is_a_log_line_every_few_seconds(capsys):
    """Off a terminal (pytest's stderr) a task's progress is a log line at
    most every LOG_EVERY_S seconds of an injected clock, at an update;
    nothing for a task shorter than that, nothing with --quiet, and no bar
    (enabled=False) when a command turns it off."""
    now = [0.0]
    bar = progress.LogLines(20, "diagnosis", "step", every_s=5.0, clock=lambda: now[0])
    with bar:
        for _ in range(20):
            now[0] += 1.5
            bar.update(1)
    lines = capsys.readouterr().err.splitlines()
    assert lines == [f"robstiff: diagnosis: {n}/20 step ({5 * n} %) after {1.5 * n:.0f} s"
                     for n in (4, 8, 12, 16, 20)], lines
    assert isinstance(progress.progress(10, None, "x"), progress.LogLines)
    assert progress.progress(10, False, "x").disable
    previous = progress.set_quiet(True)
    try:
        assert progress.progress(10, None, "x").disable
    finally:
        progress.set_quiet(previous)
    quick = progress.progress(3, None, "quick")
    for _ in range(3):
        quick.update(1)
    assert capsys.readouterr().err == ""
