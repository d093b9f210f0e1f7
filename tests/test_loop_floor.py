"""benchmarks/loop_floor.py, the machine's floor that bench_compensate.py
sets compensate's p99 against: it answers the sender's datagrams and
reports ordered figures (no timing asserted: the machine is shared)."""

import importlib.util
import os

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def _module():
    spec = importlib.util.spec_from_file_location("loop_floor", os.path.join(ROOT, "benchmarks", "loop_floor.py"))
    m = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(m)
    return m


def test_the_floor_answers_and_its_figures_are_ordered():
    m = _module()
    assert m.calibrate(0) == 0 and m.calibrate(50.0) >= 1
    r = m.floor(20.0, 0.6)  # (no CPU, priority or latency request: whatever the test process may do)
    assert r["messages"] >= 10, r
    for key in ("computation_us", "response_us"):
        s = r[key]
        if s is None and key == "response_us":
            continue  # (no kernel receive stamps off Linux)
        assert 0.0 < s["median"] <= s["p99"] <= s["max"], r
    assert r["scheduling"] == "normal scheduling"
