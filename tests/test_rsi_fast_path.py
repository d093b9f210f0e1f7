"""RSI's fast paths read what the XML parser reads, or leave it to it.

The controller's datagrams: a layout learnt (cell/rsi_layout.py) from one
the parser accepted reads a datagram only when the parser would read the
same values from it; the PC's answers: the read-back of the answer's own
bytes (the pose the controller will command) matches the parser's.  Fuzzed
(fixed seeds) and hostile inputs: every input the fast path reads, the full
parser reads identically; every input the parser refuses, the link still
refuses (MessageError: dropped and counted)."""

import numpy as np
import pytest

from robstiff_drake.cell import rsi
from robstiff_drake.cell.link import MessageError
from robstiff_drake.cell.rsi_layout import RobLayout

Q0 = [0.0, 7.008, 29.517, 0.0, 53.476, 0.0]

# a KRC4's datagram as RSI_EthernetConfig.xml's SEND section may make it
# (ROS-Industrial's ros_rsi_ethernet.xml: RIst, RSol, AIPos, ASPos, Delay,
# digital inputs, IPOC; CR-free newlines, single and double quotes)
KRC = (b"<Rob Type=\"KUKA\">\n<RIst X=\"445.0\" Y=\"0.0\" Z=\"890.0\" A=\"180.0\" B=\"0.0\" C=\"180.0\"/>\n"
       b"<RSol X='445.0' Y='0.0' Z='890.0' A='180.0' B='0.0' C='180.0'/>\n"
       b"<AIPos A1=\"0.0\" A2=\"-90.0\" A3=\"90.0\" A4=\"0.0\" A5=\"90.0\" A6=\"0.0\"/>\n"
       b"<ASPos A1=\"0.0\" A2=\"-90.0\" A3=\"90.0\" A4=\"0.0\" A5=\"90.0\" A6=\"0.0\"/>\n"
       b"<Delay D=\"0\"/>\n<Digin>0</Digin>\n<IPOC>4208236</IPOC>\n</Rob>")


def full(data, kind="Rob"):
    """The XML parser's reading, or the MessageError's text."""
    try:
        if kind == "Rob":
            return rsi.decode_rob(data)
        root = rsi._parse(data, "Sen")
        return rsi._ipoc(root), rsi._axes(root, "AK")
    except MessageError as e:
        return f"error: {e}"


def layouts():
    base = [rsi.encode_rob(1_000_000, Q0, Q0), KRC, KRC.replace(b"<ASPos", b"<Other").replace(b"</ASPos", b"</Other"),
            KRC.replace(b"\n", b"\r\n").replace(b"<IPOC>", b"<IPOC>\r\n ")]
    out = []
    for data in base:
        layout = RobLayout.learn(data, "Rob", ("AIPos", "ASPos"), rsi.AXES, rsi.decode_rob(data))
        assert layout is not None and layout.read(data) == tuple(rsi.decode_rob(data))
        out.append((data, layout))
    return out


HOSTILE = [
    (b'A1="0.0"', b'A1="0.0" A1="1.0"'),  # a duplicate attribute
    (b'A1="0.0"', b'A1="&#49;"'), (b'A1="0.0"', b'A1="&amp;"'),  # references
    (b'A1="0.0"', b'A1="\t1.0"'), (b'A1="0.0"', b'A1="1.0\n"'), (b'A1="0.0"', b'A1="\r1"'),  # normalised by XML
    (b'A1="0.0"', b'A1="nan"'), (b'A1="0.0"', b'A1="inf"'), (b'A1="0.0"', b'A1="1_0"'), (b'A1="0.0"', b'A1=""'),
    (b'A1="0.0"', "A1=\"\u0661\"".encode()), (b'A1="0.0"', b'A1="1e999"'), (b'A1="0.0"', b'A1="0x1"'),
    (b'A1="0.0"', b'A1="1.0" xmlns="urn:x"'), (b'A1="0.0"', b'A1="1.0" x:A1="2"'), (b'A1="0.0"', b"A1='1'"),
    (b"<AIPos", b"<AIPos><AIPos"), (b"<AIPos", b"<!-- c --><AIPos"), (b"<AIPos", b"<?pi x?><AIPos"),
    (b"<AIPos", b"<![CDATA[x]]><AIPos"), (b"<Rob", b"<?xml version='1.0'?><Rob"), (b"<Rob", b"\xef\xbb\xbf<Rob"),
    (b"</IPOC>", b"</IPOCX>"), (b"</IPOC>", b"</IPOC >"), (b"<IPOC>", b"<IPOC> "), (b"<IPOC>", b"<IPOC>-"),
    (b"<IPOC>", b"<IPOC>\xd9\xa1"), (b"<IPOC>", b"<IPOC>" + b"9" * 19), (b"<IPOC>", b"<IPOC>" + b"9" * 20),
    (b"<IPOC>", b"<IPOC>&#48;"), (b"<IPOC>", b"<IPOC><x/>"), (b"<IPOC>", b"<IPOC>\r\n"),
    (b"</Rob>", b"</Rob><Rob/>"), (b"</Rob>", b"</Rob>x"), (b"</Rob>", b""), (b"<Rob", b"<Sen"),
    (b"/>", b">"), (b"/>", b"//>"), (b'"', b"'"), (b"A2", b"A1"), (b"A6", b"A7"), (b"Delay", b"Delay\x00"),
    (b"<Rob", b"<Rob>" + b"x" * 5000), (b"<Rob", b" \n<Rob"), (b"</Rob>", b"</Rob>\n"),
]


@pytest.mark.parametrize("old,new", HOSTILE)
def test_hostile_datagrams_read_as_the_parser_reads_them(old, new):
    for data, layout in layouts():
        bad = data.replace(old, new, 1)
        got = layout.read(bad) if len(bad) <= rsi.MAX_BYTES else None
        if got is not None:
            assert repr(got) == repr(tuple(full(bad))), bad
        link = rsi.RsiLink(0, ("127.0.0.1", None), 0.004)
        try:
            link.decode(data)  # learns the layout
            want = full(bad)
            if isinstance(want, str):
                with pytest.raises(MessageError):
                    link._decode_rob(bad)
            else:
                assert repr(tuple(link._decode_rob(bad))) == repr(tuple(want))
        finally:
            link.close()


def test_fuzzed_datagrams_read_as_the_parser_reads_them():
    """Random byte edits (fixed seed) of the learnt messages and new values:
    whatever the layout reads, the parser reads the same; many are read."""
    rng = np.random.default_rng(20261128)
    alphabet = b'0123456789.-+eE "\'<>/=&;#xX \t\n\rAIPosnaif_\x00\xff:'
    read = 0
    for data, layout in layouts():
        for _ in range(1500):
            b = bytearray(data)
            for _ in range(rng.integers(1, 4)):
                i = int(rng.integers(0, len(b)))
                op = rng.integers(0, 3)
                c = alphabet[int(rng.integers(0, len(alphabet)))]
                if op == 0:
                    b[i] = c
                elif op == 1:
                    b.insert(i, c)
                else:
                    del b[i]
            bad = bytes(b)
            got = layout.read(bad)
            if got is not None:
                read += 1
                assert repr(got) == repr(tuple(full(bad))), bad
        for _ in range(300):  # new values in the learnt layout: all read, all the parser's
            q = rng.normal(0.0, 100.0, 12) * 10.0 ** rng.integers(-8, 8, 12)
            new = data
            for j, v in enumerate(q):
                tag = b"AIPos" if j < 6 else b"ASPos"
                at = new.find(b"A%d=" % (j % 6 + 1), new.find(b"<" + tag))
                if new.find(b"<" + tag) < 0:
                    continue
                end = new.index(new[at + 3:at + 4], at + 4)
                new = new[:at + 4] + repr(float(v)).encode() + new[end:]
            got = layout.read(new)
            assert got is not None and repr(got) == repr(tuple(full(new)))
    assert read > 100  # the fuzz reaches the fast path, not only the fallback


def test_the_answer_read_back_is_the_parsers():
    """The PC's answer's bytes read back (the pose the controller will
    command) as the XML parser reads them: finite, huge, tiny, negative
    zero and non-finite corrections (these through the parser), and edits."""
    rng = np.random.default_rng(7)
    values = [0.0, -0.0, 1e-7, -5e-7, 123456.7890125, -1e300, 1e17, float("nan"), float("inf"), -float("inf")]
    for k in range(400):
        ak = list(rng.choice(values, 6)) if k % 2 else list(rng.normal(0.0, 1.0, 6) * 10.0 ** rng.integers(-9, 9))
        data = rsi.encode_sen(int(rng.integers(0, 2**62)), ak)
        assert repr(rsi.decode_sen(data)) == repr(full(data, "Sen"))
        bad = data.replace(b'A3="', b'A3=" ' if k % 3 else b'A3="&#x31;', 1)
        want = full(bad, "Sen")
        if isinstance(want, str):
            with pytest.raises(MessageError):
                rsi.decode_sen(bad)
        else:
            assert repr(rsi.decode_sen(bad)) == repr(want)
    with pytest.raises(MessageError):
        rsi.decode_sen(rsi.encode_sen(5, Q0).replace(b"A2=", b"A1="))  # a duplicate attribute


def test_the_layout_is_learnt_only_from_simple_documents():
    for data in (KRC.replace(b"<Digin>0", b"<Digin>&amp;0"), KRC.replace(b"<Rob", b"<?xml version='1.0'?><Rob"),
                 KRC.replace(b"<Digin>0", b"<Digin><x/>0"), KRC.replace(b"Y=\"0.0\"", b"xmlY=\"0.0\"", 1)):
        decoded = rsi.decode_rob(data)
        assert RobLayout.learn(data, "Rob", ("AIPos", "ASPos"), rsi.AXES, decoded) is None
