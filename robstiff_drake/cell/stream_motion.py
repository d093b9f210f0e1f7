"""FANUC Stream Motion (option J519): binary UDP, big-endian.

No maintained Python package implements it (PyPI searched: fanucpy,
fanuc-python, fanuc-rmi, fanuc-remote-buffer speak FANUC's other
interfaces, none J519), so the wire format is written here from public
documentation: the packet definitions of FANUC's own ROS 2 driver
(FANUC America / FANUC Corporation, Apache-2.0, ``stream_motion/
packets.hpp``), which cite the J519 manual's Table 3.3(a)-(d).  Nothing is
copied.  Version 3 packets, robot on UDP port 60015:

* start (PC -> robot): uint32 packet_type 200, uint32 version 3; the robot
  then sends a status packet every interpolation cycle;
* status (robot -> PC), type 202 (version 3, without force data): uint32
  type, version, sequence_no; uint8 status (bit 0: waiting for a command,
  bit 1: command received, bit 2: system ready, bit 3: in motion),
  robot_status, contact_stop_status, unused; uint32 time_stamp; float32
  position[9], joint_angle[9] (deg, FANUC's convention: J3 from the
  horizontal), current[9]; float32 safety_scale; 256 bytes of I/O;
* command (PC -> robot), type 201: uint32 type, version, sequence_no (the
  status packet's it answers); uint8 is_last_command, do_motion_ctrl (1);
  uint16 unused (0xFFFF); float64 command_pos[9] (joint angles, deg, for a
  joint-style program); 256 bytes of I/O;
* stop (PC -> robot): uint32 type 2, version 3.

ASSUMPTION: time_stamp counts milliseconds (the driver's header does not
state its unit); the session check (cell/session.py) faults when it does
not advance with the sequence numbers at the configured period.
"""

import struct

from robstiff_drake.cell.link import ControllerSide, Message, MessageError, PCLink

VERSION = 3
START, STOP, COMMAND, STATUS = 200, 2, 201, 202
ROBOT_PORT = 60015
AXES = 9
_HEAD = struct.Struct(">II")
_STATUS = struct.Struct(f">IIIBBBBI{AXES}f{AXES}f{AXES}ff256s")
_COMMAND = struct.Struct(f">IIIBBH{AXES}d256s")
READY = 0x01


def encode_status(seq, tm_ms, joints_deg, status=0x05):
    j = list(joints_deg)[:AXES] + [0.0] * (AXES - min(len(joints_deg), AXES))
    return _STATUS.pack(STATUS, VERSION, seq & 0xFFFFFFFF, status, 0, 0, 0, int(tm_ms) & 0xFFFFFFFF,
                        *([0.0] * AXES), *j, *([0.0] * AXES), 1.0, bytes(256))


def decode_status(data):
    """(sequence_no, time_stamp, status byte, joint angles deg (6))."""
    if len(data) != _STATUS.size:
        raise MessageError(f"{len(data)} bytes, a version-3 status packet has {_STATUS.size}")
    v = _STATUS.unpack(data)
    if v[0] != STATUS or v[1] != VERSION:
        raise MessageError(f"packet type {v[0]} version {v[1]}, expected a status packet ({STATUS}, {VERSION})")
    return v[2], v[7], v[3], list(v[8 + AXES: 8 + AXES + 6])


def encode_command(seq, joints_deg, last=False):
    j = list(joints_deg) + [0.0] * (AXES - len(joints_deg))
    return _COMMAND.pack(COMMAND, VERSION, seq & 0xFFFFFFFF, 1 if last else 0, 1, 0xFFFF, *j, bytes(256))


def decode_command(data):
    """(sequence_no, joint targets deg (6))."""
    if len(data) != _COMMAND.size:
        raise MessageError(f"{len(data)} bytes, not a command packet")
    v = _COMMAND.unpack(data)
    if v[0] != COMMAND:
        raise MessageError(f"packet type {v[0]}, not a command")
    return v[2], list(v[6:12])


class StreamMotionLink(PCLink):
    """The PC's side: sends the start packet to the robot (``open``),
    answers each status packet with a command of absolute joint targets
    echoing its sequence number, and sends the stop packet at the end."""

    name = "Stream Motion"
    option = "--listen-port"
    # the interpolation cycles a FANUC controller streams at (ms): 8, or 4 on those that stream at 250 Hz
    # (docs/real_cell.md); a steady clock at one that is not --period-ms is named (cell/session_faults.py)
    cycles_ms = (4.0, 8.0)
    # a status packet every interpolation cycle, each answered by a command echoing its sequence number: the
    # command is for that cycle.  ASSUMPTION: one arriving after the next cycle is missing for it (the J519
    # packet definitions the module cites do not say what the robot does with it)
    answer_deadline_periods = 1.0

    def decode(self, data):
        seq, tm, status, joints = decode_status(data)
        if not status & READY:
            raise MessageError("the robot is not waiting for a command (status bit 0 clear)")
        return Message(seq, tm, joints, echo=seq)

    def encode(self, message, targets_deg):
        return encode_command(message.echo, targets_deg)

    def commanded_deg(self, message, data):
        return decode_command(data)[1]  # absolute joint targets (float64)

    def open(self):
        self.send_control(_HEAD.pack(START, VERSION))

    def close(self):
        self.send_control(_HEAD.pack(STOP, VERSION))
        super().close()


class StreamMotionControllerLink(ControllerSide):
    """The robot's side (a simulated R-30iB): listens on ``host:port`` for
    a start packet, then sends a status packet to that client every cycle
    and reads its commands; a stop packet ends the stream."""

    name = "Stream Motion"

    def __init__(self, host, port):
        super().__init__((host, port))
        self.seq = 0
        self._pending = []

    def _poll(self):
        for data, addr in self.datagrams():
            if len(data) == _HEAD.size:
                kind, _ = _HEAD.unpack(data)
                if kind == START:
                    self.addr = addr
                elif kind == STOP and addr == self.addr:
                    self.addr = None
                continue
            if addr != self.addr:
                continue
            try:
                seq, targets = decode_command(data)
            except MessageError:
                continue
            k = self.answer_of(seq)
            if k is not None:
                self._pending.append((k, targets))

    def send_state(self, k, joints_deg, planned_deg, tm_ms, bad_type=False):
        self._poll()
        self.seq += 1
        if self.addr is None:
            return False
        self.sent_as(self.seq, k)
        return self.send(_HEAD.pack(STATUS, 1) if bad_type else encode_status(self.seq, tm_ms, joints_deg))

    def skip(self):
        self.seq += 1

    def restart(self):
        self.seq = 0

    def answers(self):
        self._poll()
        out, self._pending = self._pending, []
        return out
