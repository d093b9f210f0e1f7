"""The wrist sensor's records in the compensator's loop
(cell/compensate.CompensatorLoop): every record received since the last
controller message through the guard (int32-clipped records and moment
spikes refused and counted) and the force filter, and the sensor's
faults: silent, invalid or rejected by the guard for ``sensor_timeout_s``
(silent: on this PC's clock and on the controller's), or no valid record
of that age at the controller's first message; after one, the chain
restarts on a new level only when two records in a row agree on it.  The
start's reading against the payload calibration and the record rate
against the configured one: cell/sensor_checks.py.

Units: wrenches in N and N*m, sensor frame; times in s.
"""


from robstiff_drake.model.compensator import guard_accepts

# The newest records the chain restarts on at the session's start (their median: one spike among them moves
# nothing); the rest of what piled up while the first message was awaited is dropped.
START_RECORDS = 8


def moments_within(w, ref, lim_Nm):
    """Whether every moment of wrench ``w`` is within ``lim_Nm`` (N*m) of
    ``ref``'s (the force part is model/compensator.guard_accepts')."""
    return abs(w[3] - ref[3]) <= lim_Nm and abs(w[4] - ref[4]) <= lim_Nm and abs(w[5] - ref[5]) <= lim_Nm


class SensorIntake:
    """The loop's sensor part (a base of CompensatorLoop: it reads and sets
    the loop's sensor state, counters and faults)."""

    def _start_on_recent_records(self):
        """At the controller's first message: the records that piled up
        while it was awaited (up to the reader's 4096, 4 s at 1 kHz: about
        25 ms of the chain's work, on the way to an answer due within a
        cycle) dropped but for the newest START_RECORDS, whose median
        restarts the guard and filter (the wrench at the start pose, not the
        one the sensor read when it was opened).  None of them valid and
        received within ``sensor_timeout_s`` (the sensor silent or invalid
        since it was opened, or only records older than that waiting: read
        at another pose, or none at all and the chain seeded on zeros): a
        sensor fault from the first message, the chain waiting for a level
        two records in a row agree on, as after a silence (the start's
        check against the payload calibration, cell/sensor_checks.py, made
        on that level at its message's pose)."""
        records = self.sensor.drain()
        self.n.sensor_records += len(records)
        fresh = self.pc_time() - self.s.sensor_timeout_s
        recent = [w for w, t_arr, _, clipped in records[-START_RECORDS:]
                  if not clipped and all(v == v for v in w) and t_arr >= fresh]
        if recent:
            w0 = [sorted(col)[len(col) // 2] if len(col) % 2 else
                  0.5 * (sorted(col)[len(col) // 2 - 1] + sorted(col)[len(col) // 2]) for col in zip(*recent)]
            self.comp.reseed(w0)
            self._check_start(w0)  # (against the payload calibration: cell/sensor_checks.py)
        else:
            self.fault_on("sensor", f"sensor: no valid record within {self.s.sensor_timeout_s * 1e3:.0f} ms of the "
                                    f"controller's first message ({len(records)} waiting, none usable): the chain "
                                    "waits for two records in a row that agree")
            self.pending_reseed = True
            self.reseed_candidate = None
            self.start_check_due = True

    def _read_sensor(self, t_now):
        """Feed every record received since the last cycle to the chain."""
        records = self.sensor.drain()
        got_good = False
        comp, lim = self.comp, self.s.max_jump_Nm
        # the records came between the last message and this one: stamped evenly over that span of the
        # controller's clock (the logs' clock; strictly increasing whatever this PC's scheduling did)
        t0, span = self.t_logged, self.t_session - self.t_logged
        n_rec = len(records)
        n_valid = 0  # (finite: neither NaN, status-flagged nor clipped; a spike the guard refuses is a record)
        for i, (w, t_arr, status, clipped) in enumerate(records):
            self.n.sensor_records += 1
            if clipped:
                self.n.sensor_clipped += 1
                if self.n.sensor_clipped <= 5 or self.n.sensor_clipped % 1000 == 0:
                    self.event(f"sensor: a record at the end of its int32 counts (the load beyond what the counts "
                               f"carry; {self.n.sensor_clipped} so far): refused")
                w = (float("nan"),) * 6
            finite = all(v == v for v in w)
            n_valid += finite
            if self.log is not None:  # (formatted after the answer has left: cycle's end)
                self._wrench_rows.append((t0 + span * (i + 1) / n_rec if span > 0 else t0 + 1e-6 * (i + 1), w))
            self.last_raw = list(w)
            if finite and self.pending_reseed:
                # the chain restarts on a new level only when two records in a row agree on it (within the
                # guard's jumps): the first record after a silence or a step may itself be a spike
                cand = self.reseed_candidate
                if cand is not None and guard_accepts(w, cand, comp.max_jump_N) and moments_within(w, cand, lim):
                    comp.reseed(list(w))
                    self.pending_reseed = False
                    self.reseed_candidate = None
                    self.fault_off("sensor", "sensor: valid records again; guard and filter restarted on the new "
                                             "reading")
                    self._records_returned()  # (a silence soon after: cell/sensor_checks.py)
                    if self.start_check_due:  # (no valid record at the start: its check on this first level)
                        self.start_check_due = False
                        self._check_start(list(w))
                else:
                    self.reseed_candidate = list(w)
            if finite and not self.pending_reseed and not moments_within(w, comp.held, lim):
                self.n.moment_spikes += 1
                if self.n.moment_spikes <= 5 or self.n.moment_spikes % 1000 == 0:
                    self.event(f"sensor: a moment jumped more than {lim:g} N*m from the last good sample: refused "
                               f"({self.n.moment_spikes} so far)")
                w = comp.held  # the guard's answer to a spike: the last good sample again
                accepted = False
                comp.sensor_sample(list(w))
            else:
                accepted = comp.sensor_sample(list(w)) if not self.pending_reseed else False
            if not finite:
                self.t_sensor_invalid = t_arr
            if accepted:
                got_good = True
                self.t_sensor_good = t_arr
                self.ts_sensor_good = self.t_session
                self.t_sensor_rejecting = None
                self.latest_sample_time = t_arr
            elif finite and self.t_sensor_rejecting is None:
                self.t_sensor_rejecting = t_arr
        to = self.s.sensor_timeout_s
        if self.t_sensor_rejecting is not None and t_now - self.t_sensor_rejecting > to and records:
            # the guard has refused every sample for a while: the force really changed, or the sensor is bad
            self.fault_on("sensor", f"sensor: the guard rejected every sample for {to * 1e3:.0f} ms (a jump of more "
                                    f"than {comp.max_jump_N:g} N or {lim:g} N*m)")
            if not self.pending_reseed:
                self.reseed_candidate = None
            self.pending_reseed = True
            self.t_sensor_rejecting = None
        # silence counts while the controller streams: after a gap in the controller's messages (this PC
        # or the network stalled) the sensor's records of that span may still be on their way; and it spans the
        # timeout on the controller's clock too (the arm moves on that clock: a simulated controller stepped in
        # lockstep on a loaded PC advances a cycle while the wall clock runs tens of ms, and the records of
        # that cycle may still wait for this process's reader thread)
        if not got_good and self.t_sensor_good is not None and t_now - max(self.t_sensor_good,
                                                                           self.t_sensor_grace) > to \
                and self.t_session - self.ts_sensor_good > to:
            invalid = self.t_sensor_invalid is not None and self.t_sensor_invalid >= self.t_sensor_good
            what = "invalid records (status flags, NaN or clipped), then none" if invalid else "no record"
            began = "sensor" not in self.faults
            self.fault_on("sensor", f"sensor: {what} for {to * 1e3:.0f} ms")
            if began:
                # (again soon after the records' return: a stream, or its valid records, slower than the timeout)
                self._silence_began(invalid)
            if not self.pending_reseed:
                self.reseed_candidate = None  # (kept while it waits: the next record may agree with it)
            self.pending_reseed = True
        if n_rec:
            self.t_logged = max(self.t_session, t0 + 1e-6 * n_rec)
        # (the valid records' rate on the controller's clock: cell/sensor_checks.py; before, invalid ones counted
        # too: a 1000 Hz stream with 15 of 16 records status-flagged read 1000 Hz, its filter fed at 62.5 Hz)
        self._count_records(n_valid, t_now)
