"""A run's counters in bounded memory, and one verdict on whether it
worked.

``Histogram``: a quantity per message (ms) in fixed bins (10 us up to
100 ms, then one overflow bin): its median, p99 and max over a run of any
length in 80 kB.

``verdict(...)``: "good", "degraded" or "poor", with the reasons, from the
counters of either side of the link (the compensator's or the simulated
controller's: the same names) and the estimate of the compensation lost:
the share of the correction (weighted by its size) that did not reach the
arm on time: in cycles the controller had no fresh answer for (late,
unanswered, lost), or computed from a stale wrench, or ramped down by a
fault.  A normal end (the controller stopping, the run's duration) is
not a fault.
"""

import math
from dataclasses import dataclass, field

import numpy as np

BIN_MS = 0.01
N_BINS = 10000  # 0-100 ms

# Thresholds of the verdict (fractions of the cycles or of the correction).
# ASSUMPTION: set so that a run whose compensation reached the arm within
# a few percent is "good": the paper's block test removes about 80 % of
# the error, so 5 % lost is small beside it and 20 % is not.
GOOD_LOST = 0.05
POOR_LOST = 0.20
GOOD_UNANSWERED = 0.01
# Late answers (sent after the next message had come, or more than the
# controller's cycle after their own message arrived: Counters.late,
# over_deadline): harmless to a controller that reads its targets a cycle
# later (EGM's transport delay), so only a larger share degrades the verdict.
GOOD_LATE = 0.05


class Histogram:
    def __init__(self):
        self.counts = [0] * (N_BINS + 1)
        self.n = 0
        self.max = float("nan")

    def add(self, ms):
        if ms != ms:
            return
        i = int(ms / BIN_MS)
        self.counts[i if 0 <= i < N_BINS else N_BINS] += 1
        self.n += 1
        if not self.max >= ms:
            self.max = ms

    def percentile(self, p):
        if not self.n:
            return float("nan")
        want = p / 100.0 * self.n
        acc = 0
        for i, c in enumerate(self.counts):
            acc += c
            if acc >= want and c:
                return min((i + 0.5) * BIN_MS, self.max) if i < N_BINS else self.max
        return self.max

    def summary(self):
        return {"median": self.percentile(50), "p99": self.percentile(99), "max": self.max}


def verdict(*, cycles, answered, late, unanswered, faults, lost_fraction, refused=0, stopped="",
            unanswered_good=GOOD_UNANSWERED, seen="", over_deadline=0, deadline_ms=float("nan")):
    """(word, reasons list, one line) of a run's health; ``late``: every
    answer the controller had no fresh target from at its next cycle, of
    which ``over_deadline`` left more than ``deadline_ms`` (its cycle)
    after their datagram arrived at this PC, the next message not yet
    read; ``stopped``: why
    the run stopped before its end ("": it did not); ``seen``: what this
    side saw of the other (the line ends with it: the compensator's and the
    controller's verdicts on one run count different things, and each says
    what it could see)."""
    reasons = [stopped] if stopped else []
    n = max(int(cycles), 1)
    missed = late + unanswered
    if refused:
        reasons.append(f"{refused} targets refused as unsafe")
    if faults:
        reasons.append(f"{faults} faults")
    if missed:
        how = (f"; {over_deadline} of them more than {deadline_ms:g} ms after their message arrived"
               if over_deadline else "")
        reasons.append(f"{missed} of {cycles} cycles without a fresh answer ({late} late{how}, {unanswered} unanswered)")
    lost_txt = "unknown" if not math.isfinite(lost_fraction) else f"{100 * lost_fraction:.1f} %"
    if refused or stopped or (math.isfinite(lost_fraction) and lost_fraction >= POOR_LOST) or missed > 0.2 * n:
        word = "poor"
    elif faults or unanswered > unanswered_good * n or late > GOOD_LATE * n or not (lost_fraction < GOOD_LOST):
        word = "degraded"
    else:
        word = "good"
    line = (f"health {word.upper()}: about {lost_txt} of the compensation lost"
            + (f" ({'; '.join(reasons)})" if reasons else "") + (f"; {seen}" if seen else ""))
    return word, reasons, line


class LostEstimate:
    """The correction's size summed over the cycles, and over those where
    it did not reach the arm as computed (see the module docstring)."""

    def __init__(self):
        self.total = 0.0
        self.lost = 0.0
        self.cycles = 0
        self.held_cycles = 0

    def add(self, corr_size, lost, held=False):
        """``held``: a fault held the correction at zero this cycle."""
        self.total += corr_size
        self.cycles += 1
        self.held_cycles += bool(held)
        if lost:
            self.lost += corr_size

    def fraction(self):
        """The correction-weighted share lost; with no correction computed
        in the whole run (a fault from the first message holds it at zero:
        a controller at another cycle than --period-ms), the share of the
        cycles a fault held (before: 0 %, for a run that compensated
        nothing)."""
        if self.total > 0:
            return self.lost / self.total
        return self.held_cycles / self.cycles if self.cycles else 0.0


def fraction_of(mask, weights):
    w = np.asarray(weights, dtype=float)
    return float(np.sum(w[np.asarray(mask, dtype=bool)]) / np.sum(w)) if np.sum(w) > 0 else 0.0


@dataclass
class Counters:
    """What the compensator's loop counts (bounded memory, whatever the
    run's length)."""

    MAX_EVENTS_KEPT = 1000  # events kept for the summary (all go to the log file and stderr)

    received: int = 0  # controller messages decoded
    answered: int = 0
    late: int = 0  # answers sent after the next message had arrived
    # answers sent before the next message was read but more than the controller's deadline (its cycle: the
    # link's ``answer_deadline_periods``) after their own datagram arrived (the kernel's stamp): the controller's
    # next cycle had passed without them (it runs on its own clock; only this PC saw the next message late)
    over_deadline: int = 0
    start_backlog: int = 0  # messages waiting before the first answer (the controller held its own pose: not late)
    skipped: int = 0  # messages never answered: a newer one was already waiting
    refused: int = 0  # targets the safety check refused
    unanswered_refused: int = 0  # messages left unanswered because no safe target was at hand
    lost: int = 0  # messages the sequence numbers say never arrived
    duplicates: int = 0
    old: int = 0
    jumps: int = 0
    clock_faults: int = 0
    gaps_over: int = 0  # gaps of more than 1.5 periods between messages
    sensor_records: int = 0
    sensor_clipped: int = 0  # records with a count at int32's end (the true force unknown)
    moment_spikes: int = 0
    saturated_cycles: int = 0
    saturation_onsets: int = 0
    stale_s: float = 0.0  # controller time with a stale or ramped-down correction
    fault_onsets: int = 0
    sensor_faults: int = 0  # of them, the sensor's (silent, invalid, rejected by the guard)
    events_dropped: int = 0
    compute_ms: Histogram = field(default_factory=Histogram)  # the message read -> its answer sent
    # the datagram's arrival at this PC (the kernel's time stamp) -> its answer sent: compute_ms and the time
    # it waited to be read (the loop's wake-up, a stall of the machine); empty where the system gives no stamp
    response_ms: Histogram = field(default_factory=Histogram)
    age_ms: Histogram = field(default_factory=Histogram)
    gap_ms: Histogram = field(default_factory=Histogram)
    gc_ms: Histogram = field(default_factory=Histogram)  # the loop's own collections, after an answer
    events: list = field(default_factory=list)  # (t_s, text), the first MAX_EVENTS_KEPT
    lost_estimate: LostEstimate = field(default_factory=LostEstimate)
