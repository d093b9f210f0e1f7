"""Two checks of the wrist sensor against what the compensator assumes of
it (a base of cell/compensate.CompensatorLoop, through cell/sensor_intake.
py), each a fault that holds the correction at zero for the rest of the
session (ramped down at the rate limit if it was not zero):

* **the start's reading against the payload calibration.**  At the
  controller's first message, the wrench the chain starts on (the median
  of the newest records) minus what the payload calibration predicts at
  the start pose (its bias and the payload's weight and moment in the
  sensor frame at the first message's joints: the chain's own gravity
  removal, model/compensator.GravityRemover, not another formula) is the
  process wrench the chain would compensate at once.  The check assumes
  the spindle off and the tool in the air at the start (the stream started
  before the approach): that wrench is then only the calibration's
  residual, the sensor's noise and its drift since the calibration.  A
  calibration page off by a factor, a sensor not tared, a wrong payload
  mass or centre of mass, a sensor mounted turned (where the turn changes
  the weight's direction in the sensor frame at that pose) read beyond
  ``start_tolerance_N`` (forces) or that force at the tool's lever
  (moments, as the moment guard's default: cell/loop_settings.py).
* **the record rate against the configured rate** (``sensor_rate_hz``):
  the force filter's coefficients are designed for it; a sensor at 125 Hz
  where 1000 Hz is configured puts the filter's corner 8 times lower (its
  lag: the loop's stability margin, cell/loop_guard.py), one at 2000 Hz
  twice higher (more noise through, less margin where the corner was
  chosen near the loop check's limit).  Valid records (neither NaN,
  status-flagged nor clipped: the filter runs on those) are counted over windows
  of RATE_WINDOW_S of the controller's clock (its messages' span: this
  PC's scheduling moves records between windows, never out of them), and
  RATE_WINDOWS windows in a row off by more than RATE_TOLERANCE the same
  way are the fault: a stall of this PC or a burst makes one window high
  and the next low, not two off the same way.  A window is off when its
  rate is off on the controller's clock and on this PC's (the arrivals of
  its first and last messages), as a silence is judged: they agree at a
  real controller; a simulated or scripted one on a loaded PC stretches
  its own clock.  A controller's fault (its silence, a restart, its
  clock) starts the count again; the sensor's own (a silence, invalid
  records) is cut out of the window, where a single dropout only pauses
  the count (of the wait before its fault, the sensor's timeout,
  SILENCE_KEPT_S stays counted).
* **a stream slower than the sensor's timeout** is a rate fault by
  itself, without waiting for windows: its records never come within the
  timeout, so the sensor's silence fault begins again as soon as the two
  agreeing records that ended the last one have come (its windows are
  then mostly cut out, and were judged only seconds later, the correction
  ramping in and out meanwhile).  RATE_WINDOWS silences in a row that each
  began within RECUR_TIMEOUTS timeouts (and two controller periods) of the
  records' return, beyond the row's first, are the fault; a dropout,
  however long, is one silence followed by records that stay.  A silence
  after invalid records counts as one without (the valid records are what
  the filter runs on).  Where the timeout is within JITTER_PERIODS record
  periods (a low --sensor-rate-hz), an honest stream's jitter makes such
  rows too: there the row is the fault only when its records also came
  more than RATE_TOLERANCE slower than the configured rate.  And
  FLAKY_SILENCES silences within FLAKY_SPAN_S, however long the records
  stay between them, are the fault too (a flaky link: each silence ramps
  the correction out and in again), with the same allowance.

Why the session stays faulted: neither a wrong calibration, tare, mass or
mounting nor a wrong rate setting heals during a run; the one reading that
tells them apart from a process force is the start's with the tool in the
air, and a rate at the edge would ramp the correction in and out.  The run
goes on at zero correction (the controller keeps its path, every other
check running) and its summary says why; fix the setting and start again.

Units: wrenches in N and N*m, sensor frame; rates in Hz; times in s.
"""

import math
from collections import deque

# ASSUMPTION (the start check's default force tolerance, N; compensate's --start-tolerance-N): what an honest
# start in the air reads beyond the calibration's prediction, summed: the calibration's residual (the payload
# file carries none as a key; `calibrate-payload examples/payload.csv` leaves 0.81 N rms, 2.5 N at 3 sigma),
# the sensor's noise on the median of START_RECORDS records (0.5 N a sample: the scenarios' sensor.noise_N),
# the bias's drift since the calibration (ASSUMPTION: 10 N, five times the 2 N (1 sigma) drift of docs/assumptions.md's
# identified models: a Net F/T warmed by the spindle, not re-tared since) and the
# arm at rest at the start (EGM, RSI and Stream Motion start from a stop: no inertial force), about 13 N, with a
# factor 2 of margin.  What it must catch is larger: a page 1000 times off reads the payload's weight (392 N
# for the IRB 6400's 40 kg spindle) as nearly nothing or 1000 times over, a payload mass 10 % off is 39 N.  What
# passes below it costs little: 25 N in its worst direction deflects the tool 0.12 mm at the tests' pose by
# the model (1000 N: 4.9 mm, cell/correction_bound.py).
DEFAULT_START_TOLERANCE_N = 25.0
# the option's range: below 5 N the residual, noise and drift above fault an honest start; above 5000 N (the
# largest bias a payload file may carry) nothing a sensor reads is refused
START_TOLERANCE_RANGE_N = (5.0, 5000.0)
MIN_LEVER_M = 0.1  # (the moment tolerance's shortest lever, as the moment guard's: cell/loop_settings.py)

# ASSUMPTION: the record rate may differ from --sensor-rate-hz by 20 % (the filter's corner moves as much: 2 Hz
# to 1.6-2.4 Hz at compensate's default).  By the loop model at the block test's start (IRB 6400, 4 ms; python
# benchmarks/sensor_rate_margin.py) the spectral radius per period, cutting at the check's 2 % damping, is
# 0.99706 and 0.99669 there against 0.99674 at the configured rate: the verdict unchanged; twice the rate (the
# corner at 4 Hz) is 1.00017, unstable; an 8 times slower stream stays stable by the model (0.99452) but its
# corner at 0.25 Hz makes the correction trail the cut's force by about 0.6 s.  Judged over windows long enough
# that counting is not the error (0.25 s: 250 records at 1 kHz, one record is 0.4 %) and short enough that a
# wrong rate is caught within half a second.
RATE_TOLERANCE = 0.2
RATE_WINDOW_S = 0.25
RATE_WINDOWS = 2
# Of the wait before the sensor's silence fault (its timeout without a record) the windows keep at most this (s):
# half the tolerance of a window, so a single dropout moves no window past it whatever --sensor-timeout-ms is,
# while a stream whose gaps exceed the timeout is judged on them (up to this each: 20 ms at the default timeout)
SILENCE_KEPT_S = 0.5 * RATE_TOLERANCE * RATE_WINDOW_S
# A silence that begins within this many sensor timeouts (and two controller periods: the silence is judged at
# the messages) of the records' return is the stream's own pace: the records of a stream slower than the timeout
# stop again exactly one timeout after the two agreeing records that ended the last silence; records that stay
# for twice as long came faster than the timeout for a while.  (Not a rate's tolerance: a stream that fails this
# is too slow for the timeout the user set, whatever its rate; a flaky link that drops out for longer than the
# timeout every few tens of ms is no usable stream either, and holding the correction at zero is the safe answer.)
RECUR_TIMEOUTS = 2.0
# An honest sensor's records come up to a record period early or late (the RDT stream's scheduling and the
# network's: an assumption, not a measured figure), so the gap between two is up to this many record periods.  Where
# --sensor-timeout-ms is within it (100 Hz or 125 Hz at the default 20 ms: 2 and 2.5 periods) that jitter alone
# makes silences, and, a few seconds into a run, three in a row soon after each return (100 Hz, each record
# +-10 ms at random: the rate's fault at message 989 and 937 in two of three 60 s runs, the stream at 95-108 Hz
# over every window; tests/test_checks_attacked.py); there the row is a fault only when its records also come
# slower than the configured rate by more than RATE_TOLERANCE (a stream slower than the timeout comes slower
# than 1 / timeout, which the option's check keeps below the configured rate: caught so, where its rate is off)
JITTER_PERIODS = 3.0
# Silences that begin this often (within FLAKY_SPAN_S of the controller's clock), however long the records stay
# between them, are a flaky link or sensor (a fault for the session, the jitter's allowance above as for a row): each
# silence ramps the correction to zero and the records' return ramps it in again, a square wave at the link's pace on
# the joints (30 ms dropouts every 130 ms: 7.7 Hz, near an arm's first modes).  A network hiccup, a few dropouts
# 0.1 s apart, is fewer.  (Before: no fault; the windows, with the silences cut out, read 788-1000 Hz.)
FLAKY_SILENCES = 5
FLAKY_SPAN_S = 1.0


def start_tolerances(tolerance_N, tool_m):
    """(force tolerance N, moment tolerance N*m): the moment's is the force's
    at the tool point's lever (``tool_m``, m; None: none), at least
    MIN_LEVER_M (the moment guard's default's rule)."""
    lever = math.sqrt(sum(float(v) * float(v) for v in tool_m)) if tool_m is not None else 0.0
    return float(tolerance_N), float(tolerance_N) * max(lever, MIN_LEVER_M)


def _norm(v):
    return math.sqrt(sum(float(x) * float(x) for x in v))


class SensorChecks:
    """The loop's sensor checks (a base of CompensatorLoop): ``_check_start``
    once on the wrench the chain starts on, ``_count_records`` every cycle."""

    def _init_sensor_checks(self):
        self.start_check = None  # summary.json's sensor_checks.start (None: not made: no valid record yet)
        self.start_check_due = False  # (no valid record at the start: the check waits for the chain's first level)
        self._rate_n = 0  # records in the window
        self._rate_span = 0.0  # the window's time so far on the controller's clock (t_session, s)
        self._rate_span_pc = 0.0  # and on this PC's (its messages' arrivals, s)
        self._rate_last = None  # (t_session, arrival) of the last message seen (None: none, or a window restarted)
        self._rate_tail = (0.0, 0.0)  # the window's time since its last record (controller's, PC's; s)
        self._rate_off = 0  # windows in a row off the same way (signed: + too fast, - too slow)
        self._silence_back = None  # when the records last returned after a sensor fault (t_session, s)
        self._silence_row = 0  # silences in a row each soon after the records' return (beyond the first)
        self._silence_from = (0.0, 0)  # the row's first silence (t_session, s) and the records counted since
        self._silence_invalid = 0  # the row's silences that followed invalid records (status flags, NaN, clipped)
        self._valid_total = 0  # valid records counted since the start
        self._silences = deque()  # (t_session s, _valid_total) at the silences begun within FLAKY_SPAN_S
        self.rate_check = {"configured_hz": self.s.sensor_rate_hz, "tolerance": RATE_TOLERANCE,
                           "window_s": RATE_WINDOW_S, "windows_judged": 0, "least_hz": None, "most_hz": None,
                           "silences_in_a_row": 0, "fault": None}

    def _check_start(self, w):
        """The wrench ``w`` the chain starts on against the payload
        calibration's prediction at the start pose (``self.q``): beyond the
        tolerance, the "sensor start" fault for the session, one line."""
        tol_N, tol_Nm = start_tolerances(self.s.start_tolerance_N, self.robot.payload.tool_point_m)
        process = self.comp.remove_gravity(list(w), self.q)  # measured - bias - weight: the chain's own
        predicted = [a - b for a, b in zip(w, process)]
        dF, dM = _norm(process[:3]), _norm(process[3:])
        self.start_check = {"read_N": _norm(w[:3]), "predicted_N": _norm(predicted[:3]), "apart_N": dF,
                            "read_Nm": _norm(w[3:]), "predicted_Nm": _norm(predicted[3:]), "apart_Nm": dM,
                            "tolerance_N": tol_N, "tolerance_Nm": tol_Nm, "passed": dF <= tol_N and dM <= tol_Nm}
        if self.start_check["passed"]:
            # a scale error (a page's units: N-mm read as N-m) shrinks a reading towards zero: it is seen only
            # where the prediction is beyond the tolerance (a tool pointing down with its centre of mass on the
            # sensor's axis reads nearly no moment: the torque's scale unchecked; docs/real_cell.md)
            unseen = [what for what, pred, tol in (("force", self.start_check["predicted_N"], tol_N),
                                                   ("torque", self.start_check["predicted_Nm"], tol_Nm))
                      if pred <= tol < math.inf]  # (math.inf: a program turned the check off)
            if unseen:
                # a note of the run's course, not a warning: nothing implausible was read, a common start pose
                # (the tool pointing down) only leaves a scale unseen; summary.json keeps it beside the check
                self.start_check["unchecked"] = (
                    f"the start pose cannot check the sensor's {' and '.join(unseen)} scale: the payload "
                    f"calibration predicts {self.start_check['predicted_N']:.4g} N and "
                    f"{self.start_check['predicted_Nm']:.4g} N*m there, within the tolerance ({tol_N:g} N, "
                    f"{tol_Nm:.3g} N*m): a calibration page's unit wrong (N-mm for N-m) would pass; start at a pose "
                    "where the payload's weight has a lever about the sensor (the tool tilted) to check it")
                self.note(f"sensor: {self.start_check['unchecked']}")
            return
        if dF > tol_N:
            what = (f"the sensor reads {_norm(w[:3]):.4g} N where the payload calibration predicts "
                    f"{_norm(predicted[:3]):.4g} N at the start pose ({dF:.4g} N apart, more than {tol_N:g} N)")
        else:
            what = (f"the sensor reads {_norm(w[3:]):.4g} N*m where the payload calibration predicts "
                    f"{_norm(predicted[3:]):.4g} N*m at the start pose ({dM:.4g} N*m apart, more than "
                    f"{tol_Nm:.3g} N*m)")
        self.fault_on("sensor start", f"sensor: {what}: calibration page, tare, payload mass or mounting wrong, "
                                      "or the tool not in the air (--start-tolerance-N); held for the session")

    def _count_records(self, n_rec, t_now):
        """This cycle's ``n_rec`` valid records into the rate's
        window, judged when it spans RATE_WINDOW_S of the controller's clock
        (``t_session``), its rate over that span and over the span of this
        PC's clock between the same messages' arrivals (``t_now``, s); a
        fault (for the session) after RATE_WINDOWS windows in a row off by
        more than RATE_TOLERANCE the same way on both clocks (as a silence is
        judged on both: a real controller runs on this PC's time; one
        simulated or scripted on a loaded PC stretches its own)."""
        if "sensor rate" in self.faults:
            return
        self._silence_from = (self._silence_from[0], self._silence_from[1] + n_rec)
        self._valid_total += n_rec
        last, self._rate_last = self._rate_last, (self.t_session, t_now)
        if any(name not in ("bound", "sensor start", "sensor") for name in self.faults):
            # (the controller's fault: a silence, a restart, a clock; its time not the stream's: counted anew)
            self._rate_n, self._rate_span, self._rate_span_pc, self._rate_off = 0, 0.0, 0.0, 0
            self._rate_last, self._rate_tail = None, (0.0, 0.0)
            return
        if self.pending_reseed or "sensor" in self.faults or last is None:
            # the sensor's own fault (a silence, invalid records) cut out of the window, not a new count, and of
            # the wait before it at most SILENCE_KEPT_S: a stream whose gaps exceed the timeout (slower than
            # 1/sensor_timeout_s) flaps between the fault and two agreeing records, and is judged on its time
            # between them (before: each fault restarted the count, no window was judged and the correction
            # ramped in and out for the run); a single dropout moves a window by half the tolerance at most
            self._rate_span -= max(0.0, self._rate_tail[0] - SILENCE_KEPT_S)
            self._rate_span_pc -= max(0.0, self._rate_tail[1] - SILENCE_KEPT_S)
            self._rate_tail = (0.0, 0.0)
            return  # (and the first message: the window counts the records of the messages after it)
        d, d_pc = self.t_session - last[0], t_now - last[1]
        self._rate_n += n_rec
        self._rate_span += d
        self._rate_span_pc += d_pc
        self._rate_tail = (0.0, 0.0) if n_rec else (self._rate_tail[0] + d, self._rate_tail[1] + d_pc)
        if self._rate_span < RATE_WINDOW_S or not n_rec:
            return  # (judged at a message with records: a wait without one may yet turn out a silence's)
        span, span_pc = self._rate_span, self._rate_span_pc
        rate = self._rate_n / span
        rate_pc = self._rate_n / span_pc if span_pc > 0 else math.inf
        self._rate_n, self._rate_span, self._rate_span_pc = 0, 0.0, 0.0
        rc = self.rate_check
        rc["windows_judged"] += 1
        rc["least_hz"] = rate if rc["least_hz"] is None else min(rc["least_hz"], rate)
        rc["most_hz"] = rate if rc["most_hz"] is None else max(rc["most_hz"], rate)
        conf = self.s.sensor_rate_hz
        off = _off(rate, conf) if _off(rate, conf) == _off(rate_pc, conf) else 0
        self._rate_off = off if off == 0 or self._rate_off * off <= 0 else self._rate_off + off
        if abs(self._rate_off) >= RATE_WINDOWS:
            rc["fault"] = rate
            self.fault_on("sensor rate", f"sensor: its records come at {rate:.4g} Hz on the controller's clock "
                                         f"({rate_pc:.4g} Hz on this PC's; {RATE_WINDOWS} windows of "
                                         f"{RATE_WINDOW_S:g} s in a row), not the {conf:g} Hz configured (more than "
                                         f"{RATE_TOLERANCE:.0%} off: the force filter is designed for that rate): "
                                         "the sensor's RDT rate or --sensor-rate-hz wrong; held for the session")


    def _records_returned(self):
        """Two agreeing records ended the sensor's fault (cell/sensor_intake.py)."""
        self._silence_back = self.t_session

    def _silence_began(self, invalid=False):
        """The sensor's silence fault has just begun (no valid record within
        the timeout; ``invalid``: invalid records came, then none): soon
        after the records' return, RATE_WINDOWS times in a row, the "sensor
        rate" fault for the session (a stream, or its valid records, slower
        than the timeout), its rate the records counted since the row's
        first silence over the controller's time since.  (Before, a silence
        after invalid records was not counted: a 1000 Hz stream with one
        valid record in 32, the rest status-flagged, flapped between the
        sensor's fault and two agreeing records for the run, 86 faults in
        6 s, the correction ramping in and out, and its windows read 1000
        Hz: counted, valid or not.)  And FLAKY_SILENCES silences within
        FLAKY_SPAN_S, however soon after the returns, are the fault too (a
        flaky link)."""
        if "sensor rate" in self.faults:
            return
        to, t = self.s.sensor_timeout_s, self.t_session
        conf = self.s.sensor_rate_hz
        jitter_silences = to * conf <= JITTER_PERIODS  # (an honest stream's jitter makes silences at this timeout)
        recent = self._silences
        recent.append((t, self._valid_total))
        while t - recent[0][0] > FLAKY_SPAN_S:
            recent.popleft()
        if len(recent) >= FLAKY_SILENCES:
            span = t - recent[0][0]
            rate = (self._valid_total - recent[0][1]) / span if span > 0 else 0.0
            if not (jitter_silences and rate >= (1 - RATE_TOLERANCE) * conf):
                self.rate_check["fault"] = rate
                self.fault_on("sensor rate", f"sensor: no valid record for longer than the sensor timeout "
                                             f"({to * 1e3:.0f} ms) {len(recent)} times in {span:.3g} s of the "
                                             f"controller's clock (valid records at {rate:.4g} Hz over that span; "
                                             f"{conf:g} Hz configured): a flaky link or sensor, or "
                                             "--sensor-timeout-ms too short; held for the session")
                return
        soon = RECUR_TIMEOUTS * to + 2.0 * self.s.period_s
        if self._silence_back is not None and t - self._silence_back <= soon:
            self._silence_row += 1
            self._silence_invalid += bool(invalid)
        else:
            self._silence_row, self._silence_from, self._silence_invalid = 0, (t, 0), int(bool(invalid))
        rc = self.rate_check
        rc["silences_in_a_row"] = max(rc["silences_in_a_row"], self._silence_row + 1)
        if self._silence_row < RATE_WINDOWS:
            return
        span, n = t - self._silence_from[0], self._silence_from[1]
        rate = n / span if span > 0 else 0.0
        if jitter_silences and not self._silence_invalid and rate >= (1 - RATE_TOLERANCE) * conf:
            return  # (silences an honest stream's jitter makes at this timeout, at its configured rate: row goes on)
        rc["fault"] = rate
        what = "its records stopped" if not self._silence_invalid else \
            (f"its valid records stopped ({self._silence_invalid} of the times after invalid ones: status flags, NaN "
             "or clipped)")
        self.fault_on("sensor rate", f"sensor: {what} for longer than the sensor timeout "
                                     f"({to * 1e3:.0f} ms) {self._silence_row + 1} times in a row, each within "
                                     f"{soon * 1e3:.0f} ms of their return ({n} valid records in "
                                     f"{span:.3g} s of the controller's clock: {rate:.3g} Hz; {conf:g} Hz "
                                     "configured): the sensor's RDT rate or status, its network, or --sensor-rate-hz "
                                     "or --sensor-timeout-ms wrong; held for the session")


def _off(rate_hz, configured_hz):
    """+1 above the configured rate by more than RATE_TOLERANCE, -1 below, 0 within."""
    return 1 if rate_hz > configured_hz * (1 + RATE_TOLERANCE) else \
        -1 if rate_hz < configured_hz * (1 - RATE_TOLERANCE) else 0
