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
setpoint (ASPos; AIPos when the controller sends no setpoints) of the
session's first message, as ROS-Industrial's kuka_rsi_hw_interface takes
its initial positions.  The session clock is the IPOC: sequence number
IPOC / period, clock IPOC (ms).

A restart.  When the controller starts RSI again (a new RSI_MOVECORR) its
corrections count from the pose it stands at then, and its IPOC jumps (a
new epoch).  A message whose IPOC is further from the last than the session
check's window (more than ``session.MAX_JUMP`` periods ahead, or more than
``session.REORDER_WINDOW`` behind) starts a new session: the start is learnt
again from that message, the message says so (``extra["new_session"]``) and
the loop ramps the correction to zero and then up again from zero; a late
datagram of the session before is dropped (counted as malformed).  Every
answer is checked on the pose the controller will command, its start plus
the AK decoded from the answer's bytes (``commanded_deg``), and the
controller's setpoint must be its start plus one of the recent corrections
sent (``answer_problem``): a setpoint that is not says the PC's start is not
the controller's, and nothing more is answered.

Lost datagrams.  Datagrams lost in a row make the IPOC skip beyond the
window too while the controller keeps its session and its start; its
setpoint then is its start plus the last AK it read, the very pose a
restarted controller stands at, so one message cannot tell the two apart,
and an answer from the wrong start moves the arm by the path travelled
since the session's start (2.4 deg on a 2 deg/s path: tests/
test_cell_review.py).  A forward skip no longer than the time that passed
at this PC (the datagrams' arrival stamps, ``LOST_ALIKE_MARGIN_MS`` more)
may be lost datagrams: until a setpoint shows the new start (it is the new
start plus an AK sent and not the old start plus any), every answer must
also be safe as the old session would read it, the old start plus the same
AK (else refused: the controller stops); a second such skip before a
setpoint told the first apart keeps both starts (every start not ruled
out, at most ``MAX_STARTS_UNRULED``: beyond, nothing is answered), so the
session's own start is never forgotten.  A skip beyond that, or backwards,
is a new IPOC epoch: a restart, when the controller fell silent before it
(more than ``RESTART_SILENCE_PERIODS``); at the period's cadence it is
treated as the lost datagrams are (a time stamp that jumped while the
controller kept its session).  So a restart whose IPOC goes on with the
time, or that comes without a silence, at a pose away from the old start,
is not answered.

The IPOC's wrap.  A millisecond counter of 32 bits wraps after 49.7 days of
the controller's uptime (``IPOC_WRAPS_MS``: the assumption).  The IPOC
before near the wrap and the next near 0, going on with the time passed
here, is read as the counter gone round: the same session (or, past
``MAX_JUMP``, lost datagrams as above), not a restart; every answer is
checked as any other (a restart that happens to land there is the case
above: the setpoint check tells it).
"""

import math
import time
from collections import deque

from robstiff_drake.cell.link import ControllerSide, Message, MessageError, PCLink
from robstiff_drake.cell.safety import UnsafeTarget, unsafe_reason
from robstiff_drake.cell.rsi_codec import (  # noqa: F401 (the codec's names, read through this module too)
    AXES, MAX_BYTES, _axes, _fmt_deg, _ipoc, _parse, decode_rob, decode_sen, encode_rob, encode_sen)
from robstiff_drake.cell.rsi_layout import RobLayout
from robstiff_drake.cell.session import MAX_JUMP, REORDER_WINDOW, WRAP

RECENT_CORRECTIONS = 64  # the answers (4 ms each: 0.26 s) a controller's setpoint may still reflect
# A forward IPOC skip (ms) no longer than the time that passed at this PC between the two datagrams' arrivals plus
# this may be lost datagrams of the same session, not a new epoch.  ASSUMPTION: a controller's datagrams reach
# this PC within a second of their IPOC's spacing (a wired link delays them by milliseconds).
LOST_ALIKE_MARGIN_MS = 1000.0
# A new IPOC epoch is taken for a restart only after the controller fell silent for more than this many periods
# (the datagrams' arrival stamps): a restart stops RSI and starts it again (RSI_OFF, then RSI_ON/RSI_MOVECORR in the
# KRL program), a controller that kept its session sends on at its period.  An IPOC that jumps back, or further ahead
# than the time passed, at the period's cadence (a corrupted or reset time stamp) is then no restart taken on trust:
# the session before stays among the starts not ruled out (as after lost datagrams) until a setpoint tells them
# apart.  ASSUMPTION: no public source at hand gives the shortest silence of an RSI restart; if a real one is shorter,
# that restart is answered only where safe from the old start too, else refused (the controller stops): the safe
# side.  Before (fuzz, tests/test_compensate_fuzz.py): such a jump moved the arm 2.4 deg back along a 2 deg/s path.
RESTART_SILENCE_PERIODS = 5
# The starts a controller may still count from after IPOC skips that may be lost datagrams (each kept until a
# setpoint rules it out): beyond this many in a row nothing is answered (the check's cost stays bounded).
MAX_STARTS_UNRULED = 8
# The IPOC's wrap (ms): after the largest value the counter starts from 0 again.  ASSUMPTION: no public source at
# hand states the IPOC's width (KUKA's RSI manual calls it a time stamp; ROS-Industrial's kuka_rsi_hw_interface reads
# it into a 64-bit integer; a third-party note on KUKA's $ROB_TIMER, a 1 ms counter, gives 32 bits signed, back to 0
# after 2**31 - 1).  A controller whose IPOC is a 32-bit (or 31-bit) millisecond counter wraps every 49.7 (24.9) days
# of uptime; the next IPOC is then small, a backwards jump that read plainly is a new epoch (a restart).  A previous
# IPOC that reaches one of these wraps, going on with the time passed at this PC (module docstring: at most
# MAX_JUMP periods, or the lost datagrams' rule), is the same counter gone round: the session goes on (or, past
# MAX_JUMP, the lost-datagram case).  An IPOC of 2**32 ms or more says the counter is wider: no wrap is looked for.
IPOC_WRAPS_MS = (2**32, 2**31)
# The cycles a KRC runs RSI at (ms): 4 with IPO_FAST, 12 in IPO mode (KUKA.RobotSensorInterface manual; docs/
# real_cell.md).  Its IPOC is the interpolation cycle's millisecond time stamp and steps by the cycle (ROS-
# Industrial's kuka_rsi_simulator steps it by its cycle_time), so a run of IPOC steps of one of these that is not
# --period-ms is a controller at another cycle (cell/session_faults.py names it with the --period-ms to set).
CYCLES_MS = (4.0, 12.0)



class RsiLink(PCLink):
    """The PC's side of RSI: the controller's <Rob> on ``port``, answered
    with <Sen> axis corrections from the start position."""

    name = "RSI"
    option = "--listen-port"
    # the session's sequence is the clock (the IPOC) over --period-ms: a wrong --period-ms is no clock fault here
    # but sequence numbers skipped or shared (cell/session_faults.py reads the IPOC's steps instead)
    seq_from_clock = True
    cycles_ms = CYCLES_MS
    clock_name = "IPOC"
    # RSI expects the <Sen> with its IPOC back within the interpolation cycle; a later one is a late packet,
    # counted towards the ETHERNET object's limit that stops the robot (module docstring; docs/real_cell.md)
    answer_deadline_periods = 1.0

    def __init__(self, port, controller, period_s):
        super().__init__(port, controller)
        self.period_ms = period_s * 1e3
        self.start_deg = None
        self.session = 0  # RSI sessions seen (a restart starts another)
        self.last_seq = None  # the newest IPOC / period of this session
        self.previous_seq = None  # ... of the session before
        self._aks = deque(maxlen=RECENT_CORRECTIONS)  # corrections sent in this session (deg), newest last
        self._t_last = None  # when the newest datagram of this session arrived (s, time.monotonic)
        # (the session before's start, its recent corrections) while a new session may be lost datagrams instead
        self._maybe_old = None
        self._doubt = ""  # (why the starts in _maybe_old are not ruled out: said in a refusal)
        self._ipoc_last = None  # the newest IPOC of this session (ms), counted on across wraps
        # the session's IPOC grid's phase (ms): its first IPOC modulo the period.  The sequence number is the IPOC's
        # cycles from it (``_seq``): a KRC's IPOC steps by whole cycles from wherever its session began, so an IPOC
        # half a cycle off the grid 0, T, 2T.. is honest (before, round(IPOC / period) tied to even there and every
        # other message of such a session was a "duplicate", dropped unanswered: tests/test_cell_rsi_period.py)
        self._phase_ms = 0.0
        self._ipoc_offset_ms = 0  # what the wraps seen add to a raw IPOC (ms)
        self._last_wrap_ms = None  # the wrap last crossed (one of IPOC_WRAPS_MS)
        self.wraps = 0  # IPOC wraps crossed
        self._layout = None  # the controller's datagram layout, learnt from one the XML parser accepted
        self._learn_in = 0  # datagrams the parser reads before the next try to learn a layout

    def _decode_rob(self, data):
        """decode_rob's result, read by the learnt layout when the datagram
        matches it (rsi_layout: the same values), else by the XML parser
        (and the layout learnt again from what it accepted)."""
        if self._layout is not None and len(data) <= MAX_BYTES:
            got = self._layout.read(data)
            if got is not None:
                return got
        got = decode_rob(data)
        if self._learn_in <= 0:  # (a layout it cannot learn is tried again 1 s of messages later: bounded cost)
            self._layout = RobLayout.learn(data, "Rob", ("AIPos", "ASPos"), AXES, got)
            self._learn_in = 0 if self._layout is not None else 250
        else:
            self._learn_in -= 1
        return got

    def _new_session(self, here_deg, seq, lost_alike=False):
        # (a second skip while the first is not yet told apart: the controller may still count from any start not
        # ruled out, the one before the first skip too; each is kept until a setpoint rules it out)
        # (beyond MAX_STARTS_UNRULED: the first and the newest kept, and nothing answered until a restart is plain)
        olds = (self._maybe_old or []) + [(list(self.start_deg), list(self._aks))] if lost_alike else None
        self._maybe_old = olds if olds is None or len(olds) <= MAX_STARTS_UNRULED + 1 else \
            olds[:1] + olds[-MAX_STARTS_UNRULED:]
        self.previous_seq = self.last_seq
        self.start_deg = list(here_deg)  # RSI_MOVECORR's start: corrections are from here
        self.session += 1
        self.last_seq = seq
        self._aks.clear()
        self.commanded = [list(here_deg)] * 2  # at its start the controller stands still there

    def _unwrap(self, ipoc, now):
        """The IPOC counted on across its wraps (ms): ``ipoc`` plus the
        wraps seen, one more when the newest IPOC reaches a wrap of
        IPOC_WRAPS_MS and ``ipoc`` goes on from it with the time passed here,
        one fewer for a late datagram of before the last wrap."""
        u = ipoc + self._ipoc_offset_ms
        if self._ipoc_last is None or ipoc >= IPOC_WRAPS_MS[0]:
            return u
        d = u - self._ipoc_last
        if d < -REORDER_WINDOW * self.period_ms:
            waited_ms = (now - self._t_last) * 1e3
            for w in IPOC_WRAPS_MS:  # (the raw IPOC before the newest was below w: a w-counter's)
                if self._ipoc_last - self._ipoc_offset_ms < w and \
                        0 < d + w <= max(MAX_JUMP * self.period_ms, waited_ms + LOST_ALIKE_MARGIN_MS):
                    self._ipoc_offset_ms += w
                    self._last_wrap_ms = w
                    self.wraps += 1
                    return u + w
        elif d > MAX_JUMP * self.period_ms and self._last_wrap_ms is not None and \
                -REORDER_WINDOW * self.period_ms <= d - self._last_wrap_ms < 0:
            return u - self._last_wrap_ms  # a late datagram of before the wrap
        return u

    def _seq(self, ipoc_u):
        """The sequence number of an IPOC (counted on across wraps, ms): its cycles from the session's grid."""
        return int(math.floor((ipoc_u - self._phase_ms) / self.period_ms + 0.5))

    def decode(self, data):
        ipoc, actual, setpoint = self._decode_rob(data)
        here = setpoint if setpoint is not None else actual
        now = self.arrival_s if self.arrival_s is not None else time.monotonic()
        ipoc_u = self._unwrap(ipoc, now)
        if self.start_deg is None:
            self._phase_ms = ipoc_u % self.period_ms
        seq = self._seq(ipoc_u)
        new = False
        if self.start_deg is None:
            self._new_session(here, seq)
            self._t_last = now
            self._ipoc_last = ipoc_u
        else:
            ds = seq - self.last_seq
            if -REORDER_WINDOW <= ds <= MAX_JUMP:
                if seq > self.last_seq:
                    self._t_last = now
                    self._ipoc_last = ipoc_u
                self.last_seq = max(self.last_seq, seq)
            elif self.previous_seq is not None and abs(seq - self.previous_seq) <= REORDER_WINDOW:
                raise MessageError(f"IPOC {ipoc}: a late datagram of the RSI session before the restart")
            else:
                # (a forward skip within the time that passed here may be datagrams lost in a row: docstring)
                waited_ms = (now - self._t_last) * 1e3
                lost_alike = 0 < ds * self.period_ms <= waited_ms + LOST_ALIKE_MARGIN_MS
                unbroken = waited_ms <= RESTART_SILENCE_PERIODS * self.period_ms  # (no restart's silence before it)
                self._phase_ms = ipoc_u % self.period_ms  # (a new epoch: its own grid)
                seq = self._seq(ipoc_u)
                self._new_session(here, seq, lost_alike=lost_alike or unbroken)
                self._doubt = ("no more than the time that passed here: lost datagrams, perhaps" if lost_alike else
                               f"{waited_ms:.0f} ms after the last datagram, without a restart's silence: a time "
                               "stamp that jumped, perhaps")
                self._t_last = now
                self._ipoc_last = ipoc_u
                new = True
        extra = {"session": self.session, "setpoint_deg": setpoint, "new_session": new,
                 "start_deg": list(self.start_deg)}
        # (the clock the session check reads: the IPOC counted on across a wrap, modulo session.WRAP as it reads it)
        return Message(seq, ipoc_u % WRAP, actual, echo=ipoc, extra=extra)

    def encode(self, message, targets_deg):
        return encode_sen(message.echo, [t - s for t, s in zip(targets_deg, self.start_deg)])

    def commanded_deg(self, message, data):
        _, ak = decode_sen(data)
        self._last_ak = ak
        return [s + a for s, a in zip(self.start_deg, ak)]  # AXISCORR, absolute: the start plus AK

    def send_targets(self, message, targets_deg, envelope):
        if self._maybe_old and message.extra.get("session", self.session) == self.session:
            # (perhaps lost datagrams, not a restart: the pose the controller commands if it kept an old start)
            if len(self._maybe_old) > MAX_STARTS_UNRULED:
                raise UnsafeTarget(f"RSI: {len(self._maybe_old)} IPOC skips in a row, none told apart from lost "
                                   "datagrams by a setpoint: the controller's start is not known; not answered")
            for old_start, _ in self._maybe_old:
                pose = [o + t - s for o, t, s in zip(old_start, targets_deg, self.start_deg)]
                reason = unsafe_reason(pose, envelope)
                if reason is not None:
                    raise UnsafeTarget(f"RSI: the IPOC skipped {message.seq - self.previous_seq} cycles, "
                                       f"{self._doubt}, not a restart; from the old start {_fmt_deg(old_start)} the "
                                       f"controller would command {reason}")
        sent = super().send_targets(message, targets_deg, envelope)
        if sent:
            self._aks.append(self._last_ak)
        return sent

    def answer_problem(self, message, envelope):
        if message.extra.get("session", self.session) != self.session:
            return "a message of the RSI session before the controller's restart (its answer would use the new start)"
        sp = message.extra.get("setpoint_deg")
        if sp is None:
            return None
        tol = envelope.step_tol_deg or envelope.reference_tol_deg
        start = self.start_deg

        def near(s, ak):
            return all(abs(p - (x + a)) <= t + 1e-6 for p, x, a, t in zip(sp, s, ak, tol))

        for ak in [[0.0] * 6, *reversed(self._aks)]:
            if near(start, ak):
                # (beyond MAX_STARTS_UNRULED some starts were dropped: none of them may be ruled out by this one)
                if self._maybe_old and len(self._maybe_old) <= MAX_STARTS_UNRULED and not any(
                        near(old_start, a) for old_start, old_aks in self._maybe_old for a in [*old_aks, *self._aks]):
                    self._maybe_old = None  # the setpoint shows the new start plus an AK sent: a restart
                return None
        err = max(range(6), key=lambda j: min(abs(sp[j] - start[j] - a[j]) for a in [[0.0] * 6, *self._aks]))
        return (f"RSI: the controller's setpoint q{err + 1} {sp[err]:.4f} deg is not its start {start[err]:.4f} plus "
                "any correction sent: the controller counts from another start than the PC's; not answered")


class RsiControllerLink(ControllerSide):
    """The controller's side (a simulated KRC): sends <Rob> to the PC at
    ``host:port`` every cycle and reads the <Sen> answers (targets = start +
    AK, the start being the setpoint of its first message, and again after
    ``restart``)."""

    name = "RSI"

    def __init__(self, host, port, period_s, ipoc0=1_000_000):
        super().__init__(("127.0.0.1" if host in ("127.0.0.1", "localhost") else "", 0), (host, port))
        self.period_ms = period_s * 1e3
        self.ipoc0 = ipoc0
        self.start = None

    def send_state(self, k, joints_deg, planned_deg, tm_ms, bad_type=False):
        if self.start is None:
            self.start = list(planned_deg)  # RSI_MOVECORR's start: the setpoint it stands at
        ipoc = (self.ipoc0 + int(round(tm_ms))) % IPOC_WRAPS_MS[0]  # (a 32-bit counter: rsi.IPOC_WRAPS_MS)
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
