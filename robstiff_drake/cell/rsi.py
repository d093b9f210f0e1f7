"""KUKA RobotSensorInterface (RSI) over Ethernet: XML in UDP datagrams.

No maintained Python package implements it (PyPI searched for kuka, rsi,
kukavarproxy-style clients: none speaks RSI's XML; the code corpus holds
C++ clients such as ROS-Industrial's kuka_rsi_hw_interface and a few
unmaintained scripts), so the wire format is written here from public
documentation: KUKA's "KUKA.RobotSensorInterface 3.x/4.x" manual (the
ETHERNET object and its configuration file RSI_EthernetConfig.xml) and
ROS-Industrial's kuka_experimental, whose ``ros_rsi_ethernet.xml``
configuration names the elements used here.  Nothing is copied.

* the controller (KRC4, KSS 8.x) sends every interpolation cycle (4 ms,
  or 12 ms with RSI's IPO mode) ``<Rob Type="KUKA">`` with, as configured
  in RSI_EthernetConfig.xml's SEND section, ``<AIPos A1=".." .. A6=".."/>``
  (the actual axis angles, deg, KUKA's convention), ``<ASPos .../>``
  (setpoints) and ``<IPOC>`` (its time stamp, ms);
* the PC answers within the cycle with ``<Sen Type="ImFree">`` holding
  ``<AK A1=".." .. A6=".."/>`` (the RECEIVE section's axis corrections,
  deg, fed to an AXISCORR object in absolute mode: the correction from
  the axis angles at RSI_MOVECORR's start) and the same ``<IPOC>`` (the
  controller refuses an answer whose IPOC is not its own).

The PC streams the whole path as corrections from the start position
(as EGMRunJoint streams it): AK = target - start, the start being the
first message's AIPos.  The session clock is the IPOC: sequence number
IPOC / period, clock IPOC (ms).
"""

import xml.etree.ElementTree as ET

from robstiff_drake.cell.link import ControllerSide, Message, MessageError, PCLink

MAX_BYTES = 4096  # a Rob datagram is a few hundred bytes
AXES = tuple(f"A{j}" for j in range(1, 7))


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
    try:
        return int(el.text.strip())
    except (AttributeError, ValueError):
        raise MessageError("no <IPOC> time stamp") from None


def decode_rob(data):
    """(IPOC, AIPos deg, ASPos deg or None) of a controller's datagram."""
    root = _parse(data, "Rob")
    setpoints = _axes(root, "ASPos") if root.find("ASPos") is not None else None
    return _ipoc(root), _axes(root, "AIPos"), setpoints


def encode_rob(ipoc, actual_deg, setpoint_deg):
    a = " ".join(f'{n}="{v:.6f}"' for n, v in zip(AXES, actual_deg))
    s = " ".join(f'{n}="{v:.6f}"' for n, v in zip(AXES, setpoint_deg))
    return (f'<Rob Type="KUKA"><AIPos {a} /><ASPos {s} /><Delay D="0" /><IPOC>{int(ipoc)}</IPOC></Rob>').encode()


def encode_sen(ipoc, corrections_deg):
    ak = " ".join(f'{n}="{v:.6f}"' for n, v in zip(AXES, corrections_deg))
    return f'<Sen Type="ImFree"><EStr>robstiff</EStr><AK {ak} /><IPOC>{int(ipoc)}</IPOC></Sen>'.encode()


def decode_sen(data):
    """(IPOC, AK deg) of a PC's answer."""
    root = _parse(data, "Sen")
    return _ipoc(root), _axes(root, "AK")


class RsiLink(PCLink):
    """The PC's side of RSI: the controller's <Rob> on ``port``, answered
    with <Sen> axis corrections from the start position."""

    name = "RSI"
    option = "--listen-port"

    def __init__(self, port, controller, period_s):
        super().__init__(port, controller)
        self.period_ms = period_s * 1e3
        self.start_deg = None

    def decode(self, data):
        ipoc, actual, _ = decode_rob(data)
        if self.start_deg is None:
            self.start_deg = list(actual)  # RSI_MOVECORR's start: corrections are from here
        return Message(int(round(ipoc / self.period_ms)), ipoc, actual, echo=ipoc)

    def encode(self, message, targets_deg):
        return encode_sen(message.echo, [t - s for t, s in zip(targets_deg, self.start_deg)])


class RsiControllerLink(ControllerSide):
    """The controller's side (a simulated KRC): sends <Rob> to the PC at
    ``host:port`` every cycle and reads the <Sen> answers (targets = start +
    AK, the start being the axis angles of its first message)."""

    name = "RSI"

    def __init__(self, host, port, period_s, ipoc0=1_000_000):
        super().__init__(("127.0.0.1" if host in ("127.0.0.1", "localhost") else "", 0), (host, port))
        self.period_ms = period_s * 1e3
        self.ipoc0 = ipoc0
        self.start = None

    def send_state(self, k, joints_deg, planned_deg, tm_ms, bad_type=False):
        if self.start is None:
            self.start = list(joints_deg)
        ipoc = self.ipoc0 + int(round(tm_ms))
        self.sent_as(ipoc, k)
        return self.send(b"<Rob Type='KUKA'/>" if bad_type else encode_rob(ipoc, joints_deg, planned_deg))

    def restart(self):
        self.ipoc0 += 10_000_000  # a new RSI session: another IPOC epoch
        self.start = None

    def answers(self):
        out = []
        for data, _ in self.datagrams():
            try:
                ipoc, ak = decode_sen(data)
            except MessageError:
                continue
            k = self.answer_of(ipoc)
            if k is not None and self.start is not None:  # the controller refuses an IPOC not its own
                out.append((k, [s + a for s, a in zip(self.start, ak)]))
        return out
