"""ABB Externally Guided Motion (EGM): UDP, protobuf messages
(``abb.egm.EgmRobot`` from the controller at its cycle, 4 ms on an IRC5;
``abb.egm.EgmSensor`` back with joint targets in degrees, EGMRunJoint).

The message definitions are those of ABB's egm.proto as the package
abb-robot-client ships them compiled (abb_robot_client._egm_protobuf,
Apache-2.0); nothing is copied here.  The PC side (``EgmLink``,
cell/link.py's checks) encodes and decodes with those definitions, as
abb-robot-client's ``EGM`` class does (its receive neither checks the
message type nor survives a datagram that is not protobuf, and its send
answers whoever sent last), and the controller's side
(``ControllerLink``: the simulated cell and the tests' fake controller) is
written here: no package implements it.
"""

import math
import time

from robstiff_drake.cell.link import ControllerSide, Message, MessageError, PCLink
from robstiff_drake.errors import InputError

EGM_JOINTS = 6


def _egm_pb2():
    try:
        from abb_robot_client._egm_protobuf import egm_pb2
    except ImportError:
        raise InputError("EGM needs the package abb-robot-client: in robstiff-drake's clone, pip install -e '.[cell]' (robstiff-drake itself is not on PyPI)") from None
    return egm_pb2


class EgmMessageError(MessageError):
    """A datagram that is not a usable EgmRobot message."""


def parse_robot_message(data, pb2=None):
    """(seqno, tm ms, joints deg (list), planned deg (list or None)) of an
    EgmRobot datagram; EgmMessageError saying what is wrong."""
    pb2 = pb2 or _egm_pb2()
    msg = pb2.EgmRobot()
    try:
        msg.ParseFromString(data)
    except Exception:
        raise EgmMessageError(f"not an EGM protobuf message ({len(data)} bytes)") from None
    mtype = msg.header.mtype if msg.HasField("header") else 0
    if mtype != pb2.EgmHeader.MSGTYPE_DATA:
        name = pb2.EgmHeader.MessageType.Name(mtype) if mtype in pb2.EgmHeader.MessageType.values() else str(mtype)
        raise EgmMessageError(f"message type {name}, expected MSGTYPE_DATA (an EgmRobot from the controller)")
    if not msg.HasField("feedBack") or not msg.feedBack.HasField("joints"):
        raise EgmMessageError("an EgmRobot without joint feedback (feedBack.joints)")
    joints = list(msg.feedBack.joints.joints)
    if len(joints) != EGM_JOINTS:
        raise EgmMessageError(f"{len(joints)} joints in the feedback, expected {EGM_JOINTS}")
    planned = list(msg.planned.joints.joints) if msg.HasField("planned") and msg.planned.HasField("joints") else None
    return msg.header.seqno, msg.header.tm, joints, planned


class EgmLink(PCLink):
    """The PC's side: receives EgmRobot on ``port`` from the controller
    only, and answers it with an EgmSensor of joint targets (deg) in
    ``planned.joints`` (EGMRunJoint), header MSGTYPE_CORRECTION as
    abb-robot-client's ``EGM.send_to_robot`` writes it."""

    name = "EGM"
    option = "--egm-port"
    # the cycles an IRC5 streams EGM at (ms): \SampleRate, a multiple of 4 ms.  ASSUMPTION (ABB's manual not at
    # hand): the multiples up to 24; a steady clock at one of them that is not --period-ms is named with the
    # --period-ms to set (cell/session_faults.py)
    cycles_ms = (4.0, 8.0, 12.0, 16.0, 20.0, 24.0)
    # the IRC5 takes the newest EgmSensor it has at each cycle: an answer after the next cycle is a held cycle
    # (the last target held, then two steps at once: docs/real_cell.md, \LpFilter)
    answer_deadline_periods = 1.0

    def __init__(self, port, controller):
        self.pb2 = _egm_pb2()
        super().__init__(port, controller)
        self._out_seq = 0

    def decode(self, data):
        try:
            seq, tm, joints, _ = parse_robot_message(data, self.pb2)
        except EgmMessageError as e:
            raise MessageError(str(e)) from None
        return Message(seq, tm, joints)

    def encode(self, message, targets_deg):
        m = self.pb2.EgmSensor()
        self._out_seq += 1
        m.header.mtype = self.pb2.EgmHeader.MSGTYPE_CORRECTION
        m.header.seqno = self._out_seq
        m.header.tm = message.tm_ms & 0xFFFFFFFF
        m.planned.joints.joints.extend(float(v) for v in targets_deg)
        return m.SerializeToString()

    def commanded_deg(self, message, data):
        m = self.pb2.EgmSensor()
        m.ParseFromString(data)
        return list(m.planned.joints.joints)  # EGMRunJoint: absolute joint targets


class ControllerLink(ControllerSide):
    """The controller's side (a simulated IRC5): sends EgmRobot to the
    sensor (the compensator) at ``host:port`` and receives its EgmSensor
    joint targets."""

    name = "EGM"

    def __init__(self, host, port):
        self.pb2 = _egm_pb2()
        super().__init__(("127.0.0.1" if host in ("127.0.0.1", "localhost") else "", 0), (host, port))
        self.seqno = 0
        self.t0 = time.monotonic()

    def restart(self):
        """A controller restart: the sequence number and clock start again."""
        self.seqno = 0
        self.t0 = time.monotonic()

    def robot_message(self, joints_deg, planned_deg=None, mtype=None, tm_ms=None):
        """``tm_ms``: the controller's clock (ms) of the cycle; a hard
        real-time controller stamps its cycles, not the moment the message
        leaves (default: the time since the start or the last restart)."""
        m = self.pb2.EgmRobot()
        self.seqno += 1
        m.header.seqno = self.seqno
        tm = (time.monotonic() - self.t0) * 1000 if tm_ms is None else tm_ms
        m.header.tm = int(round(tm)) & 0xFFFFFFFF
        m.header.mtype = self.pb2.EgmHeader.MSGTYPE_DATA if mtype is None else mtype
        m.feedBack.joints.joints.extend([float(v) for v in joints_deg])
        if planned_deg is not None:
            m.planned.joints.joints.extend([float(v) for v in planned_deg])
        m.motorState.state = self.pb2.EgmMotorState.MOTORS_ON
        m.rapidExecState.state = self.pb2.EgmRapidCtrlExecState.RAPID_RUNNING
        return m.SerializeToString()

    def send_state(self, k, joints_deg, planned_deg, tm_ms, bad_type=False):
        """Send cycle ``k``'s EgmRobot; the answer to it echoes ``tm_ms``."""
        mtype = self.pb2.EgmHeader.MSGTYPE_COMMAND if bad_type else None
        self.sent_as(int(round(tm_ms)) & 0xFFFFFFFF, k)
        return self.send(self.robot_message(joints_deg, planned_deg, mtype, tm_ms=tm_ms))

    def skip(self):
        self.seqno += 1

    def answers(self):
        """[(cycle k answered, targets deg)] of the EgmSensor waiting."""
        out = []
        for data, _ in self.datagrams():
            m = self.pb2.EgmSensor()
            try:
                m.ParseFromString(data)
            except Exception:
                continue
            j = list(m.planned.joints.joints) if m.HasField("planned") else []
            if len(j) == EGM_JOINTS:
                # an answer that echoes no message's clock (abb-robot-client's EGM does not) answers the
                # newest message, as a controller takes the latest target it has
                k = self.answer_of(m.header.tm) if m.header.tm else None
                out.append((self._last_k if k is None else k, j))
        return out

    def receive_targets(self, timeout_s=0.0):
        """The joint targets (deg, list) of the newest EgmSensor waiting, or
        None; with ``timeout_s`` > 0, wait that long (s) for one first."""
        if timeout_s > 0.0:
            self.wait(timeout_s)
        got = [j for _, j in self.answers() if all(math.isfinite(v) for v in j)]
        return got[-1] if got else None
