"""ATI Net F/T Raw Data Transfer (RDT): UDP, port 49152, big-endian
(ATI's Net F/T manual, "RDT interface"; the same layout as ATI's demo
client and the netft-cpp core that pynetft wraps):

* request (client -> sensor), 8 bytes: uint16 command_header = 0x1234,
  uint16 command (0x0000 stop streaming, 0x0002 start real-time
  streaming, 0x0042 set software bias), uint32 sample_count (0: forever);
* record (sensor -> client), 36 bytes: uint32 rdt_sequence, uint32
  ft_sequence, uint32 status (0: healthy), int32 Fx, Fy, Fz, Tx, Ty, Tz in
  counts (the sensor's calibration gives the counts per force unit and
  per torque unit, shown on its web page; ``NetFTReader`` is told them
  per N and per N*m).

The sensor side (``encode_record``, ``decode_request``) is written here:
no package implements a Net F/T server.  The client side is pynetft's
(``NetFTReader`` wraps it): it starts the stream, checks the header and
the sequence numbers, and recovers from a stalled or faulted stream.
"""

import collections
import socket
import struct
import time

from robstiff_drake.errors import InputError

RDT_PORT = 49152
COMMAND_HEADER = 0x1234
CMD_STOP = 0x0000
CMD_START_REALTIME = 0x0002
CMD_SET_BIAS = 0x0042
_REQUEST = struct.Struct("!HHI")
_RECORD = struct.Struct("!3I6i")
RECORD_BYTES = _RECORD.size  # 36
# Counts per N and per N*m used between the simulated sensor and the
# compensator (ASSUMPTION: a fine resolution, 1e6 counts per N and per
# N*m, so that the int32 counts carry the simulated wrench to 1 uN; a
# real sensor's calibration gives its own, which --netft-counts sets).
DEFAULT_COUNTS_PER_UNIT = 1_000_000.0
# A record whose status has any of these bits is not a valid measurement
# (ATI: 0x80010000 is a monitor-condition warning; any other non-zero
# status is a serious condition).
WARNING_STATUS = 0x80010000


def encode_request(command, sample_count=0):
    return _REQUEST.pack(COMMAND_HEADER, command, sample_count)


def decode_request(data):
    """(command, sample_count), or None for anything that is not an RDT request."""
    if len(data) != _REQUEST.size:
        return None
    header, command, count = _REQUEST.unpack(data)
    return (command, count) if header == COMMAND_HEADER else None


def encode_record(rdt_sequence, ft_sequence, status, wrench, counts_per_force=DEFAULT_COUNTS_PER_UNIT,
                  counts_per_torque=DEFAULT_COUNTS_PER_UNIT):
    """One 36-byte record of a wrench (N, N*m)."""
    f = [int(round(v * counts_per_force)) for v in wrench[:3]]
    t = [int(round(v * counts_per_torque)) for v in wrench[3:]]
    lim = 2**31 - 1
    counts = [max(-lim, min(lim, c)) for c in f + t]
    return _RECORD.pack(rdt_sequence & 0xFFFFFFFF, ft_sequence & 0xFFFFFFFF, status & 0xFFFFFFFF, *counts)


def status_is_valid(status):
    return status == 0 or status == WARNING_STATUS


def parse_host_port(text, default_port=RDT_PORT, what="--netft"):
    """'HOST[:PORT]' -> (host, port); InputError naming the option."""
    host, sep, port = str(text).rpartition(":")
    if not sep:
        host, port = str(text), str(default_port)
    if not host:
        raise InputError(f"{what} {text!r}: expected HOST[:PORT]")
    try:
        p = int(port)
    except ValueError:
        raise InputError(f"{what} {text!r}: port {port!r} is not a number") from None
    if not 1 <= p <= 65535:
        raise InputError(f"{what} {text!r}: port {p} is outside 1-65535")
    try:
        socket.getaddrinfo(host, p, socket.AF_INET, socket.SOCK_DGRAM)
    except socket.gaierror:
        raise InputError(f"{what} {text!r}: cannot resolve host {host!r}") from None
    return host, p


def _pynetft():
    try:
        import pynetft
    except ImportError:
        raise InputError("reading a Net F/T needs the package pynetft: in robstiff-drake's clone, pip install -e '.[cell]' (it is not on PyPI)") from None
    return pynetft


class NetFTReader:
    """The sensor's stream, through pynetft: ``open()`` starts it and
    waits for the first record (InputError, one line, when no sensor
    answers or it answers with something that is not RDT); ``drain()``
    returns the records received since the last call, each as (wrench
    (N, N*m; NaN for a record whose status flags it invalid), arrival time
    (s, time.monotonic clock), status)."""

    def __init__(self, host, port=RDT_PORT, counts_per_force=DEFAULT_COUNTS_PER_UNIT,
                 counts_per_torque=DEFAULT_COUNTS_PER_UNIT, receive_timeout_s=0.05, queue_size=4096):
        self.host, self.port = host, port
        p = _pynetft()
        cal = p.Calibration(counts_per_force, counts_per_torque, p.ForceUnit.NEWTON, p.TorqueUnit.NEWTON_METER)
        self._config = p.Config(sensor_host=host, rdt_port=port, calibration_override=cal,
                                receive_timeout=receive_timeout_s, deliver_samples_with_error_status=True)
        # callback delivery into a deque: pynetft's iterator costs about
        # 0.1 ms per call on an empty queue (a timed wait), too much for a
        # 4 ms cycle; popping a deque costs about a microsecond
        self._queue = collections.deque(maxlen=queue_size)
        self._client = p.Client(self._config, queue_size=queue_size, callback=self._on_sample)

    def _on_sample(self, s):
        # (the arrival on time.monotonic's clock, taken as pynetft hands the record over)
        self._queue.append((s.force + s.torque, time.monotonic(), s.status))

    def open(self, timeout_s=2.0):
        try:
            self._client.start()
        except Exception as e:  # pynetft's configuration / socket errors
            raise InputError(f"--netft {self.host}:{self.port}: cannot start the RDT stream ({e})") from None
        t_end = time.monotonic() + timeout_s
        while not self._queue and time.monotonic() < t_end:
            time.sleep(0.005)
        if not self._queue:
            h = self._client.health()
            self.close()
            if h.malformed_count:
                raise InputError(f"--netft {self.host}:{self.port}: the device answers, but not with RDT records "
                                 f"({h.malformed_count} malformed packets: wrong header or length); is it a Net F/T "
                                 "on its RDT port?")
            raise InputError(f"--netft {self.host}:{self.port}: no RDT record within {timeout_s:g} s (is the Net F/T "
                             "on, at this address, with RDT on this UDP port, and no other client streaming?)")

    def drain(self):
        out = []
        q = self._queue
        while q:
            w, t_arr, status = q.popleft()
            if not status_is_valid(status):
                w = (float("nan"),) * 6
            out.append((w, t_arr, status))
        return out

    def health(self):
        return self._client.health()

    def close(self):
        try:
            self._client.stop()
        except Exception:
            pass


class RDTServer:
    """The sensor's side of RDT on a UDP port (the simulated Net F/T and the
    tests' fake one): answers a start request by streaming to the client
    what ``send`` is given, stops on a stop request."""

    def __init__(self, port, host="127.0.0.1", counts_per_force=DEFAULT_COUNTS_PER_UNIT,
                 counts_per_torque=DEFAULT_COUNTS_PER_UNIT):
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            self.sock.bind((host, port))
        except OSError as e:
            self.sock.close()
            raise InputError(f"--netft-port {port}: cannot listen on {host}:{port} ({e.strerror})") from None
        self.sock.setblocking(False)
        self.port = self.sock.getsockname()[1]
        self.client = None
        self.rdt_sequence = 0
        self.ft_sequence = 0
        self.cpf, self.cpt = counts_per_force, counts_per_torque
        self.requests = 0

    def poll(self):
        """Handle the requests waiting (non-blocking)."""
        while True:
            try:
                data, addr = self.sock.recvfrom(64)
            except (BlockingIOError, InterruptedError):
                return
            except OSError:
                return
            req = decode_request(data)
            if req is None:
                continue
            self.requests += 1
            cmd, _ = req
            if cmd == CMD_START_REALTIME:
                self.client = addr
                self.rdt_sequence = 0
            elif cmd == CMD_STOP and addr == self.client:
                self.client = None

    def send(self, wrench, status=0, raw=None):
        """Stream one record of ``wrench`` (N, N*m) to the client, if one
        has started the stream; ``raw``: bytes to send instead (faults)."""
        self.ft_sequence += 1
        if self.client is None:
            return False
        self.rdt_sequence += 1
        data = raw if raw is not None else encode_record(self.rdt_sequence, self.ft_sequence, status, wrench,
                                                         self.cpf, self.cpt)
        try:
            self.sock.sendto(data, self.client)
        except OSError:
            return False
        return True

    def close(self):
        self.sock.close()
