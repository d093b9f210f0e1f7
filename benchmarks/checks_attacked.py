"""The two checks of a stream `compensate` hears, attacked (docs/real_cell.md, 'The two checks, attacked'): the
sensor's silences recurring soon after its records' return (cell/sensor_checks.py) over the loop with records at
their own arrival times (tests/timed_sensor_loop.py), and the controller's clock summed against its sequence
(cell/session.py) over scripted stamps.  One line a case: the fault or none, when, what the correction did.
Fixed seeds; no timing.  About two minutes.  Usage: python benchmarks/checks_attacked.py [sensor|clock]"""

import os
import sys

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "tests"))
from timed_sensor_loop import T, drive, jittered, plain, summary  # noqa: E402

from robstiff_drake.cell.session import SessionClock  # noqa: E402
from robstiff_drake.cell.session_faults import CLEAR_MESSAGES  # noqa: E402


def _dropped(t, spans):
    keep = np.ones(t.size, bool)
    for a, b in spans:
        keep &= ~((t >= a) & (t < b))
    return t[keep]


def _stalled(n, spans):
    """n messages at 4 ms; those due within a span [a, b) s read at b in one burst (this PC stalled)."""
    out, held = [], []
    for k in range(n):
        t = k * T
        s = [b for a, b in spans if a <= t < b]
        if s:
            held.append((k + 1, round(k * 4), s[0]))
            continue
        out.append(held + [(k + 1, round(k * 4), t)])
        held = []
    return out


def sensor_cases():
    n = 1500  # 6 s at 4 ms
    end = n * T + 0.1
    khz = np.arange(-0.05, end, 1e-3)
    stall = [(0.5 + 0.1 * i, 0.54 + 0.1 * i) for i in range(3)]
    at_stall_end = khz.copy()
    for a, b in stall:
        at_stall_end = np.where((at_stall_end >= a) & (at_stall_end < b), b, at_stall_end)
    bunched = (lambda k: (k + k % 2) * T)
    restart = plain(750) + [[]] * 5 + [[(k + 1, k * 4, 3.02 + k * T)] for k in range(750)]
    pairs = (lambda gap: np.sort(np.r_[np.arange(-0.05, end, gap), np.arange(-0.05, end, gap) + 0.001]))
    flaky = (lambda on: _dropped(khz, [(0.3 + (0.03 + on) * i, 0.33 + (0.03 + on) * i) for i in range(200)]))
    every32 = (np.arange(khz.size) % 32 != 0) & (khz > 0.5)
    every16 = (np.arange(khz.size) % 16 != 0) & (khz > 0.5)
    yield "honest", "1000 Hz, EGM 4 ms", plain(n), khz, {}
    yield "honest", "1000 Hz, EGM bunched 0/8 ms", plain(n, arrive=bunched), khz, {}
    yield "honest", "7000 Hz (--sensor-rate-hz 7000), EGM bunched", plain(n, arrive=bunched), \
        np.arange(-0.05, end, 1 / 7000), {"sensor_rate_hz": 7000}
    yield "honest", "1000 Hz, RSI 12 ms IPO bunched 0/24 ms", \
        plain(500, period_s=0.012, arrive=lambda k: (k + k % 2) * 0.012), khz, {"period_s": 0.012}
    for seed in range(3):
        yield "honest", f"100 Hz +-1 period (seed {seed}), 60 s", plain(15000), \
            jittered(100.0, 1.0, 60.0, seed), {"sensor_rate_hz": 100}
    yield "honest", "125 Hz +-1 period, 60 s", plain(15000), jittered(125.0, 1.0, 60.0, 0), {"sensor_rate_hz": 125}
    yield "honest", "125 Hz +-1 period, Stream Motion 8 ms, 20 s", plain(2500, period_s=0.008), \
        jittered(125.0, 1.0, 20.0, 0), {"sensor_rate_hz": 125, "period_s": 0.008}
    yield "honest", "100 Hz +-1 period, RSI 12 ms, 20 s", plain(1666, period_s=0.012), \
        jittered(100.0, 1.0, 20.0, 0), {"sensor_rate_hz": 100, "period_s": 0.012}
    yield "honest", "two 30 ms dropouts 0.1 s apart", plain(n), _dropped(khz, [(0.5, 0.53), (0.6, 0.63)]), {}
    yield "honest", "three 30 ms dropouts 0.1 s apart", plain(n), \
        _dropped(khz, [(0.5, 0.53), (0.6, 0.63), (0.7, 0.73)]), {}
    yield "honest", "this PC stalled 40 ms, then a burst", _stalled(n, stall[:1]), \
        np.where((khz >= 0.5) & (khz < 0.54), 0.54, khz), {}
    yield "honest", "this PC stalled 40 ms three times, 0.1 s apart", _stalled(n, stall), at_stall_end, {}
    yield "honest", "the controller restarted (silent 20 ms, from 1 again)", restart, khz, {}
    yield "fault", "1 record / 3 messages (+2 ms), 10 ms timeout, 1000 Hz configured", plain(n), \
        np.arange(-0.05, end, 3 * T) + 0.002, {"sensor_timeout_s": 0.01}
    yield "fault", "1 record / 3 messages (+2 ms), 10 ms timeout, 125 Hz configured", plain(n), \
        np.arange(-0.05, end, 3 * T) + 0.002, {"sensor_timeout_s": 0.01, "sensor_rate_hz": 125}
    yield "fault", "31 Hz, 1000 Hz configured", plain(n), np.arange(-0.05, end, 0.032), {}
    yield "fault", "45 Hz, 100 Hz configured", plain(n), np.arange(-0.05, end, 1 / 45), {"sensor_rate_hz": 100}
    yield "fault", "pairs every 25 ms (80 Hz), 100 Hz configured", plain(n), pairs(0.025), {"sensor_rate_hz": 100}
    yield "fault", "pairs every 30 ms (67 Hz), 100 Hz configured", plain(n), pairs(0.03), {"sensor_rate_hz": 100}
    yield "fault", "1000 Hz in bursts every 30 ms", plain(n), np.ceil(khz / 0.03) * 0.03, {}
    for on in (0.03, 0.05, 0.08, 0.1):
        yield "fault", f"flaky link: 30 ms off, {on * 1e3:.0f} ms on", plain(n), flaky(on), {}
    yield "fault", "1000 Hz, one valid record in 32 (the rest NaN)", plain(n), khz, {"invalid": every32}
    yield "fault", "1000 Hz, one valid record in 16 (the rest NaN)", plain(n), khz, {"invalid": every16}


def _clock_run(period_ms, stamps):
    c = SessionClock(period_ms * 1e-3)
    vs, t, ref_off, ahead, behind = [], 0.0, 0.0, 0.0, 0.0
    for i, tm in enumerate(stamps):
        v, dt = c.accept(i + 1, int(tm) & 0xFFFFFFFF)
        vs.append(v)
        t += dt
        ref_off = max(ref_off, abs(t - i * period_ms * 1e-3))
        slower = min(i * period_ms, float(stamps[i]) - float(stamps[0])) * 1e-3  # (cell/session.py ``_pace``)
        ahead, behind = max(ahead, t - slower), max(behind, slower - t)
    faults = [i for i, v in enumerate(vs) if v != "ok"]
    # (the reference's time against the slower of the sequence's and the clock's elapsed: never ahead of it)
    pace = f" (of the slower of it and the clock's: {ahead * 1e3:.2f} ms ahead, {behind * 1e3:.2f} ms behind at most)"
    if not faults:
        return f"no fault; the reference within {ref_off * 1e3:.2f} ms of the sequence's time" + pace
    clears, run = 0, 0
    for v in vs[faults[0]:] + ["clock"]:
        if v == "ok":
            run += 1
            continue
        clears, run = clears + (run >= CLEAR_MESSAGES), 0
    return (f"{len(faults)} fault messages, the first at {faults[0]}; the fault cleared {clears} times; the reference "
            f"within {ref_off * 1e3:.2f} ms of the sequence's time" + pace)


def clock_cases():
    n = 15000  # a minute at 4 ms
    k = np.arange(n)
    rng = np.random.default_rng(3)
    for p in (4, 8, 12):
        yield "honest", f"{p} ms, stamps late U(0,2) ms", p, np.round(k * p + rng.uniform(0, 2, n))
        yield "honest", f"{p} ms, stamps U(-1,1) ms", p, np.round(1000 + k * p + rng.uniform(-1, 1, n))
        yield "honest", f"{p} ms, stamps late U(0,3) ms", p, np.round(k * p + rng.uniform(0, 3, n))
        t64 = np.cumsum(np.full(n, p / 1000.0)) - p / 1000.0
        yield "honest", f"{p} ms, a float64 sum of s, truncated to ms", p, np.floor(t64 * 1000)
        acc, t32 = np.float32(1000.0), np.empty(n)
        for i in range(n):
            t32[i], acc = acc, np.float32(acc + np.float32(p / 1000.0))
        yield "limit", f"{p} ms, a float32 sum of s from 1000 s of uptime, truncated", p, np.floor(t32 * 1000)
    hour = 900_000
    kh = np.arange(hour)
    for ppm in (100, 500, 900):
        yield "honest", f"an hour, {ppm} ppm fast, stamps late U(0,2) ms", 4, \
            np.round(kh * 4 * (1 + ppm * 1e-6) + rng.uniform(0, 2, hour))
    for pace in (6.0, 4.5, 3.6, 4.1, 4.03, 4.01, 3.97):
        yield "fault", f"{pace} ms a 4 ms message", 4, np.round(k * pace)
    kq = np.arange(hour + 2000)
    yield "fault", "an hour honest, then 4.5 ms a 4 ms message from message 900000", 4, \
        np.round(np.where(kq < hour, kq * 4.0, hour * 4.0 + (kq - hour) * 4.5))
    late = np.round(rng.uniform(0, 1, n))
    at = np.arange(500, n - 2, 1000)
    late[at], late[at + 1] = 4, np.maximum(late[at + 1], 1)
    yield "step", "every 1000th stamp 4 ms late, the next 1 ms (each a step's fault, not the drift's)", 4, k * 4 + late


def rsi_cases():
    """RSI's IPOC through RsiLink.decode (sequence IPOC / period, clock the IPOC) into the session's check."""
    n = 3000
    k = np.arange(n)
    for p in (4, 12):
        yield f"RSI {p} ms, the IPOC from an odd start", p, 1_000_003 + k * p, k * p * 1e-3
        yield f"RSI {p} ms, restarted after 200 ms silent (a new IPOC epoch)", p, \
            np.r_[1_000_003 + k[:1500] * p, 50_000_001 + k[:1500] * p], \
            np.r_[k[:1500] * p * 1e-3, 1500 * p * 1e-3 + 0.2 + k[:1500] * p * 1e-3]
    yield "RSI 12 ms IPO read with --period-ms 4", 4, 1_000_000 + k * 12, k * 12e-3
    yield "RSI 4 ms, an IPOC that jitters 0-2 ms", 4, \
        1_000_000 + k * 4 + np.random.default_rng(0).integers(0, 3, n), k * 4e-3
    jitter = np.random.default_rng(0).integers(0, 3, n)
    jitter[0] = 0  # (the session's grid from a message at the jitter's low end)
    yield "RSI 4 ms, an IPOC that jitters 0-2 ms, its first at 0", 4, 1_000_000 + k * 4 + jitter, k * 4e-3
    for p in (4, 12):  # (an honest KRC whose IPOC is half a cycle off the grid 0, T, 2T..)
        yield f"RSI {p} ms, the IPOC half a cycle off the grid", p, 1_000_000 + p // 2 - 1_000_000 % p + k * p, \
            k * p * 1e-3
    yield "RSI 4 ms read with --period-ms 12", 12, 1_000_000 + k * 4, k * 4e-3


def _rsi_run(period_ms, ipocs, arrivals):
    from collections import Counter

    from robstiff_drake.cell.rsi import RsiLink
    from robstiff_drake.cell.rsi_codec import encode_rob

    link, c, q = RsiLink(0, ("127.0.0.1", None), period_ms * 1e-3), SessionClock(period_ms * 1e-3), [0.0] * 6
    got = Counter()
    try:
        for ip, t in zip(ipocs, arrivals):
            link.arrival_s = float(t)
            m = link.decode(encode_rob(int(ip), q, q))
            got[c.accept(m.seq, m.tm_ms)[0]] += 1
            got["new session"] += bool(m.extra.get("new_session"))
    finally:
        link.close()
    return ", ".join(f"{v} {name}" for name, v in sorted(got.items()) if v)


def main(which=None):
    if which in (None, "sensor"):
        from robstiff_drake.model.robot import load_robot

        robot = load_robot()
        for kind, name, msgs, rec, settings in sensor_cases():
            loop, corr = drive(robot, msgs, rec, **settings)
            print(f"sensor {kind}: " + summary(loop, corr, name), flush=True)
    if which in (None, "clock"):
        for kind, name, period_ms, stamps in clock_cases():
            print(f"clock {kind}: [{name}] {_clock_run(period_ms, stamps)}", flush=True)
        for name, period_ms, ipocs, arrivals in rsi_cases():
            print(f"clock RSI: [{name}] {_rsi_run(period_ms, ipocs, arrivals)}", flush=True)


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else None)
