"""The controller's sequence numbers and clock as the compensator loop's
faults (a base of cell/compensate.CompensatorLoop): cell/session.
SessionClock's verdict on each message turned into what the loop does
with it: a duplicate or an older datagram dropped unanswered (counted; a
run of them behind the last one logged once), a new session (RSI), a
jump or a restart a sequence fault, a clock that disagrees with the
sequence a clock fault (each ramps the correction to zero), and the
faults cleared after CLEAR_MESSAGES consistent messages once the
correction is at zero.
"""

from robstiff_drake.cell.session import WRAP, _signed  # (the clocks' width and their signed step)

CLEAR_MESSAGES = 25  # consistent messages (0.1 s at 4 ms) before a sequence or clock fault clears
# clock faults in a row whose stamps all step by the same multiple of --period-ms that the loop names as a
# --period-ms that is not the controller's cycle (once a run): as many as clear a fault (0.1 s at 4 ms)
WRONG_PERIOD_MESSAGES = CLEAR_MESSAGES
# messages in a row behind the last one (each the next after the one before) that the loop logs once: more than
# a sequence jump's MAX_JUMP, fewer than the reorder window's 64 (cell/session.py)
BEHIND_LOGGED = 8


def _fmt(q_deg):
    return "(" + ", ".join(f"{v:.3f}" for v in q_deg) + ")" if q_deg else "?"


class SessionFaults:
    """The loop's session part (it reads and sets the loop's clock,
    counters and faults)."""

    def _session(self, msg):
        """The clock's verdict; False: drop the message unanswered."""
        prev, prev_tm = self.clock.seq, self.clock.tm
        self._watch_cycle(msg)
        if msg.extra.get("new_session"):
            # the controller restarted its session (RSI: a new RSI_MOVECORR): its corrections count from the
            # pose it stands at now; the link learnt that start, the correction ramps to zero, then up again
            self.fault_on("sequence", f"{self.link.name}: a new session (sequence number {msg.seq} after {prev}); "
                                      f"its start {_fmt(msg.extra.get('start_deg'))} deg learnt again")
        v, dt = self.clock.accept(msg.seq, msg.tm_ms)
        if v == "duplicate":
            if getattr(self.link, "seq_from_clock", False) and msg.tm_ms != prev_tm:
                self._between_cycles(msg, prev_tm)
            else:
                self.n.duplicates += 1  # (the same number and clock again: a true duplicate, or a replay)
            return False, 0.0
        if v == "old":
            self.n.old += 1
            self.n.lost = max(self.n.lost - 1, 0)  # (counted lost when a newer one came first)
            if self.clock.behind_run == BEHIND_LOGGED:  # (once a run: safe, nothing sent, but not silent)
                self.event(f"{self.link.name}: {BEHIND_LOGGED} messages in a row with sequence numbers behind the "
                           f"last one ({msg.seq - BEHIND_LOGGED + 1} to {msg.seq} after {prev}; "
                           f"{BEHIND_LOGGED * self.s.period_s * 1e3:.0f} ms of the controller's cycles): a restart "
                           "of the controller within its first messages? nothing is answered until its numbering "
                           f"passes {prev}")
            return False, 0.0
        if prev is not None and v in ("ok", "clock"):
            ds = (msg.seq - prev) % WRAP
            # (a controller named at another cycle, ``_watch_cycle``: its numbers skipped per message are not lost)
            lost = max(0, int(round(ds / self._cycle_periods)) - 1 if self._cycle_periods > 1 else ds - 1)
            self.n.lost += lost
            if self._cycle_run is not None:
                self._cycle_run[2] += lost
        if v == "jump":
            self.n.jumps += 1
            restart = (msg.seq - (prev or 0)) % WRAP >= WRAP // 2 and msg.seq < 100  # numbering from the start again
            what = "the controller restarted" if restart else "the sequence jumped"
            if self.clock.restarted_from is not None:  # (cell/session.py: a run numbered from the start again)
                what = (f"the controller restarted ({msg.seq - self.clock.restarted_from + 1} messages in a row "
                        f"numbered from {self.clock.restarted_from} again, behind the last one)")
            self.fault_on("sequence", f"{self.link.name}: {what} (sequence number {msg.seq} after {prev})")
        elif v == "clock":
            self.n.clock_faults += 1
            why = self.clock.clock_reason
            if why is not None and why[0] == "drift":
                # (every step within the tolerance, their sum not: a clock at another pace, or --period-ms wrong)
                what = (f"the controller's clock runs away from its sequence (its steps add up to {why[1]:+.1f} ms "
                        f"beyond {why[2]} periods of {self.s.period_s * 1e3:g} ms, more than the "
                        f"{why[3]:.3g} ms allowed; time stamp {msg.tm_ms} ms at sequence number {msg.seq}): "
                        "its clock, or --period-ms not the controller's cycle")
            else:
                what = (f"the controller's clock disagrees with its sequence (time stamp {msg.tm_ms} ms at sequence "
                        f"number {msg.seq})")
            # (cell/session.py: the reference at the slower of the clock and the sequence since the run's start,
            # whatever the verdict; a clock that stalls or goes back holds it, said here)
            self.fault_on("clock", f"{self.link.name}: {what}; the reference advances by the slower of the clock "
                                   "and the sequence")
            self._steady_clock(why, None if prev_tm is None else _signed(msg.tm_ms - prev_tm),
                               ((msg.seq - prev) % WRAP) * self.s.period_s * 1e3 if prev is not None else None)
        else:
            self._steady = None
            self.ok_since_fault += 1
            if self.ok_since_fault >= CLEAR_MESSAGES and all(abs(c) < 1e-12 for c in self.comp.correction):
                for name in ("sequence", "clock", "target"):
                    self.fault_off(name, f"{name}: {CLEAR_MESSAGES} consistent messages and the correction at zero; "
                                         "compensating again")
        return True, dt

    def _steady_clock(self, why, raw_step_ms=None, raw_nominal_ms=None):
        """A clock fault on every message, each stamp stepping the same
        (within its 1 ms resolution) where the sequence steps one period:
        a steady clock at another cycle than --period-ms (Stream Motion's
        8 ms interpolation cycle, compensate's default 4 ms), named once a run
        with the period to set; meanwhile the correction stays at zero and
        the reference plays at the sequence's pace, --period-ms per message
        (half the program's feed at 8 ms).  A clock whose every step is within
        the tolerance but whose sum runs away (the "drift" fault: --period-ms 8
        on a 4 ms controller) is named alike when its steady step is one of the
        protocol's cycles (``link.cycles_ms``; before, only "its clock, or
        --period-ms not the controller's cycle").  The reference follows the
        clock's steps there from the first message, not only once named
        (cell/session.py: the slower of the clock and the sequence; before,
        8 ms a 4 ms message, twice the program's feed, until named)."""
        if why is None or self._wrong_period_said:
            self._steady = None
            return
        if why[0] == "step":
            step_ms, nominal_ms = float(why[1]), float(why[2])
        elif raw_step_ms is not None and raw_nominal_ms:
            step_ms, nominal_ms = float(raw_step_ms), float(raw_nominal_ms)
        else:
            self._steady = None
            return
        run = self._steady
        if run is None or nominal_ms != run[1] or abs(step_ms - run[0]) > 1.0:
            run = self._steady = [step_ms, nominal_ms, 0]
        run[2] += 1
        if run[2] >= WRONG_PERIOD_MESSAGES and run[0] > 0:
            cycle_ms = run[0] / (run[1] / (self.s.period_s * 1e3))
            if why[0] != "step" and not any(abs(cycle_ms - c) < 0.5 for c in getattr(self.link, "cycles_ms", ())):
                return  # (a steady drift at no cycle of the protocol: a clock at another pace, its fault said)
            self._wrong_period_said = True
            self.event(f"{self.link.name}: --period-ms is not the controller's cycle: its time stamps stepped "
                       f"{run[0]:g} ms a message, {run[2]} messages in a row, where --period-ms "
                       f"{self.s.period_s * 1e3:g} says {run[1]:g}; the correction stays at zero and the reference "
                       f"plays at {min(1.0, self.s.period_s * 1e3 / cycle_ms):.2f} times the program's speed: stop the "
                       f"run and start compensate again with --period-ms {cycle_ms:g} (FANUC Stream Motion: 8 ms, "
                       "or 4 ms on controllers that stream at 250 Hz; ABB EGM: 4 ms; KUKA RSI: 4 or 12 ms)")

    def _between_cycles(self, msg, prev_tm):
        """A message whose clock is not the last one's but whose sequence
        number, the clock over --period-ms (RSI's IPOC), is: within the last
        one's cycle.  Dropped unanswered as a duplicate is (its answer would
        share the last one's cycle) but counted apart and said, a clock
        fault: a KRC's IPOC steps by whole cycles, so either --period-ms is
        not its cycle (``_watch_cycle`` names it) or the clock is not one."""
        self.n.between_cycles += 1
        step = _signed(msg.tm_ms - prev_tm)
        what = getattr(self.link, "clock_name", "clock")
        self.fault_on("clock", f"{self.link.name}: {what} {msg.tm_ms} ms is {step:+d} ms from the last one answered "
                               f"({prev_tm}), within the last one's cycle at --period-ms {self.s.period_s * 1e3:g}: "
                               f"dropped unanswered (not a duplicate: another {what}); a KRC's IPOC steps by whole "
                               "cycles (4 ms with IPO_FAST, 12 in IPO mode): --period-ms not its cycle, or a "
                               "clock that is not one")

    def _watch_cycle(self, msg):
        """A link whose sequence is its clock over --period-ms (RSI: the
        IPOC): the clock's steps, every message's, ahead of the verdict.
        ``WRONG_PERIOD_MESSAGES`` in a row of one step that is one of the
        protocol's cycles (``link.cycles_ms``) and not --period-ms is a
        controller at that cycle: the wrong period never runs silently (a
        longer cycle skipped numbers, counted as lost datagrams, with no
        fault; a shorter one put two messages on a number, dropped as
        duplicates).  Named once a run in one line with the --period-ms to
        set, a fault held for the run (the correction ramps to zero and
        stays: the loop was checked and tuned at --period-ms, not at the
        controller's cycle); the numbers skipped meanwhile are taken back
        from the lost count, and from then on a step of the cycle loses
        none."""
        if not getattr(self.link, "seq_from_clock", False) or self._cycle_periods != 1.0:
            return
        last, self._cycle_tm = self._cycle_tm, msg.tm_ms
        step = None if last is None else _signed(msg.tm_ms - last)
        if step is None or step <= 0:
            self._cycle_tm = last if step == 0 else msg.tm_ms  # (the same clock again: the run goes on)
            if step is not None and step < 0:
                self._cycle_run = None
            return
        run = self._cycle_run
        if run is None or step != run[0]:
            run = self._cycle_run = [step, 0, 0]  # [the step ms, messages, lost counted in the run]
        run[1] += 1
        T_ms = self.s.period_s * 1e3
        if run[1] < WRONG_PERIOD_MESSAGES or abs(step - T_ms) < 0.5 or \
                not any(abs(step - c) < 0.5 for c in getattr(self.link, "cycles_ms", ())):
            return
        self._cycle_periods = step / T_ms
        self.n.lost = max(0, self.n.lost - run[2])
        if step > T_ms:
            meant = (f"each message skipped {step / T_ms - 1:g} of its numbers: not lost datagrams (not counted "
                     "lost)")
        else:
            meant = (f"{1 - step / T_ms:.0%} of the messages fall within the last one's cycle and are dropped "
                     "unanswered (the controller's late-packet limit stops it)")
        what = getattr(self.link, "clock_name", "clock")
        self.fault_on("period", f"{self.link.name}: --period-ms is not the controller's cycle: its {what} stepped "
                                f"{step:g} ms a message, {run[1]} messages in a row, where --period-ms is {T_ms:g}; "
                                f"{meant}; a fault held for the run (the loop was checked and tuned for {T_ms:g} ms): "
                                f"stop the run and start compensate again with --period-ms {step:g}")
        self._cycle_run = None

