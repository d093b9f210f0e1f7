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
        prev = self.clock.seq
        if msg.extra.get("new_session"):
            # the controller restarted its session (RSI: a new RSI_MOVECORR): its corrections count from the
            # pose it stands at now; the link learnt that start, the correction ramps to zero, then up again
            self.fault_on("sequence", f"{self.link.name}: a new session (sequence number {msg.seq} after {prev}); "
                                      f"its start {_fmt(msg.extra.get('start_deg'))} deg learnt again")
        v, dt = self.clock.accept(msg.seq, msg.tm_ms)
        if v == "duplicate":
            self.n.duplicates += 1
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
            self.n.lost += max(0, (msg.seq - prev) % 2**32 - 1)
        if v == "jump":
            self.n.jumps += 1
            restart = (msg.seq - (prev or 0)) % 2**32 >= 2**31 and msg.seq < 100  # numbering from the start again
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
            self.fault_on("clock", f"{self.link.name}: {what}; the reference advances by the sequence")
            self._steady_clock(why)
        else:
            self._steady = None
            self.ok_since_fault += 1
            if self.ok_since_fault >= CLEAR_MESSAGES and all(abs(c) < 1e-12 for c in self.comp.correction):
                for name in ("sequence", "clock", "target"):
                    self.fault_off(name, f"{name}: {CLEAR_MESSAGES} consistent messages and the correction at zero; "
                                         "compensating again")
        return True, dt

    def _steady_clock(self, why):
        """A clock fault on every message, each stamp stepping the same
        (within its 1 ms resolution) where the sequence steps one period:
        a steady clock at another cycle than --period-ms (Stream Motion's
        8 ms interpolation cycle, compensate's default 4 ms), named once a run
        with the period to set; meanwhile the correction stays at zero and
        the reference plays at the sequence's pace, --period-ms per message
        (half the program's feed at 8 ms)."""
        if why is None or why[0] != "step" or self._wrong_period_said:
            self._steady = None
            return
        step_ms, nominal_ms = float(why[1]), float(why[2])
        run = self._steady
        if run is None or nominal_ms != run[1] or abs(step_ms - run[0]) > 1.0:
            run = self._steady = [step_ms, nominal_ms, 0]
        run[2] += 1
        if run[2] >= WRONG_PERIOD_MESSAGES and run[0] > 0:
            self._wrong_period_said = True
            cycle_ms = run[0] / (run[1] / (self.s.period_s * 1e3))
            self.event(f"{self.link.name}: --period-ms is not the controller's cycle: its time stamps stepped "
                       f"{run[0]:g} ms a message, {run[2]} messages in a row, where --period-ms "
                       f"{self.s.period_s * 1e3:g} says {run[1]:g}; the correction stays at zero and the reference "
                       f"plays at {self.s.period_s * 1e3 / cycle_ms:.2f} times the program's speed: stop the "
                       f"run and start compensate again with --period-ms {cycle_ms:g} (FANUC Stream Motion: 8 ms, "
                       "or 4 ms on controllers that stream at 250 Hz; ABB EGM: 4 ms; KUKA RSI: 4 or 12 ms)")
