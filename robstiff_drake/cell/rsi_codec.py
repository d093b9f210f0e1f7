"""KUKA RSI's XML messages (the wire format of cell/rsi.py): the
controller's ``<Rob>`` and the PC's ``<Sen>`` answer, read and written.
The sources of the format are in cell/rsi.py's docstring.  A message is at
most MAX_BYTES; no DTD or entity is parsed; a number or time stamp that is
not one is a MessageError naming the element."""

import re
import xml.etree.ElementTree as ET

from robstiff_drake.cell.link import MessageError

MAX_BYTES = 4096  # a Rob datagram is a few hundred bytes
AXES = tuple(f"A{j}" for j in range(1, 7))
# an IPOC: the controller's time stamp (ms), ASCII digits only, at most 19 of
# them (below 2**63: no float overflow, no sign, no other script's digits)
_IPOC = re.compile(r"[0-9]{1,19}\Z", re.ASCII)


def _parse(data, root_tag):
    if len(data) > MAX_BYTES:
        raise MessageError(f"{len(data)} bytes, more than an RSI message's {MAX_BYTES}")
    if b"<!" in data:  # no DTD, no entities: nothing for the parser to expand
        raise MessageError("an XML document type or entity declaration (not an RSI message)")
    try:
        root = ET.fromstring(data)
    except ET.ParseError as e:
        raise MessageError(f"not XML ({e})") from None
    if root.tag != root_tag:
        raise MessageError(f"a <{root.tag}> element, expected <{root_tag}>")
    return root


def _axes(root, tag):
    el = root.find(tag)
    if el is None:
        raise MessageError(f"no <{tag}> element")
    try:
        return [float(el.attrib[a]) for a in AXES]
    except KeyError as e:
        raise MessageError(f"<{tag}> without {e.args[0]}") from None
    except ValueError:
        raise MessageError(f"<{tag}>: an axis value that is not a number") from None


def _ipoc(root):
    el = root.find("IPOC")
    text = (el.text or "").strip() if el is not None else None
    if text is None:
        raise MessageError("no <IPOC> time stamp")
    if not _IPOC.match(text):
        raise MessageError(f"<IPOC> {text[:24]!r}: not a time stamp (1 to 19 ASCII digits)")
    return int(text)


def decode_rob(data):
    """(IPOC, AIPos deg, ASPos deg or None) of a controller's datagram."""
    root = _parse(data, "Rob")
    setpoints = _axes(root, "ASPos") if root.find("ASPos") is not None else None
    return _ipoc(root), _axes(root, "AIPos"), setpoints


_ROB = ('<Rob Type="KUKA"><AIPos A1="%.6f" A2="%.6f" A3="%.6f" A4="%.6f" A5="%.6f" A6="%.6f" />'
        '<ASPos A1="%.6f" A2="%.6f" A3="%.6f" A4="%.6f" A5="%.6f" A6="%.6f" /><Delay D="0" /><IPOC>%d</IPOC></Rob>')
_SEN = ('<Sen Type="ImFree"><EStr>robstiff</EStr>'
        '<AK A1="%.6f" A2="%.6f" A3="%.6f" A4="%.6f" A5="%.6f" A6="%.6f" /><IPOC>%d</IPOC></Sen>')


def encode_rob(ipoc, actual_deg, setpoint_deg):
    return (_ROB % (*actual_deg, *setpoint_deg, int(ipoc))).encode()


def encode_sen(ipoc, corrections_deg):
    return (_SEN % (*corrections_deg, int(ipoc))).encode()


# The PC's own answer in the one layout encode_sen writes, its numbers as
# "%.6f" writes finite ones and the IPOC as 1 to 19 ASCII digits.  A byte
# string this matches (whole) is that XML document and nothing else, so its
# numbers read here are what the XML parser would read from the same bytes;
# anything else (a non-finite value, another layout) goes to the parser.
_NUMBER = rb'"(-?[0-9]+\.[0-9]{6})"'
_SEN_RE = re.compile(rb'<Sen Type="ImFree"><EStr>robstiff</EStr><AK '
                     + b" ".join(a.encode() + b"=" + _NUMBER for a in AXES)
                     + rb' /><IPOC>([0-9]{1,19})</IPOC></Sen>\Z')


def decode_sen(data):
    """(IPOC, AK deg) of a PC's answer."""
    m = _SEN_RE.match(data)
    if m is not None:
        g = m.groups()
        return int(g[6]), [float(v) for v in g[:6]]
    root = _parse(data, "Sen")
    return _ipoc(root), _axes(root, "AK")


def _fmt_deg(q_deg):
    return "(" + ", ".join(f"{v:.3f}" for v in q_deg) + ")"
