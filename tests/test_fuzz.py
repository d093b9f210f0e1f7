"""Property-based tests of the reliability contract (hypothesis, derandomized
so every run tries the same cases): whatever a measurement file, a scenario
file, a robot file, a run folder or a numeric option holds, and whatever
output names a file that a scenario names (its program, robot, JSON,
payload), a command ends with exit status 0 and valid output, or exit
status 2 and one line on stderr; never a traceback (an exception escaping
``main``), and its inputs are never changed.  YAML anchors, aliases, small
alias bombs and deep nesting are refused in every user file (the large
bombs run under a memory limit in tests/test_user_yaml.py).

The cases are mutations of valid files (a cell, a key, a delimiter, an
encoding, a duplicated or dropped line), so most of them reach deep into
the readers rather than failing at the first byte."""

import hashlib
import json
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, event, example, given, settings
from hypothesis import strategies as st

from robstiff_drake.commands.main import main
from robstiff_drake.diagrams.scenario import load_scenario
from robstiff_drake.diagrams.scenario_schema import Scenario
from robstiff_drake.diagrams.schema import check_object
from robstiff_drake.errors import InputError
from robstiff_drake.identification.stiffness import synth
from robstiff_drake.model.robot import load_robot

ROOT = Path(__file__).parents[1]
ROBOT = load_robot()
def fuzz(max_examples):
    """Hypothesis settings of these tests: the same cases on every run."""
    return settings(derandomize=True, deadline=None, database=None, max_examples=max_examples,
                    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])

# Values a hand-edited or machine-written cell or YAML value can hold.
EDGE_TEXT = ["", " ", "0", "-0", "1", "-1", "7", "1e308", "-1e308", "1e-320", "inf", "-inf", "nan", "NaN", ".nan",
             "1_000", "١٢", "１２", "0,5", "1.2.3", "abc", "\u00a0", "'", '"', "[", "]", "{", "}", ":", "#", "1e", "+",
             "0x10", "2**40", "true", "null", "~", "3.5", "-720", "720", "99999", "-0.0001"]
cell = st.one_of(st.sampled_from(EDGE_TEXT), st.floats(allow_nan=True, allow_infinity=True).map(repr),
                 st.integers(-10**6, 10**6).map(str), st.text(max_size=6))

_CAMPAIGN = synth.stiffness_csv(synth.stiffness_campaign(ROBOT, n=24, seed=5), robot=ROBOT, noise_mm=0.01, seed=5,
                                force_N=300.0, tool_m=np.zeros(3), how="test")
_PAYLOAD = synth.payload_csv(synth.payload_campaign(ROBOT, n=15, seed=1), noise_N=1.0, noise_Nm=0.1, seed=1,
                             how="test")
_SCENARIO = (ROOT / "tests" / "data" / "short_block.yaml").read_text()


def _contract(capsys, argv, inputs):
    before = {p: hashlib.sha256(Path(p).read_bytes()).hexdigest() for p in inputs}
    code = main([str(a) for a in argv])  # an exception escaping here fails the test: that is a traceback
    out, err = capsys.readouterr()
    event(f"{argv[0]}: exit {code}")
    assert code in (0, 2), (code, err)
    if code == 2:
        lines = err.strip().splitlines()
        assert len(lines) == 1 and "error:" in lines[0], err
    else:
        assert "error:" not in err and "Traceback" not in err, err
    for p, h in before.items():
        assert hashlib.sha256(Path(p).read_bytes()).hexdigest() == h, f"input {p} changed"
    return code, out


@st.composite
def mutated_csv(draw, text):
    lines = text.splitlines()
    body = [i for i, ln in enumerate(lines) if ln and not ln.startswith("#")]
    for _ in range(draw(st.integers(1, 3))):
        kind = draw(st.sampled_from(["cell", "cell", "cell", "drop_line", "dup_line", "drop_cell", "header",
                                     "delimiter", "blank", "truncate"]))
        i = draw(st.sampled_from(body))
        if i >= len(lines):
            continue
        cells = lines[i].split(",")
        j = draw(st.integers(0, len(cells) - 1))
        if kind == "cell":
            cells[j] = draw(cell)
            lines[i] = ",".join(cells)
        elif kind == "drop_line":
            lines[i] = "# dropped"
        elif kind == "dup_line":
            lines.insert(i, lines[i])
        elif kind == "drop_cell":
            lines[i] = ",".join(cells[:j] + cells[j + 1:])
        elif kind == "header":
            hdr = lines[body[0]].split(",")
            hdr[j % len(hdr)] = draw(st.sampled_from(["", "q1", "fzz", "pose", "dx ", "FX", "seq", "x"]))
            lines[body[0]] = ",".join(hdr)
        elif kind == "delimiter":
            d = draw(st.sampled_from([";", "\t", " "]))
            lines = [ln if ln.startswith("#") else ln.replace(",", d) for ln in lines]
        elif kind == "blank":
            lines[i] = ""
        elif kind == "truncate":
            lines = lines[: i + 1]
    text = "\n".join(lines) + "\n"
    enc = draw(st.sampled_from(["utf-8", "utf-8", "utf-8-sig", "utf-16", "latin-1"]))
    return text.encode(enc, errors="replace")


@fuzz(250)
@given(data=mutated_csv(_CAMPAIGN), cmd=st.sampled_from(["identify", "identify --robust", "diagnose"]))
def test_fuzz_stiffness_files(capsys, tmp_path_factory, data, cmd):
    d = tmp_path_factory.mktemp("fz")
    p = d / "c.csv"
    p.write_bytes(data)
    out = d / "o.json"
    code, _ = _contract(capsys, cmd.split() + [p, "--json", out], [p])
    if code == 0:
        json.loads(out.read_text(), parse_constant=lambda t: pytest.fail(f"non-JSON token {t}"))
    else:
        assert not out.exists()


@fuzz(100)
@given(data=mutated_csv(_PAYLOAD))
def test_fuzz_payload_files(capsys, tmp_path_factory, data):
    d = tmp_path_factory.mktemp("fz")
    p = d / "p.csv"
    p.write_bytes(data)
    out = d / "o.json"
    code, _ = _contract(capsys, ["calibrate-payload", p, "--json", out, "--yaml", d / "o.yaml"], [p])
    if code == 0:
        res = json.loads(out.read_text(), parse_constant=lambda t: pytest.fail(f"non-JSON token {t}"))
        assert res["mass_kg"] > 0


YAML_VALUES = ["0", "-1", "1e9", "1e-9", ".nan", ".inf", "-.inf", '"four"', "[]", "[1, 2]", "[1, 2, 3, 4, 5, 6]",
               "{}", "null", "true", "3", "0.5", "1000000", "-0.0", "[.nan, 0, 0]", "[[1, 2, 3]]", "x"]


def _scaled(value, factor):
    """A numeric YAML value scaled (a plausible edit), or None."""
    try:
        return repr(float(value) * factor)
    except ValueError:
        return None


@st.composite
def mutated_scenario(draw, edits=st.integers(1, 2), wild=True):
    lines = _SCENARIO.splitlines()
    keyed = [i for i, ln in enumerate(lines) if ":" in ln and not ln.lstrip().startswith("#")]
    kinds = ["scale", "scale", "value", "value", "drop", "dup", "unknown", "indent"] if wild else ["scale"]
    for _ in range(draw(edits)):
        kind = draw(st.sampled_from(kinds))
        i = draw(st.sampled_from(keyed))
        if i >= len(lines):
            continue
        key, _, value = lines[i].partition(":")
        if kind == "scale":
            new = _scaled(value.strip(), draw(st.sampled_from([0.0, 0.5, 0.9, 1.1, 2.0, 10.0, -1.0])))
            if new is not None:
                lines[i] = f"{key}: {new}"
        else:
            _edit_line(draw, lines, i, kind)
    return "\n".join(lines) + "\n"


def _edit_line(draw, lines, i, kind):
    """A hand edit of a YAML file's keyed line ``i``: another value, the line
    dropped, duplicated, indented, or a misspelt key before it."""
    key = lines[i].partition(":")[0]
    if kind == "value":
        lines[i] = f"{key}: {draw(st.sampled_from(YAML_VALUES))}"
    elif kind == "drop":
        lines[i] = "# dropped"
    elif kind == "dup":
        lines.insert(i, lines[i])
    elif kind == "unknown":
        lines.insert(i, f"{key}x: 1")
    elif kind == "indent":
        lines[i] = " " + lines[i]


@fuzz(400)
@given(text=mutated_scenario())
def test_fuzz_scenario_files(tmp_path_factory, text):
    """Every scenario either loads with every key within its range, or is
    refused with one line naming the file."""
    p = tmp_path_factory.mktemp("fz") / "s.yaml"
    p.write_text(text)
    try:
        sc = load_scenario(p)
        event("loaded")
    except InputError as e:
        event("refused")
        msg = str(e)
        assert "\n" not in msg and msg.startswith(str(p)), msg
        return
    check_object(Scenario, sc, str(p))  # what loaded is within every range


@fuzz(8)
@given(text=mutated_scenario(edits=st.just(1), wild=False))
def test_fuzz_scenario_through_simulate(capsys, tmp_path_factory, text):
    """A few mutated scenarios all the way through `simulate` (seconds each)."""
    d = tmp_path_factory.mktemp("fz")
    p = d / "s.yaml"
    p.write_text(text)
    code, out = _contract(capsys, ["simulate", p, "--compensation", "on", "--json", "-", "--out", d / "run"], [p])
    if code == 0:
        json.loads(out, parse_constant=lambda t: pytest.fail(f"non-JSON token {t}"))


NUMBERS = st.one_of(st.sampled_from(EDGE_TEXT), st.integers(-5, 60).map(str))


def _int(text):
    try:
        return int(text)
    except ValueError:
        return None


# Valid sizes that would make a unit test slow (they are bounded by the
# options' ranges and tried by hand); the fuzz test skips them.
TOO_SLOW = {
    "kg-study": lambda a, b, c: (_int(a) or 0) > 3,
    "plan-poses": lambda a, b, c: (_int(a) or 0) > 12 or (_int(b) or 0) > 30,
    "stiffness-map": lambda a, b, c: (_int(a) or 0) > 9,
    "synth": lambda a, b, c: (_int(a) or 0) > 2000,
}


@fuzz(300)
@given(cmd=st.sampled_from([
    ["stiffness", "{a}", "{b}", "10", "0", "{c}", "0", "--tool", "{a},0,{b}"],
    ["synth", "stiffness", "-", "--n", "{a}", "--loads-per-pose", "{b}", "--seed", "{c}", "--noise-mm", "{b}"],
    ["synth", "payload", "-", "--n", "{a}", "--mass-kg", "{b}", "--seed", "{c}"],
    ["plan-poses", "{a}", "--candidates", "{b}", "--seed", "{c}"],
    ["kg-study", "--grid", "{a}", "--force-N", "{b}", "--payload-kg", "{c}"],
    ["stiffness-map", "--resolution", "{a}", "--force-N", "{b}", "--out", "{out}"],
    ["sweep", "{scen}", "--period-ms", "{a},4", "--cutoff-hz", "{b}", "--delay-steps", "{c}", "--json", "-"],
]), a=NUMBERS, b=NUMBERS, c=NUMBERS)
def test_fuzz_numeric_options(capsys, tmp_path_factory, monkeypatch, cmd, a, b, c):
    from hypothesis import assume

    from robstiff_drake.commands import sweep

    assume(not TOO_SLOW.get(cmd[0], lambda *_: False)(a, b, c))
    # a sweep's runs are simulations (seconds each): what is fuzzed here is
    # everything before them, the options' checks and the scenario's
    monkeypatch.setattr(sweep, "run_sweep", lambda path, combos, **kw: [dict(c, stable=True) for c in combos])
    d = tmp_path_factory.mktemp("fz")
    monkeypatch.chdir(d)
    scen = d / "s.yaml"
    scen.write_text(_SCENARIO)
    argv = [x.format(a=a, b=b, c=c, out=d / "m.png", scen=scen) for x in cmd]
    code, out = _contract(capsys, argv, [scen])
    if code == 0 and argv[-1] == "-" and argv[0] == "sweep":
        json.loads(out, parse_constant=lambda t: pytest.fail(f"non-JSON token {t}"))


# ------------------------------------------------------------------ issue 19
# Inputs named inside other inputs, YAML and JSON that would explode, robot
# files, and run folders with symlinks and other robots' settings.  Every
# case: exit 0 with valid output, or exit 2 with one line; no input changed.

import os  # noqa: E402
import shutil  # noqa: E402

from robstiff_drake.paths import DEFAULT_ROBOT_YAML  # noqa: E402

_CONTOUR = (ROOT / "diagrams" / "contour_with_arcs.yaml").read_text()
_ROBOT = DEFAULT_ROBOT_YAML.read_text()
_STIFFNESS_JSON = json.dumps({"joint_stiffness_Nm_per_rad": [1.5e6, 1.1e6, 8e5, 3e5, 3e5, 2e5]})
_PAYLOAD_YAML = ("payload_calibration:\n  mass_kg: 40.0\n  com_mm: [0, 0, 180]\n  force_bias_N: [3, -2, 5]\n"
                 "  torque_bias_Nm: [0.2, -0.1, 0.05]\n  sensor_mount_rpy_deg: [0, 0, 0]\n")
NAMED = {"toolpath.program": "prog.nc", "robot": "r.yaml", "model.identified_json": "m.json",
         "model.payload_yaml": "pay.yaml"}


def _named_scenario(d):
    """A scenario in ``d`` that names a program, a robot file, an identification JSON and a payload YAML."""
    shutil.copy(ROOT / "diagrams" / "contour_with_arcs.nc", d / "prog.nc")
    (d / "r.yaml").write_text(_ROBOT)
    (d / "m.json").write_text(_STIFFNESS_JSON)
    (d / "pay.yaml").write_text(_PAYLOAD_YAML)
    text = _CONTOUR.replace("program: contour_with_arcs.nc", "program: prog.nc")
    text = text.replace("name: contour_with_arcs", "name: contour_with_arcs\nrobot: r.yaml")
    text = text.replace("controller:", "model:\n  identified_json: m.json\n  payload_yaml: pay.yaml\ncontroller:")
    (d / "s.yaml").write_text(text)
    return d / "s.yaml"


def _refused_one_line(code, err):
    lines = err.strip().splitlines()
    assert code == 2 and len(lines) == 1 and "error:" in lines[0] and len(lines[0]) < 1000, (code, err[:2000])
    return lines[0]


@fuzz(40)
@given(key=st.sampled_from(sorted(NAMED)), how=st.sampled_from(["same", "dot", "updown", "symlink", "hardlink",
                                                                 "parent", "absolute"]),
       cmd=st.sampled_from(["simulate --json", "simulate --replay", "simulate --out", "sim-cell --reference-out",
                            "sim-cell --json", "fk --json"]))
def test_fuzz_scenario_named_inputs(capsys, tmp_path_factory, monkeypatch, key, how, cmd):
    d = tmp_path_factory.mktemp("fz")
    monkeypatch.chdir(d)
    s = _named_scenario(d)
    target = NAMED[key]
    if cmd.startswith("fk"):
        target = NAMED["robot"]
    if how == "symlink":
        os.symlink(target, d / "link")
        out = "link"
    elif how == "hardlink":
        os.link(d / target, d / "hard")
        out = "hard"
    else:
        out = {"same": target, "dot": f"./{target}", "updown": f"sub/../{target}", "parent": ".",
               "absolute": str(d / target)}[how]
    if how == "updown":
        (d / "sub").mkdir()
    if cmd == "simulate --out" and how != "parent":
        out = str(d)  # a folder that holds the input
    before = {p: hashlib.sha256(p.read_bytes()).hexdigest() for p in d.iterdir() if p.is_file()}
    prog, option = cmd.split()
    if prog == "simulate":
        argv = ["simulate", s, option, out] + (["--out", d / "o"] if option != "--out" else [])
    elif prog == "sim-cell":
        argv = ["sim-cell", s, "--egm-to", "127.0.0.1:9", "--netft-port", "9", "--wait-s", "0.1", option, out]
    else:
        argv = ["fk", "0", "0", "0", "0", "30", "0", "--robot", "r.yaml", "--json", out]
    code = main([str(a) for a in argv])
    _, err = capsys.readouterr()
    line = _refused_one_line(code, err)
    event(f"{cmd} {how}")
    expected = ("is a folder; give a file name",) if how == "parent" and option != "--out" else \
        ("input of the command", "cannot replace this folder")
    assert any(e in line for e in expected), line
    assert {p: hashlib.sha256(p.read_bytes()).hexdigest() for p in d.iterdir() if p.is_file()} == before
    assert not (d / "o").exists()


def _nested(depth, kind):
    return (kind[0] * depth) + (kind[1] * depth)


@st.composite
def exploding_text(draw):
    """(file kind, text): a user file with anchors, aliases, a merge key, a
    small alias bomb or deep nesting put in at a keyed line."""
    kind = draw(st.sampled_from(["scenario", "robot", "payload", "json"]))
    if kind == "json":
        depth = draw(st.sampled_from([1, 2, 63, 64, 65, 1000, 100000]))
        return kind, '{"joint_stiffness_Nm_per_rad": ' + _nested(depth, "[]") + "}", depth
    text = {"scenario": _SCENARIO, "robot": _ROBOT, "payload": _PAYLOAD_YAML}[kind]
    lines = text.splitlines()
    keyed = [i for i, ln in enumerate(lines) if ": " in ln and not ln.lstrip().startswith(("#", "-"))]
    i, j = sorted(draw(st.lists(st.sampled_from(keyed), min_size=2, max_size=2, unique=True)))
    what = draw(st.sampled_from(["alias", "merge", "bomb", "anchor", "nest"]))
    key_i, _, value_i = lines[i].partition(": ")
    key_j, _, _ = lines[j].partition(": ")
    depth = 0
    if what == "alias":
        lines[i], lines[j] = f"{key_i}: &v {value_i}", f"{key_j}: *v"
    elif what == "anchor":
        lines[i] = f"{key_i}: &v {value_i}"
    elif what == "merge":
        lines.insert(j + 1, " " * (len(key_j) - len(key_j.lstrip())) + "<<: {x: 1}")
        lines[i] = f"{key_i}: &v {value_i}"
    elif what == "bomb":
        levels = draw(st.integers(2, 4))
        parts = ["&b0 [1, 1, 1]"] + [f"&b{n} [*b{n - 1}, *b{n - 1}, *b{n - 1}]" for n in range(1, levels)]
        lines[i] = f"{key_i}: [{', '.join(parts)}]"
    else:
        depth = draw(st.sampled_from([2, 64, 65, 5000]))
        lines[i] = f"{key_i}: {_nested(depth, draw(st.sampled_from(['[]', '{}'])))}"
    return kind, "\n".join(lines) + "\n", (what, depth)


@fuzz(60)
@given(case=exploding_text())
def test_fuzz_alias_bombs_and_nesting(capsys, tmp_path_factory, case):
    kind, text, what = case
    d = tmp_path_factory.mktemp("fz")
    scen = d / "s.yaml"
    if kind == "scenario":
        scen.write_text(text)
        p, argv = scen, ["simulate", scen, "--compensation", "on", "--out", d / "o"]
    elif kind == "robot":
        p = d / "r.yaml"
        p.write_text(text)
        argv = ["fk", "0", "0", "0", "0", "30", "0", "--robot", p, "--json", d / "o.json"]
    else:
        p = d / ("pay.yaml" if kind == "payload" else "m.json")
        p.write_text(text)
        key = "payload_yaml" if kind == "payload" else "identified_json"
        scen.write_text(_SCENARIO.replace("controller:", f"model:\n  {key}: {p.name}\ncontroller:"))
        argv = ["simulate", scen, "--compensation", "on", "--out", d / "o"]
    event(f"{kind} {what}")
    if kind == "scenario" and what[0] == "nest" and what[1] < 64 or kind == "json" and what in (1,):
        return  # a legal depth with a value of the wrong type: the schema fuzz covers those
    code, _ = _contract(capsys, argv, [p, scen] if scen.exists() else [p])
    assert code == 2  # never a run: every case here is refused
    assert not (d / "o").exists() and not (d / "o.json").exists()


@st.composite
def mutated_robot(draw):
    lines = _ROBOT.splitlines()
    keyed = [i for i, ln in enumerate(lines) if ":" in ln and not ln.lstrip().startswith("#")]
    for _ in range(draw(st.integers(1, 2))):
        i = draw(st.sampled_from(keyed))
        if i >= len(lines):
            continue
        key, _, value = lines[i].partition(":")
        kind = draw(st.sampled_from(["scale", "scale", "units", "value", "drop", "dup", "unknown", "indent"]))
        if kind in ("scale", "units"):
            factor = draw(st.sampled_from([0.0, -1.0, 0.5, 2.0, 10.0, 1e-300, 1e300] if kind == "scale"
                                          else [1e-3, 1e3, np.pi / 180.0]))
            nums = value.strip().strip("[]").split(",")
            try:
                new = [repr(float(v) * factor) for v in nums]
            except ValueError:
                continue
            lines[i] = f"{key}: [{', '.join(new)}]" if "[" in value else f"{key}: {new[0]}"
        else:
            _edit_line(draw, lines, i, kind)
    return "\n".join(lines) + "\n"


@fuzz(150)
@given(text=mutated_robot())
def test_fuzz_robot_files(capsys, tmp_path_factory, text):
    d = tmp_path_factory.mktemp("fz")
    p = d / "r.yaml"
    p.write_text(text)
    out = d / "o.json"
    code, _ = _contract(capsys, ["fk", "0", "0", "0", "0", "30", "0", "--robot", p, "--json", out], [p])
    if code == 0:
        res = json.loads(out.read_text(), parse_constant=lambda t: pytest.fail(f"non-JSON token {t}"))
        event(f"loaded, {len(res.get('warnings', []))} warning(s)")
    else:
        assert not out.exists()


CELL = ["compensator.yaml", "scan.csv", "wrench_log.csv", "joint_log.csv", "RUN_ID"]


@fuzz(14)
@example(kind="robot_file", name="RUN_ID", robot="irb6640", scale=1e-3)
@example(kind="symlink_out", name="compensator.yaml", robot="irb6400", scale=1e-3)
@given(kind=st.sampled_from(["symlink_out", "symlink_in", "robot", "robot_file", "wrench_units", "missing"]),
       name=st.sampled_from(CELL), robot=st.sampled_from(["irb6640", "kr240_r2900", "r2000ic_165f", "irb6400"]),
       scale=st.sampled_from([1e-3, 1e3]))
def test_fuzz_run_folders(capsys, tmp_path_factory, short_run_folder, kind, name, robot, scale):
    d = tmp_path_factory.mktemp("fz")
    run = d / "run"
    shutil.copytree(short_run_folder, run)
    secret = d / "secret.txt"
    secret.write_text("TOP-SECRET,line\n")
    settings = run / "compensator.yaml"
    if kind == "symlink_out":
        (run / name).unlink()
        (run / name).symlink_to(secret)
    elif kind == "symlink_in":
        shutil.move(run / name, run / f"real_{name}")
        (run / name).symlink_to(f"real_{name}")
    elif kind == "robot":
        settings.write_text(settings.read_text().replace("robot: irb6400", f"robot: {robot}"))
    elif kind == "robot_file":
        (d / "mine.yaml").write_text((ROOT / "models" / f"{robot}.yaml").read_text())
        settings.write_text(settings.read_text().replace("robot: irb6400", "robot: ../mine.yaml"))
    elif kind == "wrench_units":
        w = run / "wrench_log.csv"
        w.write_text("\n".join(ln if ln.startswith(("#", "t_s")) else ",".join(
            [c if j == 0 or c == "" else repr(float(c) * scale) for j, c in enumerate(ln.split(","))])
            for ln in w.read_text().splitlines()) + "\n")
    else:
        (run / name).unlink()
    event(kind)
    inputs = [p for p in run.iterdir() if p.is_file()] + [secret]
    code, out = _contract(capsys, ["diagnose-run", run, "--json", d / "rep.json", "--out", d / "diag"], inputs)
    assert "TOP-SECRET" not in out
    same_robot = robot == "irb6400" or kind not in ("robot", "robot_file")
    if code == 0:
        assert kind == "symlink_in" or (kind in ("robot", "robot_file") and same_robot), kind
        json.loads((d / "rep.json").read_text())
    else:
        assert kind != "symlink_in" and not (kind in ("robot", "robot_file") and same_robot), kind
