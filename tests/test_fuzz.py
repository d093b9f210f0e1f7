"""Property-based tests of the reliability contract (hypothesis, derandomized
so every run tries the same cases): whatever a measurement file, a scenario
file or a numeric option holds, a command ends with exit status 0 and valid
output, or exit status 2 and one line on stderr; never a traceback (an
exception escaping ``main``), and its inputs are never changed.

The cases are mutations of valid files (a cell, a key, a delimiter, an
encoding, a duplicated or dropped line), so most of them reach deep into
the readers rather than failing at the first byte."""

import hashlib
import json
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from robstiff_drake.commands.main import main
from robstiff_drake.diagrams.scenario import Scenario, load_scenario
from robstiff_drake.diagrams.schema import check_object
from robstiff_drake.errors import InputError
from robstiff_drake.identification import synth
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
        elif kind == "value":
            lines[i] = f"{key}: {draw(st.sampled_from(YAML_VALUES))}"
        elif kind == "drop":
            lines[i] = "# dropped"
        elif kind == "dup":
            lines.insert(i, lines[i])
        elif kind == "unknown":
            lines.insert(i, f"{key}x: 1")
        elif kind == "indent":
            lines[i] = " " + lines[i]
    return "\n".join(lines) + "\n"


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
