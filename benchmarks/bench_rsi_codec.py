"""Benchmark: KUKA RSI's XML per message, the candidates side by side in one
run (issue 32): decoding a controller's <Rob> datagram, encoding the PC's
<Sen> answer and reading that answer back as the controller will read it
(cell/rsi.py, cell/rsi_layout.py).  Microseconds per call, median and p99
of single calls (time.perf_counter_ns around each call; the timer's own
cost, an empty call, printed first as the reference), on the tests' KRC4
datagram (tests/test_rsi_fast_path.py's KRC, 339 bytes) and on a fuller
one of about 700 bytes (tests/test_rsi_equivalence.py's REALISTIC: KRC
plus the external axes, the motor currents and realistic values).

Decoding, every candidate reading A1..A6 of AIPos and ASPos and the IPOC:
  ET.fromstring          the reference (rsi.decode_rob: ElementTree's tree, find, float)
  ET.XMLPullParser       feed + close, the same look-ups
  expat, handlers        xml.parsers.expat (ElementTree's own parser) called directly, a start-element handler
                         filling a dict (no tree), a new parser per datagram
  expat, reused          one parser fed an endless outer document, each datagram a fragment of it: measured for the
                         figure only, NOT SAFE (expat cannot be reset: an error, a declaration, an unclosed element of
                         one datagram carries over to the next), not taken
  lxml                   only if installed (it is not a dependency: not added for this)
  learnt layout          the link's hot path (RsiLink._decode_rob: rsi_layout's whole-match expression, then float)
  link.decode            the link's whole decode (the layout, the IPOC's session and wrap checks, the Message)
Encoding and read-back (six corrections, deg):
  ET build + tostring    ElementTree's Element/SubElement
  template %             rsi.encode_sen ("%.6f" into a precompiled template)
  read-back, ET          the reference parse of the answer's bytes
  read-back, regex       rsi.decode_sen (a whole match of the template, then float)
  check from the values  the strings "%.6f" wrote, float() of each: no read of the bytes (not taken: the bytes'
                         read-back also catches a fault of the template, e.g. two axes swapped)
  link encode+read-back  RsiLink.encode + RsiLink.commanded_deg, as the loop calls them
No target: figures only (the per-message target is bench_compensate.py's).
Each candidate is timed back to back (hot caches) and spaced (a sleep
between calls, as the loop calls it once a message: caches partly cold;
the loop's in-process breakdown sees the latter).
Run: python3 benchmarks/bench_rsi_codec.py [--calls N]
"""

import argparse
import math
import os
import statistics
import sys
import time
import xml.etree.ElementTree as ET
import xml.parsers.expat as expat

sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "tests"))
from test_rsi_equivalence import REALISTIC  # noqa: E402
from test_rsi_fast_path import KRC  # noqa: E402

from robstiff_drake.cell import rsi  # noqa: E402


SPACING_S = 0.001  # between the spaced calls (the loop's messages come every 4 ms; 1 ms keeps the run short)
AK = [0.012345, -0.098765, 0.5, -0.000123, 1.234567, -0.4]


def _expat_decode(data):
    first = {}

    def start(name, attrs):
        first.setdefault(name, attrs)

    texts = []
    p = expat.ParserCreate()
    p.StartElementHandler = start
    p.CharacterDataHandler = texts.append  # (the IPOC's text, and the newlines between elements)
    p.Parse(data, True)
    ai, asp = first["AIPos"], first["ASPos"]
    return [float(ai[a]) for a in rsi.AXES], [float(asp[a]) for a in rsi.AXES]


def _pull_decode(data):
    p = ET.XMLPullParser(("end",))
    p.feed(data)
    p.close()
    root = None
    for _, root in p.read_events():
        pass
    return rsi._ipoc(root), rsi._axes(root, "AIPos"), rsi._axes(root, "ASPos")


class _ReusedExpat:
    """NOT SAFE (module docstring): the figure of a parser not created per datagram."""

    def __init__(self):
        self.first = {}
        self.p = expat.ParserCreate()
        self.p.StartElementHandler = lambda name, attrs: self.first.setdefault(name, attrs)
        self.p.Parse(b"<stream>", False)

    def __call__(self, data):
        self.first = {}
        self.p.Parse(data, False)
        ai, asp = self.first["AIPos"], self.first["ASPos"]
        return [float(ai[a]) for a in rsi.AXES], [float(asp[a]) for a in rsi.AXES]


def _et_encode(ipoc, ak):
    root = ET.Element("Sen", Type="ImFree")
    ET.SubElement(root, "EStr").text = "robstiff"
    ET.SubElement(root, "AK", {a: "%.6f" % v for a, v in zip(rsi.AXES, ak)})
    ET.SubElement(root, "IPOC").text = str(int(ipoc))
    return ET.tostring(root)


def _from_values(ipoc, ak):
    """The answer and its corrections read from the strings formatted, not
    from the answer's bytes (a candidate, not taken: the bytes' read-back
    also catches a template's fault, e.g. two axes swapped)."""
    s = ["%.6f" % v for v in ak]
    back = list(map(float, s))
    if not all(map(math.isfinite, back)):
        raise ValueError("not finite")
    return ('<Sen Type="ImFree"><EStr>robstiff</EStr><AK A1="%s" A2="%s" A3="%s" A4="%s" A5="%s" A6="%s" />'
            '<IPOC>%d</IPOC></Sen>' % (*s, ipoc)).encode(), back


def _et_read_back(data):
    root = rsi._parse(data, "Sen")
    return rsi._ipoc(root), rsi._axes(root, "AK")


def _stats_us(t_ns):
    t_ns.sort()
    return statistics.median(t_ns) / 1e3, t_ns[min(len(t_ns) - 1, math.ceil(0.99 * len(t_ns)) - 1)] / 1e3


def per_call_us(fn, calls):
    """(median, p99) us of single calls of ``fn``: back to back (hot: the
    caches hold its code and data), then ``calls // 10`` of them spaced by
    SPACING_S of sleep (as the loop calls it once a message, other work and
    other processes between: the caches partly cold); (hot median, hot p99,
    spaced median, spaced p99)."""
    clock = time.perf_counter_ns
    hot = []
    for _ in range(calls):
        t0 = clock()
        fn()
        hot.append(clock() - t0)
    spaced = []
    for _ in range(max(1, calls // 10)):
        time.sleep(SPACING_S)
        t0 = clock()
        fn()
        spaced.append(clock() - t0)
    return _stats_us(hot) + _stats_us(spaced)


def rows(calls):
    out = [("timer (an empty call)", "-", per_call_us(lambda: None, calls))]
    for label, data in (("KRC", KRC), ("realistic", REALISTIC)):
        name = f"{label} {len(data)} B"
        link = rsi.RsiLink(0, ("127.0.0.1", None), 0.004)
        try:
            link.decode(data)  # learns the layout
            assert link._layout is not None and link._decode_rob(data) == rsi.decode_rob(data)
            ipoc = int(data[data.index(b"<IPOC>") + 6:data.index(b"</IPOC>")])
            seq = [data.replace(b"<IPOC>%d<" % ipoc, b"<IPOC>%d<" % (ipoc + 4 * k))
                   for k in range(1, calls + calls // 10 + 2)]  # (link.decode's datagrams: the IPOC goes on)
            it = iter(seq)
            reused = _ReusedExpat()
            out += [("decode: ET.fromstring (the reference)", name, per_call_us(lambda: rsi.decode_rob(data), calls)),
                    ("decode: ET.XMLPullParser", name, per_call_us(lambda: _pull_decode(data), calls)),
                    ("decode: expat, handlers, no tree", name, per_call_us(lambda: _expat_decode(data), calls)),
                    ("decode: expat reused (NOT SAFE)", name, per_call_us(lambda: reused(data), calls))]
            try:
                from lxml import etree as lx  # noqa: F401

                out.append(("decode: lxml", name, per_call_us(lambda: lx.fromstring(data).find("AIPos"), calls)))
            except ImportError:
                out.append(("decode: lxml (not installed)", name, None))
            out += [("decode: learnt layout (the link's)", name, per_call_us(lambda: link._decode_rob(data), calls)),
                    ("decode: link.decode (layout + session)", name, per_call_us(lambda: link.decode(next(it)), calls))]
        finally:
            link.close()
    link = rsi.RsiLink(0, ("127.0.0.1", None), 0.004)
    try:
        msg = link.decode(rsi.encode_rob(1_000_000, [0.0] * 6, [0.0] * 6))
        targets = list(AK)
        answer = rsi.encode_sen(1_000_000, AK)
        assert _et_encode(1_000_000, AK).replace(b" />", b"/>") == answer.replace(b" />", b"/>")
        name = f"<Sen> {len(answer)} B"
        out += [("encode: ET build + tostring", name, per_call_us(lambda: _et_encode(1_000_000, AK), calls)),
                ("encode: template % (the link's)", name, per_call_us(lambda: rsi.encode_sen(1_000_000, AK), calls)),
                ("read-back: ET.fromstring (the reference)", name, per_call_us(lambda: _et_read_back(answer), calls)),
                ("read-back: whole-match regex (the link's)", name, per_call_us(lambda: rsi.decode_sen(answer),
                                                                                  calls)),
                ("encode + check from the values (not taken)", name,
                 per_call_us(lambda: _from_values(1_000_000, AK), calls)),
                ("encode + read-back: the link's", name,
                 per_call_us(lambda: link.commanded_deg(msg, link.encode(msg, targets)), calls))]
    finally:
        link.close()
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--calls", type=int, default=20000, help="calls per candidate (default: 20000)")
    args = ap.parse_args(argv)
    print(f"RSI XML per call (us; load average {os.getloadavg()[0]:.2f}; {args.calls} calls each)")
    print(f"  {'':59s} {'back to back':>17s} {f'spaced {SPACING_S * 1e3:g} ms':>17s}")
    print(f"  {'candidate':44s} {'datagram':14s} {'median':>8s} {'p99':>8s} {'median':>8s} {'p99':>8s}")
    for what, name, fig in rows(args.calls):
        figs = ["-"] * 4 if fig is None else [f"{v:.2f}" for v in fig]
        print(f"  {what:44s} {name:14s} " + " ".join(f"{v:>8s}" for v in figs))
    print(f"  (load average after: {os.getloadavg()[0]:.2f})")


if __name__ == "__main__":
    main()
