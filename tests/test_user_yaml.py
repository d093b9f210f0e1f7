"""YAML and JSON that cannot explode (issue 19, item 3): anchors and aliases
are refused in every user file before anything expands them, nesting is
bounded (no RecursionError), files that are not regular files are refused
before they are opened, and an error quotes at most a short, escaped
excerpt of what the file holds.

The alias bombs run in a child process under a memory limit (RLIMIT_AS)
and an alarm, so that a regression fails the test instead of taking the
machine's memory."""

import json
import os
import resource
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

from robstiff_drake.commands.main import main
from robstiff_drake.paths import DEFAULT_ROBOT_YAML

ROOT = Path(__file__).parents[1]
SHORT = (ROOT / "tests" / "data" / "short_block.yaml").read_text()
ROBOT = DEFAULT_ROBOT_YAML.read_text()
PAYLOAD = ("payload_calibration:\n  mass_kg: 40.0\n  com_mm: [0, 0, 180]\n  force_bias_N: [3, -2, 5]\n"
           "  torque_bias_Nm: [0.2, -0.1, 0.05]\n  sensor_mount_rpy_deg: [0, 0, 0]\n")
MEMORY_LIMIT_BYTES = 1 << 30  # the child's address space: a command needs about 0.6 GB
CASE_TIMEOUT_S = 60


def bomb(levels=9, width=9, leaf="lol"):
    """A flow list of ``levels`` anchored lists, each holding ``width``
    aliases of the one before: width**levels leaves from a few KB."""
    parts = [f"&a0 [{', '.join([leaf] * width)}]"]
    parts += [f"&a{i} [{', '.join([f'*a{i - 1}'] * width)}]" for i in range(1, levels)]
    return "[" + ", ".join(parts) + "]"


def _child_limits():
    resource.setrlimit(resource.RLIMIT_AS, (MEMORY_LIMIT_BYTES, MEMORY_LIMIT_BYTES))


CHILD = """
import contextlib, io, json, signal, sys, time
from robstiff_drake.commands.main import main

def alarm(signum, frame):
    raise TimeoutError()

signal.signal(signal.SIGALRM, alarm)
out = []
for argv in json.loads(sys.argv[1]):
    err = io.StringIO()
    t0 = time.perf_counter()
    signal.alarm(%d)
    try:
        with contextlib.redirect_stderr(err):
            code = main(argv)
    except TimeoutError:
        code = "timeout"
    except BaseException as e:
        code = "exception " + type(e).__name__
    signal.alarm(0)
    out.append([code, err.getvalue(), time.perf_counter() - t0])
print(json.dumps(out))
""" % CASE_TIMEOUT_S


def run_limited(cases, cwd):
    """Each argv of ``cases`` through main() in one child process under the
    memory limit: [(exit status or 'timeout', stderr, seconds)]."""
    proc = subprocess.run([sys.executable, "-c", CHILD, json.dumps([[str(a) for a in c] for c in cases])],
                          cwd=cwd, capture_output=True, text=True, preexec_fn=_child_limits,
                          timeout=CASE_TIMEOUT_S * len(cases) + 60)
    assert proc.returncode == 0, proc.stderr[-2000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])


def test_alias_bombs_are_refused_in_every_user_file_under_a_memory_limit(tmp_path, short_run_folder):
    run_folder = short_run_folder
    b = bomb()
    assert len(b) < 2000  # 9**9 = 387 million leaves when expanded
    cases, files = [], []

    def case(name, text, argv, where):
        p = tmp_path / name
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text(text)
        files.append(p)
        cases.append((argv(p), where(p)))

    desc = "description: A short version of block_milling for the tests (120 mm block, fast feed).\n"
    case("desc/s.yaml", SHORT.replace(desc, f"description: {b}\n"),
         lambda p: ["simulate", p, "--out", tmp_path / "o"], lambda p: f"{p}:7: column 15:")
    case("merge/s.yaml", SHORT.replace("cutter:\n", "base: &b {diameter_mm: 75.0}\ncutter:\n  <<: *b\n"),
         lambda p: ["simulate", p, "--out", tmp_path / "o"], lambda p: f"{p}:")
    (tmp_path / "pay").mkdir()
    (tmp_path / "pay" / "s.yaml").write_text(SHORT.replace("\nmodel:\n", "\nmodel:\n  payload_yaml: p.yaml\n", 1))
    case("pay/p.yaml", PAYLOAD.replace("  com_mm: [0, 0, 180]", f"  com_mm: {b}"),
         lambda p: ["simulate", p.parent / "s.yaml", "--out", tmp_path / "o"], lambda p: f"{p}:3:")
    case("robot/r.yaml", ROBOT.replace('source: "the paper\'s Table 1 (standard DH as printed)"', f"source: {b}"),
         lambda p: ["fk", 0, 0, 0, 0, 30, 0, "--robot", p], lambda p: f"{p}:")
    run = tmp_path / "runb"
    shutil.copytree(run_folder, run)
    case("runb/compensator.yaml",
         (run_folder / "compensator.yaml").read_text().replace("  mode: plain", f"  mode: {b}"),
         lambda p: ["diagnose-run", p.parent, "--out", tmp_path / "d"], lambda p: f"{p}:")
    (tmp_path / "comp").mkdir()
    (tmp_path / "comp" / "s.yaml").write_text(SHORT)
    case("comp/c.yaml", (run_folder / "compensator.yaml").read_text().replace("  mode: plain", f"  mode: {b}"),
         lambda p: ["simulate", p.parent / "s.yaml", "--compensator", p, "--out", tmp_path / "o"],
         lambda p: f"{p}:")
    os.mkfifo(tmp_path / "fifo.yaml")  # read, it would block for ever
    cases.append((["simulate", tmp_path / "fifo.yaml"], f"{tmp_path / 'fifo.yaml'}: not a regular file"))
    before = {p: p.read_bytes() for p in files}
    results = run_limited([argv for argv, _ in cases], tmp_path)
    for (argv, where), (code, err, seconds) in zip(cases, results):
        assert code == 2, (argv, code, err[-500:])
        lines = err.strip().splitlines()
        assert len(lines) == 1 and len(lines[0]) < 400, (argv, err[:1000])
        assert where in lines[0], (where, lines[0])
        if "fifo" not in str(argv[1]):
            assert "anchors and aliases" in lines[0], lines[0]
        assert seconds < 20, (argv, seconds)
    assert {p: p.read_bytes() for p in files} == before
    assert not (tmp_path / "o").exists() and not (tmp_path / "d").exists()


def _one_line(capsys, argv, *fragments):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    assert code == 2, (out, err)
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err and len(lines[0]) < 600, err[:2000]
    for f in fragments:
        assert f in lines[0], (f, lines[0])
    return lines[0]


@pytest.mark.parametrize("depth", [65, 5000, 200000])
def test_deep_nesting_is_one_line_in_every_reader(capsys, tmp_path, depth):
    nested = "[" * depth + "]" * depth
    s = tmp_path / "s.yaml"
    s.write_text(SHORT.replace("name: short_block", f"name: short_block\nx: {nested}"))
    _one_line(capsys, ["simulate", s, "--out", tmp_path / "o"], f"{s}:", "nested more than 64 levels deep")
    r = tmp_path / "r.yaml"
    r.write_text(ROBOT.replace("name: irb6400", f"name: irb6400\nx: {nested}"))
    _one_line(capsys, ["fk", 0, 0, 0, 0, 30, 0, "--robot", r], f"{r}:", "nested more than 64 levels deep")
    (tmp_path / "m.json").write_text('{"joint_stiffness_Nm_per_rad": ' + nested + "}")
    s2 = tmp_path / "s2.yaml"
    s2.write_text(SHORT.replace("\nmodel:\n", "\nmodel:\n  identified_json: m.json\n", 1))
    _one_line(capsys, ["simulate", s2, "--out", tmp_path / "o"], f"{tmp_path / 'm.json'}: nested {depth + 1} levels")


def test_errors_quote_a_short_escaped_excerpt(capsys, tmp_path):
    s = tmp_path / "s.yaml"
    huge = ", ".join(str(i) for i in range(200000))
    s.write_text(SHORT.replace("name: short_block", f"name: [{huge}]"))
    line = _one_line(capsys, ["simulate", s], f"{s}:6: name: expected text, got [0, 1, 2")
    assert "199999" not in line
    s.write_text(SHORT.replace("  diameter_mm: 75.0", '  diameter_mm: "line one\\nline two\\u2028\\u001b[31mred"'))
    _one_line(capsys, ["simulate", s], "cutter.diameter_mm: expected a number in mm, got 'line one\\nline "
                                       "two\\u2028\\x1b[31mred'")
    r = tmp_path / "r.yaml"
    r.write_text(ROBOT.replace("name: irb6400", "name: '" + "x" * 100000 + "'\nname2: 1"))
    line = _one_line(capsys, ["fk", 0, 0, 0, 0, 30, 0, "--robot", r], "key 'name2': unknown key")
    r.write_text(ROBOT.replace("  mass_kg: 40.0\n", f"  mass_kg: '{'y' * 100000}'\n"))
    line = _one_line(capsys, ["fk", 0, 0, 0, 0, 30, 0, "--robot", r], "key 'payload.mass_kg': expected a number")
    assert "y" * 61 not in line


def test_a_file_name_with_a_newline_stays_one_line(capsys, tmp_path):
    p = tmp_path / "bad\nname\u2028.csv"
    line = _one_line(capsys, ["identify", p], "bad\\nname\\u2028.csv")
    assert "\n" not in line
    d = tmp_path / "new\nfolder"
    d.mkdir()
    shutil.copy(DEFAULT_ROBOT_YAML, d / "r.yaml")
    (d / "r.yaml").write_text(ROBOT.replace("  mass_kg: 40.0\n", "  mass_kg: 40.0\n  mass_kg: 4.0\n"))
    _one_line(capsys, ["fk", 0, 0, 0, 0, 30, 0, "--robot", d / "r.yaml"], "new\\nfolder/r.yaml:", "duplicated key")


def test_no_shipped_file_uses_anchors_or_aliases():
    """The refusal costs nothing: no project file needs them (and every one still loads)."""
    from robstiff_drake.user_files import load_yaml

    files = [p for d in ("models", "diagrams", "tests/data") for p in (ROOT / d).glob("*.yaml")]
    assert len(files) >= 15
    for p in files:
        load_yaml(p.read_text(), p)


def test_time_to_refuse_a_bomb_does_not_grow_with_its_levels(tmp_path):
    """The refusal comes at the first anchor: 3 levels or 30, the same time."""
    from robstiff_drake.user_files import UserFileError, load_yaml

    times = []
    for levels in (3, 30):
        t0 = time.perf_counter()
        with pytest.raises(UserFileError, match="anchors and aliases"):
            load_yaml(f"a: {bomb(levels)}\n", "b.yaml")
        times.append(time.perf_counter() - t0)
    assert max(times) < 0.5, times


@pytest.mark.parametrize("char", ["\x1b", "\x00", "\x07", "\x7f"])
def test_a_raw_control_character_is_one_line_with_its_place(capsys, tmp_path, char):
    """A raw control byte in a YAML file (an escape sequence pasted from a
    terminal) was a PyYAML traceback: it is one line naming the file, line,
    column and character, in a robot file and a scenario alike."""
    r = tmp_path / "r.yaml"
    r.write_text(ROBOT.replace("name: irb6400", f"name: irb{char}6400", 1), encoding="utf-8")
    line_no = ROBOT.splitlines().index("name: irb6400") + 1
    _one_line(capsys, ["fk", 0, 0, 0, 0, 30, 0, "--robot", r], f"{r}:{line_no}: column 10: character U+{ord(char):04X}")
    s = tmp_path / "s.yaml"
    s.write_text(SHORT.replace("name: short_block", f'name: "a{char}b"', 1), encoding="utf-8")
    _one_line(capsys, ["simulate", s, "--out", tmp_path / "o"], f"{s}:", f"character U+{ord(char):04X}")
    assert not (tmp_path / "o").exists()
