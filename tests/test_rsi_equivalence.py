"""RSI's fast decoders against the reference, on one corpus (issue 32).

The reference is the XML parser's reading (rsi.decode_rob: ElementTree;
the answer's rsi._parse/_ipoc/_axes).  The fast paths are the link's
learnt layout (cell/rsi_layout.py, RsiLink._decode_rob, the parser behind
it) and the answer's whole-match read-back (rsi.decode_sen).  A corpus of
the tests' datagrams and fixed-seed mutations of them (truncation, byte
edits, attribute reorders, whitespace, references and declarations,
duplicate elements and attributes, huge and non-finite numbers, IPOC
problems) goes through both: the same values (repr: -0.0 and nan too) or
the same rejection with the same text."""

import random
import re

import pytest

from robstiff_drake.cell import rsi
from robstiff_drake.cell.link import MessageError
from robstiff_drake.cell.rsi_layout import RobLayout
from test_rsi_fast_path import KRC

Q0 = [0.0, 7.008, 29.517, 0.0, 53.476, 0.0]
# the tests' KRC with realistic values and the elements a KRC4's default SEND section adds (external axes'
# actual and setpoint, motor currents): 658 bytes (benchmarks/bench_rsi_codec.py times it)
REALISTIC = KRC.replace(
    b'A1="0.0" A2="-90.0" A3="90.0" A4="0.0" A5="90.0" A6="0.0"',
    b'A1="-12.345678" A2="-87.654321" A3="91.234567" A4="0.123456" A5="88.765432" A6="-3.210987"').replace(
    b"<Delay", b'<ELPos E1="0.0" E2="0.0" E3="0.0" E4="0.0" E5="0.0" E6="0.0"/>\n'
               b'<ESPos E1="0.0" E2="0.0" E3="0.0" E4="0.0" E5="0.0" E6="0.0"/>\n'
               b'<MACur A1="0.3" A2="-2.1" A3="1.7" A4="0.0" A5="0.4" A6="0.0"/>\n'
               b'<MECur E1="0.0" E2="0.0" E3="0.0" E4="0.0" E5="0.0" E6="0.0"/>\n<Delay')
BASES = [rsi.encode_rob(1_000_000, Q0, Q0), KRC, REALISTIC]
NUMBERS = [b"1e308", b"1e309", b"-1e999", b"1e-400", b"9" * 400, b"nan", b"-inf", b"Infinity", b"+1.5", b"-0",
           b".5", b"5.", b"1_000", b"0x10", b"1e", b"", b" 1", b"\xd9\xa1", b"\xef\xbc\x91", b"1.7976931348623157e308"]
IPOCS = [b"", b"-5", b"+5", b"5 ", b" 5", b"\n5\n", b"9" * 19, b"9" * 20, b"0", b"00000000000000000001",
         b"&#53;", b"5<x/>", b"\xd9\xa1", b"5.0", b"1e3"]
BILLION_LAUGHS = (b'<?xml version="1.0"?><!DOCTYPE Rob [<!ENTITY a "aaaaaaaaaa">'
                  b'<!ENTITY b "&a;&a;&a;&a;&a;&a;&a;&a;&a;&a;">]>')


def reference(data):
    """The parser's reading, or the MessageError's text."""
    try:
        return repr(tuple(rsi.decode_rob(data)))
    except MessageError as e:
        return f"error: {e}"


def fast(link, data):
    """The link's reading (its learnt layout, the parser behind it)."""
    try:
        return repr(tuple(link._decode_rob(data)))
    except MessageError as e:
        return f"error: {e}"


def _values(data):
    """(start, end) of every attribute value in ``data`` (either quote)."""
    return [m.span(2) for m in re.finditer(rb"""=[ \t\r\n]*(["'])([^"'<]*)\1""", data)]


def mutations(data, rng):
    """Fixed-seed edits of one datagram (each a bytes)."""
    out = [data[:rng.randrange(len(data))] for _ in range(20)]  # truncations
    for _ in range(60):  # byte edits: replace, insert, delete
        b = bytearray(data)
        for _ in range(rng.randint(1, 3)):
            i = rng.randrange(len(b))
            c = rng.choice(b'0123456789.-+eE "\'<>/=&;#xX \t\n\rAIPosnaif_\x00\xff\x80:')
            op = rng.randrange(3)
            if op == 0:
                b[i] = c
            elif op == 1:
                b.insert(i, c)
            else:
                del b[i]
        out.append(bytes(b))
    tag = data.index(b"<AIPos") + 1
    head, _, rest = data[tag:].partition(b"/>")
    parts = head.split(b" ")
    for _ in range(5):  # the axes' attributes in another order
        attrs = parts[1:]
        rng.shuffle(attrs)
        out.append(data[:tag] + b" ".join([parts[0], *attrs]) + b"/>" + rest)
    for ws in (b" ", b"\n", b"\t", b"\r\n", b"  \n "):  # whitespace between and inside elements
        out += [data.replace(b"><", b">" + ws + b"<"), data.replace(b"/>", ws + b"/>"),
                data.replace(b'="', ws + b"=" + ws + b'"'), ws + data + ws, data.replace(b"<IPOC>", b"<IPOC>" + ws)]
    spans = _values(data)
    for _ in range(40):  # one value replaced: numbers huge, non-finite, odd; references
        s, e = rng.choice(spans)
        out.append(data[:s] + rng.choice(NUMBERS + [b"&#49;", b"&amp;", b"&a;", b"&#x31;.5"]) + data[e:])
    ipoc = data.index(b"<IPOC>") + 6
    ipoc_end = data.index(b"</IPOC>")
    out += [data[:ipoc] + v + data[ipoc_end:] for v in IPOCS]
    out += [data.replace(b"<IPOC>", b"<IPOC>1</IPOC><IPOC>", 1), data.replace(b"<IPOC>" + data[ipoc:ipoc_end]
                                                                               + b"</IPOC>", b"")]
    for tag in (b"<AIPos", b"<ASPos"):  # duplicate elements (the parser reads the first), duplicate attributes
        if tag in data:
            at = data.index(tag)
            el = data[at:data.index(b">", at) + 1]
            out += [data.replace(el, el + el.replace(b'"', b'"1', 1), 1), data.replace(el, el.replace(b'"', b'"1', 1)
                                                                                   + el, 1),
                    data.replace(el, b"", 1), data.replace(tag + b" A1=", tag + b' A2="0" A1=', 1)]
    out += [BILLION_LAUGHS + data, b"<!-- c -->" + data, data.replace(b"<Rob", b"<Sen").replace(b"</Rob>", b"</Sen>"),
            data.replace(b'Type="KUKA"', b'Type="KUKA" Type="x"'), data.replace(b"<Rob", b"<r:Rob xmlns:r='urn:x'")
            .replace(b"</Rob>", b"</r:Rob>"), data + b"<Rob/>", data.replace(b"</Rob>", b"</Rob"),
            data + b" " * (rsi.MAX_BYTES - len(data) + 1), data.decode().encode("utf-16")]
    return out


def test_the_link_reads_what_the_reference_reads_or_rejects_it_alike():
    rng = random.Random(20261206)
    read_fast = rejected = accepted = 0
    for base in BASES:
        link = rsi.RsiLink(0, ("127.0.0.1", None), 0.004)
        try:
            link.decode(base)
            assert link._layout is not None  # each base is learnt: the fast path is under test
            for bad in mutations(base, rng):
                want = reference(bad)
                assert fast(link, bad) == want, bad
                rejected += want.startswith("error")
                accepted += not want.startswith("error")
                read_fast += link._layout is not None and link._layout.read(bad) is not None
                if link._layout is None or link._layout.read(base) is None:  # (a refused one never unlearns it)
                    link._layout = RobLayout.learn(base, "Rob", ("AIPos", "ASPos"), rsi.AXES, rsi.decode_rob(base))
        finally:
            link.close()
    assert rejected > 200 and accepted > 100 and read_fast > 50, (rejected, accepted, read_fast)


def test_layouts_learnt_from_the_accepted_mutations_read_as_the_reference():
    """A controller that sends a mutated layout (reordered, spaced): the
    layout learnt from it reads it and its value edits as the reference."""
    rng = random.Random(7)
    learnt = 0
    for base in BASES:
        for m in mutations(base, rng):
            if reference(m).startswith("error"):
                continue
            layout = RobLayout.learn(m, "Rob", ("AIPos", "ASPos"), rsi.AXES, rsi.decode_rob(m))
            if layout is None:
                continue
            learnt += 1
            spans = _values(m)
            for _ in range(5 if spans else 0):
                s, e = rng.choice(spans)
                edit = m[:s] + rng.choice(NUMBERS + [repr(rng.uniform(-400, 400)).encode()]) + m[e:]
                got = layout.read(edit)
                if got is not None:
                    assert repr(got) == reference(edit), edit
    assert learnt > 50


@pytest.mark.parametrize("seed", [1, 2])
def test_the_answer_read_back_is_the_reference(seed):
    """decode_sen against the parser: values finite, huge, tiny, -0.0 and
    non-finite, and byte edits of the answers: the same or the same error."""
    rng = random.Random(seed)
    values = [0.0, -0.0, 1e-7, -4e-7, 5e-7, 123456.7890125, -1e300, 1e17, float("nan"), float("inf"), -float("inf")]
    same = 0
    for k in range(300):
        ak = [rng.choice(values) if k % 2 else rng.gauss(0.0, 1.0) * 10.0 ** rng.randint(-9, 9) for _ in range(6)]
        data = rsi.encode_sen(rng.randrange(2**62), ak)
        b = bytearray(data)
        i = rng.randrange(len(b))
        b[i] = rng.choice(b'0123456789.-e "<>/=&#;A \n')
        for d in (data, bytes(b), data[:rng.randrange(len(data))], data.replace(b'A2="', b'A2="&#45;', 1)):
            try:
                want = repr((rsi._ipoc(rsi._parse(d, "Sen")), rsi._axes(rsi._parse(d, "Sen"), "AK")))
            except MessageError as e:
                want = f"error: {e}"
            try:
                got = repr(rsi.decode_sen(d))
            except MessageError as e:
                got = f"error: {e}"
            assert got == want, d
            same += 1
    assert same == 1200
