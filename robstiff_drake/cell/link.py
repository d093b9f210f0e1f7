"""The PC's side of a robot controller's streaming protocol (EGM, RSI,
Stream Motion), the part they share: one UDP socket, only the configured
controller heard, and one way out for joint targets.

* ``receive(timeout_s)``: every datagram waiting (up to ``MAX_DRAIN``); a
  datagram from any other address (or port, when ``--controller`` gives
  one) is dropped and counted in ``strangers``, never decoded, never
  answered; the controller's are decoded by the protocol (``decode``) and
  returned in arrival order with their arrival times; one that does not
  decode is counted in ``malformed``.  Each message's ``queued_s`` says
  how long its datagram waited at this PC before the loop read it (from
  the kernel's receive time stamp, SO_TIMESTAMPNS on Linux): the loop's
  wake-up, and any stall of this machine meanwhile, which the arrival time
  (taken when the loop reads it) does not see.
* ``send_targets(message, targets_deg, envelope)``: the only way a target
  leaves: the protocol's ``encode``, then the pose the controller will
  command on reading those bytes (``commanded_deg``: for RSI its start plus
  the corrections, for EGM and Stream Motion the absolute targets decoded)
  through ``safety.unsafe_reason`` and ``safety.motion_reason`` (its step
  from the poses commanded before; UnsafeTarget when either refuses), then
  to the controller.  A protocol class writes ``decode``, ``encode`` and
  ``commanded_deg`` (bytes in, bytes out) and never touches the socket.
"""

import ipaddress
import math
import platform
import select
import socket
import struct
import sys
import time
from dataclasses import dataclass, field

from robstiff_drake.cell.safety import UnsafeTarget, motion_reason, unsafe_reason
from robstiff_drake.errors import InputError

MAX_DRAIN = 256  # datagrams read per receive (a flood cannot hold the loop)
MAX_DATAGRAM = 65536
# the kernel's receive time stamp of a datagram (struct timespec, CLOCK_REALTIME): Linux's SO_TIMESTAMPNS, 35 in
# asm-generic/socket.h, which x86, ARM, RISC-V and PowerPC use (Python's socket module does not name it); on the
# architectures with their own numbers (Alpha, MIPS, PA-RISC, SPARC) and off Linux none: no option set, queued_s NaN
_GENERIC_SOCKET_ABI = ("x86_64", "i386", "i686", "aarch64", "armv7l", "armv8l", "riscv64", "ppc64le", "ppc64")
SO_TIMESTAMPNS = getattr(socket, "SO_TIMESTAMPNS", 35 if sys.platform.startswith("linux")
                         and platform.machine() in _GENERIC_SOCKET_ABI else None)
_TIMESPEC = struct.Struct("@ll")  # (tv_sec, tv_nsec: the C longs of the old, native time stamp)


class MessageError(ValueError):
    """A datagram from the controller that is not a usable message."""


@dataclass
class Message:
    """One controller message: its sequence number and clock (ms), the
    measured joint angles (deg, the controller's convention) and what the
    answer must echo (``echo``: the protocol's own)."""

    seq: int
    tm_ms: int
    joints_deg: list
    echo: object = None
    extra: dict = field(default_factory=dict)
    # how long (s) the datagram waited at this PC from its arrival (the kernel's receive time stamp) to its
    # read; NaN where the system gives no stamp
    queued_s: float = float("nan")


def stamp_s(ancdata):
    """The kernel's receive time (s, CLOCK_REALTIME) in a datagram's
    ancillary data (``socket.recvmsg``), or None when it carries none."""
    for level, kind, data in ancdata:
        if level == socket.SOL_SOCKET and kind == SO_TIMESTAMPNS and len(data) >= _TIMESPEC.size:
            sec, nsec = _TIMESPEC.unpack_from(data)
            return sec + nsec * 1e-9
    return None


def queued_s(stamp, now_realtime_s):
    """How long a datagram stamped at ``stamp`` (s, CLOCK_REALTIME; None:
    no stamp) had waited when read at ``now_realtime_s`` (the same clock,
    read at once: a step of the wall clock between the two is all that can
    err); NaN when unknown or negative (a clock stepped back)."""
    if stamp is None:
        return float("nan")
    q = now_realtime_s - stamp
    return q if 0.0 <= q < 3600.0 and math.isfinite(q) else float("nan")


def split_host_port(text, default_port, what):
    """'HOST[:PORT]' -> (host, port or ``default_port``); InputError naming the option."""
    host, sep, port = str(text).rpartition(":")
    if not sep:
        host, port = str(text), None
    if not host:
        raise InputError(f"{what} {text!r}: expected HOST[:PORT]")
    if port is None:
        return host, default_port
    try:
        p = int(port)
    except ValueError:
        raise InputError(f"{what} {text!r}: port {port!r} is not a number") from None
    if not 1 <= p <= 65535:
        raise InputError(f"{what} {text!r}: port {p} is outside 1-65535")
    return host, p


def parse_controller(text, default_port=None, what="--controller"):
    """'HOST[:PORT]' -> (IP address text, port or None); InputError naming the option."""
    host, p = split_host_port(text, default_port, what)
    try:
        ip = socket.getaddrinfo(host, None, socket.AF_INET, socket.SOCK_DGRAM)[0][4][0]
    except (socket.gaierror, UnicodeError):
        raise InputError(f"{what} {text!r}: cannot resolve host {host!r}") from None
    return ip, p


def is_loopback(ip):
    return ipaddress.ip_address(ip).is_loopback


class PCLink:
    """Base of the protocols' PC side.  ``listen_port``: the UDP port the
    controller sends to (0: any, the protocol's client mode); ``controller``:
    (IP, port or None) of the only sender heard."""

    name = "controller"
    option = "--listen-port"
    # The answer's deadline, in the controller's periods from its message's arrival at this PC (the kernel's
    # stamp): a controller runs its cycle on its own clock and takes at each cycle the newest target it has, so
    # an answer that leaves later missed that cycle even when this PC saw the next message late (a late
    # datagram, not a late controller).  Each protocol states its own (EgmLink, RsiLink, StreamMotionLink).
    answer_deadline_periods = 1.0
    # With ``--controller HOST`` and no port (EGM's and RSI's controllers send from a port of their own), the port
    # of the first message decoded is the controller's: another port on that host is a stranger while the
    # controller speaks, and is taken up only after it fell silent this long (a new session, stopped and started
    # again); any datagram from the learnt port, garbled or not, keeps it (``_drain``).  ASSUMPTION: 0.1 s, 25
    # periods of 4 ms; no public source gives how soon a restarted session sends or whether it keeps its port; a
    # faster one from a new port is heard at most this late.  Before, every port on the host was heard and the
    # answer went to the newest sender's.
    port_switch_silence_s = 0.1

    def __init__(self, listen_port, controller):
        self.controller_ip, self.controller_port = controller
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        bind_host = "127.0.0.1" if is_loopback(self.controller_ip) else ""
        try:
            self.sock.bind((bind_host, int(listen_port)))
        except OSError as e:
            self.sock.close()
            raise InputError(f"{self.option} {listen_port}: cannot listen on UDP port {listen_port} ({e.strerror}; "
                             "is another compensator running?)") from None
        self.sock.setblocking(False)
        self.port = self.sock.getsockname()[1]
        self._stamped = False  # (the kernel's receive time stamps on: ``queued_s``)
        if SO_TIMESTAMPNS is not None and hasattr(self.sock, "recvmsg"):
            try:
                self.sock.setsockopt(socket.SOL_SOCKET, SO_TIMESTAMPNS, 1)
                self._stamped = True
            except OSError:
                pass
        self._anc = socket.CMSG_SPACE(_TIMESPEC.size) + 64 if self._stamped else 0
        self.reply_to = None if self.controller_port is None else (self.controller_ip, self.controller_port)
        self._heard_s = None  # when the controller's port (learnt, when not given) was last heard (time.monotonic)
        self.port_switches = 0  # times the learnt port changed (after the silence above)
        self.strangers = 0
        self.stranger_example = None
        self.malformed = 0
        self.malformed_example = ""
        self.sent = 0
        # when the datagram being decoded came (s, time.monotonic; the kernel's stamp when there is one): a
        # protocol's decode may compare the controller's clock with it (RsiLink: lost datagrams or a restart)
        self.arrival_s = None
        # the poses the controller was told to command (deg), newest last (two
        # kept: its step and the change of its step); a new session of the
        # protocol (RSI's restart) starts them again from its start
        self.commanded = []

    # ------------------------------------------------------------ protocol hooks

    def decode(self, data):
        """Message of a datagram; MessageError saying what is wrong."""
        raise NotImplementedError

    def encode(self, message, targets_deg):
        """The answer (bytes) carrying joint targets ``targets_deg`` (deg)
        to ``message``; called only with targets that passed the check."""
        raise NotImplementedError

    def commanded_deg(self, message, data):
        """The joint angles (deg, 6) the controller will command when it
        reads ``data``, the answer to ``message`` (the protocol's reading of
        its own bytes)."""
        raise NotImplementedError

    def answer_problem(self, message, envelope):
        """None when the link may answer ``message``; else why not (a
        protocol's own check that it knows what the controller will do)."""
        return None

    def open(self):
        """Whatever the protocol sends before the controller streams (a start request)."""

    def close(self):
        try:
            self.sock.close()
        except OSError:
            pass

    # ------------------------------------------------------------ receiving

    def _from_controller(self, addr, t_s):
        """Whether a datagram from ``addr`` that came at ``t_s`` (time.monotonic) is the controller's."""
        if addr[0] != self.controller_ip:
            return False
        if self.controller_port is not None:
            return addr[1] == self.controller_port
        learnt = None if self.reply_to is None else self.reply_to[1]
        return learnt is None or addr[1] == learnt or t_s - self._heard_s > self.port_switch_silence_s

    def receive(self, timeout_s):
        """[(Message, arrival time s on time.monotonic)] of the controller's
        datagrams waiting, oldest first; [] after ``timeout_s`` without one."""
        t_end = time.monotonic() + max(timeout_s, 0.0)
        while True:
            got = self._drain()
            if got:
                return got
            left = t_end - time.monotonic()
            if left <= 0:
                return []
            try:
                select.select([self.sock], [], [], left)
            except (OSError, ValueError):
                return []

    def _drain(self):
        out = []
        for _ in range(MAX_DRAIN):
            try:
                if self._stamped:
                    data, anc, _, addr = self.sock.recvmsg(MAX_DATAGRAM, self._anc)
                else:
                    data, addr = self.sock.recvfrom(MAX_DATAGRAM)
            except (BlockingIOError, InterruptedError):
                break
            except OSError:
                break
            t = time.monotonic()
            waited = queued_s(stamp_s(anc), time.time()) if self._stamped else float("nan")
            arrival = t - waited if math.isfinite(waited) else t
            if not self._from_controller(addr, arrival):
                self.strangers += 1
                if self.stranger_example is None:
                    self.stranger_example = f"{addr[0]}:{addr[1]}"
                continue
            self.arrival_s = arrival
            learnt = self.controller_port is None and self.reply_to is not None and addr[1] == self.reply_to[1]
            if learnt:  # (the learnt port speaks, garbled or not: its silence alone hands the port on)
                self._heard_s = arrival
            try:
                msg = self.decode(data)
            except MessageError as e:
                self.malformed += 1
                self.malformed_example = str(e)
                continue
            if self.controller_port is None and not learnt:  # the controller's own port, learnt (EGM, RSI)
                if self.reply_to is not None:
                    self.port_switches += 1
                    # the old session's messages read in this batch: their answer would go to the new port,
                    # checked against the old arm's feedback; never answered, counted as a stranger's
                    self.strangers += len(out)
                    out = []
                self.reply_to = addr
                self._heard_s = arrival
            msg.queued_s = waited
            out.append((msg, t))
        return out

    # ------------------------------------------------------------ sending

    def send_targets(self, message, targets_deg, envelope):
        """Send ``targets_deg`` (6, controller deg) as the answer to
        ``message`` if the pose the controller will command from it passes
        ``safety.unsafe_reason`` and ``safety.motion_reason``; else raise
        UnsafeTarget (nothing is sent)."""
        reason = unsafe_reason(targets_deg, envelope)  # (before encoding: a NaN or 1e300 never reaches a codec)
        if reason is not None:
            raise UnsafeTarget(reason)
        reason = self.answer_problem(message, envelope)
        if reason is not None:
            raise UnsafeTarget(reason)
        if self.reply_to is None:
            raise UnsafeTarget("no controller address to answer yet")
        data = self.encode(message, targets_deg)
        commanded = self.commanded_deg(message, data)
        reason = unsafe_reason(commanded, envelope) or motion_reason(commanded, envelope, self.commanded)
        if reason is not None:
            raise UnsafeTarget(f"{reason} (the pose the controller would command)")
        try:
            self.sock.sendto(data, self.reply_to)
        except OSError:
            return False
        self.sent += 1
        self.commanded = self.commanded[-1:] + [list(commanded)]
        return True

    def send_control(self, data):
        """A datagram that carries no joint target (a start or stop request)."""
        if self.reply_to is None:
            return False
        try:
            self.sock.sendto(data, self.reply_to)
            return True
        except OSError:
            return False


class ControllerSide:
    """Base of the simulated controllers' side of a protocol: one UDP
    socket, and the messages sent by the key their answers echo (``sent``:
    key -> cycle k; ``answer_of`` pops it)."""

    MAX_PENDING = 4096  # answers that never came are forgotten past this many

    def __init__(self, bind=("127.0.0.1", 0), peer=None):
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(bind)
        self.sock.setblocking(False)
        self.addr = peer
        self._sent = {}
        self._last_k = None

    def sent_as(self, key, k):
        if len(self._sent) > self.MAX_PENDING:
            self._sent.clear()
        self._sent[key] = k
        self._last_k = k

    def answer_of(self, key):
        return self._sent.pop(key, None)

    def send(self, data, to=None):
        try:
            self.sock.sendto(data, to or self.addr)
            return True
        except OSError:
            return False

    def datagrams(self):
        """The datagrams waiting, with their senders."""
        out = []
        while True:
            try:
                out.append(self.sock.recvfrom(65536))
            except (BlockingIOError, InterruptedError, OSError):
                return out

    def wait(self, timeout_s):
        select.select([self.sock], [], [], timeout_s)

    def skip(self):
        """A message lost on the way (the protocol's sequence number used up)."""

    def close(self):
        self.sock.close()
