"""ATI Net F/T Raw Data Transfer (RDT): UDP, port 49152, big-endian
(ATI's Net F/T manual, "RDT interface"; the same layout as ATI's demo
client and the netft-cpp core that pynetft wraps):

* request (client -> sensor), 8 bytes: uint16 command_header = 0x1234,
  uint16 command (0x0000 stop streaming, 0x0002 start real-time
  streaming, 0x0042 set software bias), uint32 sample_count (0: forever);
* record (sensor -> client), 36 bytes: uint32 rdt_sequence, uint32
  ft_sequence, uint32 status (0: healthy), int32 Fx, Fy, Fz, Tx, Ty, Tz in
  counts.  The sensor's calibration gives the counts per force unit and
  per torque unit and the units; it serves them over HTTP as
  ``/netftapi2.xml`` (elements ``cfgcpf``, ``cfgcpt``, ``scfgfu``,
  ``scfgtu``, ``prodname``), which pynetft reads when it is given no
  override (its native core, netft-cpp: ``discover_sensor``).
  ``NetFTReader`` converts whatever units the sensor reports to N and N*m.

The sensor side (``encode_record``, ``decode_request``, ``RDTServer``
with its calibration page) is written here: no package implements a Net
F/T server.  RDT records from any other address than the sensor never
reach the compensator: pynetft's socket is connected to the sensor, so
the kernel drops them (tests/test_cell_io.py checks it).  The client side is pynetft's
(``NetFTReader`` wraps it): it starts the stream, checks the header and
the sequence numbers, and recovers from a stalled or faulted stream.
"""

import collections
import math
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
# the malformed packets (wrong header or length) with no RDT record among them after which a device is refused
# (pynetft stops a stream of malformed packets and asks again with a back-off: a few arrive per second)
MALFORMED_ENOUGH = 5
# The simulated sensor's calibration (ASSUMPTION: a fine resolution, 1e6
# counts per N and per N*m, so that the int32 counts carry the simulated
# wrench to 1 uN; a real sensor serves its own, which compensate reads).
DEFAULT_COUNTS_PER_UNIT = 1_000_000.0
INT32_MAX = 2**31 - 1
# The units a Net F/T reports (netft-cpp's spellings) in N and N*m.
FORCE_UNITS_N = {"N": 1.0, "lbf": 4.4482216152605, "klbf": 4448.2216152605, "kN": 1000.0, "kgf": 9.80665}
TORQUE_UNITS_NM = {"N-m": 1.0, "Nm": 1.0, "N-mm": 1e-3, "Nmm": 1e-3, "lbf-in": 0.112984829027617,
                   "lbf-ft": 1.3558179483314004, "kgf-cm": 0.0980665, "kN-m": 1000.0}
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
    from robstiff_drake.cell.link import split_host_port

    host, p = split_host_port(text, default_port, what)
    try:
        socket.getaddrinfo(host, p, socket.AF_INET, socket.SOCK_DGRAM)
    except socket.gaierror:
        raise InputError(f"{what} {text!r}: cannot resolve host {host!r}") from None
    return host, p


def _pynetft():
    try:
        import pynetft
    except ImportError:
        raise InputError("reading a Net F/T needs the package pynetft: in robstiff-drake's clone, pip install -e '.[cell]' (robstiff-drake itself is not on PyPI)") from None
    return pynetft


def calibration_problem(counts, units):
    """None when an override (counts per force and torque unit, their
    units) is usable; else what is wrong (for a one-line error)."""
    cpf, cpt = counts
    fu, tu = units
    if fu not in FORCE_UNITS_N:
        return f"force unit {fu!r} is not one of {', '.join(FORCE_UNITS_N)}"
    if tu not in TORQUE_UNITS_NM:
        return f"torque unit {tu!r} is not one of {', '.join(TORQUE_UNITS_NM)}"
    for what, c, per_N in (("force", cpf, FORCE_UNITS_N[fu]), ("torque", cpt, TORQUE_UNITS_NM[tu])):
        if not (math.isfinite(c) and c > 0):
            return f"counts per {what} unit must be a positive number, got {c!r}"
        # int32 counts must carry at least 1 N (1 N*m) of range and resolve 10 N (10 N*m)
        full_scale = INT32_MAX / c * per_N
        if not 1.0 <= full_scale:
            return (f"{c:g} counts per {what} unit would put the sensor's int32 counts at their end at "
                    f"{full_scale:.3g} {'N' if what == 'force' else 'N*m'}: not a Net F/T's calibration")
        if not per_N / c <= 10.0:
            return (f"{c:g} counts per {what} unit resolves {per_N / c:.3g} {'N' if what == 'force' else 'N*m'} "
                    "per count: not a Net F/T's calibration")
    return None


class NetFTReader:
    """The sensor's stream, through pynetft: ``open()`` reads the sensor's
    calibration (its ``/netftapi2.xml`` on ``http_port``, unless
    ``counts``/``units`` override it) and starts the stream, waiting for
    the first record (InputError, one line, when no sensor answers or it
    answers with something that is not RDT); ``drain()`` returns the
    records received since the last call, each as (wrench (N, N*m; NaN
    for a record whose status flags it invalid), arrival time (s,
    time.monotonic clock), status, clipped: a count at the end of int32's
    range, the true load unknown).  ``calibration``: (counts per force
    unit, counts per torque unit, force unit, torque unit, source)."""

    def __init__(self, host, port=RDT_PORT, *, counts=None, units=None, http_port=80, receive_timeout_s=1.0,
                 queue_size=4096):
        """``receive_timeout_s``: pynetft restarts the stream after this
        long without a record (with its back-off); the compensator's own
        sensor timeout (20 ms) is what faults: a short stall of this PC
        must not make pynetft restart a stream that is still there."""
        self.host, self.port, self.http_port = host, port, int(http_port)
        self._p = p = _pynetft()
        override = None
        if counts is not None:
            fu = next(u for u in p.ForceUnit if u.value == units[0])
            tu = next(u for u in p.TorqueUnit if u.value == {"Nm": "N-m", "Nmm": "N-mm"}.get(units[1], units[1]))
            override = p.Calibration(float(counts[0]), float(counts[1]), fu, tu)
        self._config = p.Config(sensor_host=host, rdt_port=port, http_port=self.http_port,
                                calibration_override=override, receive_timeout=receive_timeout_s,
                                deliver_samples_with_error_status=True)
        # callback delivery into a deque: pynetft's iterator costs about
        # 0.1 ms per call on an empty queue (a timed wait), too much for a
        # 4 ms cycle; popping a deque costs about a microsecond
        self._queue = collections.deque(maxlen=queue_size)
        self._client = p.Client(self._config, queue_size=queue_size, callback=self._on_sample)
        self._scale = None
        self.calibration = None

    def _on_sample(self, s):
        # (the arrival on time.monotonic's clock, taken as pynetft hands the record over)
        self._queue.append((s.force, s.torque, s.raw_wrench, time.monotonic(), s.status, s.force_unit.value,
                            s.torque_unit.value))

    def open(self, timeout_s=2.0):
        where = f"--netft {self.host}:{self.port}"
        try:
            self._client.start()
        except self._p.DiscoveryError as e:
            raise InputError(f"{where}: cannot read the sensor's calibration from http://{self.host}:"
                             f"{self.http_port}/netftapi2.xml ({e}); is it a Net F/T (--netft-http-port), or give "
                             "--netft-counts and --netft-units") from None
        except Exception as e:  # pynetft's configuration / socket errors
            raise InputError(f"{where}: cannot start the RDT stream ({e})") from None
        t_end = time.monotonic() + timeout_s
        # (a device that has sent MALFORMED_ENOUGH packets and no RDT record is refused at once: a count, not
        # a time, so the verdict does not depend on how fast this PC runs)
        while (not self._queue and time.monotonic() < t_end
               and self._client.health().malformed_count < MALFORMED_ENOUGH):
            time.sleep(0.005)
        if not self._queue:
            h = self._client.health()
            self.close()
            if h.sensor_configuration is None and "configuration" in h.last_error:
                raise InputError(f"{where}: cannot read the sensor's calibration from http://{self.host}:"
                                 f"{self.http_port}/netftapi2.xml ({h.last_error}); is it a Net F/T "
                                 "(--netft-http-port), or give --netft-counts and --netft-units")
            if h.malformed_count:
                raise InputError(f"{where}: the device answers, but not with RDT records ({h.malformed_count} "
                                 "malformed packets: wrong header or length); is it a Net F/T on its RDT port?")
            raise InputError(f"{where}: no RDT record within {timeout_s:g} s (is the Net F/T on, at this address, "
                             "with RDT on this UDP port, and no other client streaming?)")
        cfg = self._client.health().sensor_configuration
        if cfg is not None:
            c = cfg.calibration
            self.calibration = (c.counts_per_force_unit, c.counts_per_torque_unit, c.force_unit.value,
                                c.torque_unit.value, cfg.source.value)
            problem = calibration_problem(self.calibration[:2], self.calibration[2:4])
            if problem and cfg.source.value == "sensor":
                self.close()
                raise InputError(f"{where}: the sensor's calibration is not usable: {problem}")

    def drain(self):
        out = []
        q = self._queue
        while q:
            f, m, raw, t_arr, status, fu, tu = q.popleft()
            clipped = any(c >= INT32_MAX or c <= -INT32_MAX for c in raw)
            if not status_is_valid(status):
                w = (float("nan"),) * 6
            else:
                kf, kt = FORCE_UNITS_N.get(fu, float("nan")), TORQUE_UNITS_NM.get(tu, float("nan"))
                w = (f[0] * kf, f[1] * kf, f[2] * kf, m[0] * kt, m[1] * kt, m[2] * kt)
            out.append((w, t_arr, status, clipped))
        return out

    def health(self):
        return self._client.health()

    def close(self):
        try:
            self._client.stop()
        except Exception:
            pass


CALIBRATION_XML = """<?xml version="1.0" encoding="utf-8"?>
<netft><prodname>{prodname}</prodname><cfgcpf>{cpf:g}</cfgcpf><cfgcpt>{cpt:g}</cfgcpt><scfgfu>{fu}</scfgfu>\
<scfgtu>{tu}</scfgtu></netft>
"""


class CalibrationPage:
    """The simulated sensor's web page: ``/netftapi2.xml`` with its
    calibration on a TCP port (127.0.0.1), served by a thread."""

    def __init__(self, port, counts, units, prodname="robstiff simulated Net F/T"):
        import http.server
        import threading

        body = CALIBRATION_XML.format(prodname=prodname, cpf=counts[0], cpt=counts[1], fu=units[0],
                                      tu=units[1]).encode()

        class Handler(http.server.BaseHTTPRequestHandler):
            def do_GET(self):
                if self.path.split("?")[0] != "/netftapi2.xml":
                    self.send_error(404)
                    return
                self.send_response(200)
                self.send_header("Content-Type", "application/xml")
                self.send_header("Content-Length", str(len(body)))
                self.end_headers()
                self.wfile.write(body)

            def log_message(self, *args):
                pass

        try:
            self.server = http.server.ThreadingHTTPServer(("127.0.0.1", int(port)), Handler)
        except OSError as e:
            raise InputError(f"--netft-http-port {port}: cannot serve the calibration on TCP {port} "
                             f"({e.strerror})") from None
        self.port = self.server.server_address[1]
        self.thread = threading.Thread(target=self.server.serve_forever, kwargs={"poll_interval": 0.2}, daemon=True)
        self.thread.start()

    def close(self):
        self.server.shutdown()
        self.server.server_close()


class RDTServer:
    """The sensor's side of RDT on a UDP port (the simulated Net F/T and the
    tests' fake one): answers a start request by streaming to the client
    what ``send`` is given, stops on a stop request."""

    def __init__(self, port, host="127.0.0.1", counts_per_force=DEFAULT_COUNTS_PER_UNIT,
                 counts_per_torque=DEFAULT_COUNTS_PER_UNIT, units=("N", "N-m"), http_port=None):
        """``units``: the calibration's force and torque units (the records
        carry counts per those); ``http_port``: serve the calibration page
        on this TCP port (0: any free one; None: no page)."""
        self.units = tuple(units)
        self.page = None
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
        self.http_port = None
        if http_port is not None:
            try:
                self.page = CalibrationPage(http_port, (self.cpf, self.cpt), self.units)
            except InputError:
                self.sock.close()
                raise
            self.http_port = self.page.port

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
        kf, kt = FORCE_UNITS_N[self.units[0]], TORQUE_UNITS_NM[self.units[1]]
        data = raw if raw is not None else encode_record(self.rdt_sequence, self.ft_sequence, status, wrench,
                                                         self.cpf / kf, self.cpt / kt)
        try:
            self.sock.sendto(data, self.client)
        except OSError:
            return False
        return True

    def close(self):
        self.sock.close()
        if self.page is not None:
            self.page.close()
