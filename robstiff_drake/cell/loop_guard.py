"""``robstiff compensate``'s check, before anything is streamed, that the
correction loop it is about to close is stable at the start pose and at
poses along the reference (model/loop_check.py: the linear loop model in
plain numpy, in air and at a nominal process stiffness, with the margin of
2 % modal damping on the drives-closed modes; the drives tuned at the
start pose).

A loop the model predicts unstable is refused in one line (exit status 2)
naming the pose (along the reference: its row and time), the mode, the
spectral radius and the largest ``--cutoff-hz`` the model finds stable there; ``--allow-unstable-loop`` runs it
anyway with a warning in the text, the log's events and summary.json.

Units: the pose in the controller's degrees at the interface (the
pendant's), the model's radians inside.
"""

import time

import numpy as np

from robstiff_drake.errors import InputError
from robstiff_drake.model import joint_dynamics
from robstiff_drake.model import kinematics as kin
from robstiff_drake.model import loop_check
from robstiff_drake.model.servo import ServoParameters

# The tool point must move this far along the reference (m) for its start to have a feed direction.
FEED_DISTANCE_M = loop_check.FEED_DISTANCE_M
# The poses along a reference the loop is checked at beyond its first row: this many, evenly spaced in its rows
# (the last row among them).  The arm's mass matrix changes smoothly along a path; a path whose poses change more
# between samples than this catches is checked at the worst of those sampled (the result's "along_path" lists them).
PATH_CHECK_SAMPLES = 11
OVERRIDE = "--allow-unstable-loop"


def servo_parameters(servo):
    """ServoParameters from compensate's --servo (interpolator dead time ms,
    position gain 1/s, velocity bandwidth Hz, velocity feed-forward and,
    optionally, the velocity loop's integral corner Hz), or the
    scenarios' assumed IRC5 servo (diagrams/scenario_schema.ServoConfig, with its
    sources) when not given."""
    from robstiff_drake.diagrams.scenario_schema import ServoConfig

    s = ServoConfig()
    if servo is None:
        delay_ms, kp, bw, ff = s.interpolator_delay_ms, s.position_gain_per_s, s.velocity_bandwidth_hz, \
            s.velocity_feedforward
        ki = s.velocity_integral_hz
    else:
        delay_ms, kp, bw, ff = (float(v) for v in servo[:4])
        ki = float(servo[4]) if len(servo) > 4 else s.velocity_integral_hz
    # an integral corner not given: chosen from the arm's first antiresonance at the start pose, at most
    # ServoConfig's (model/servo.integral_corner_hz), as the scenarios' plant chooses it
    given = servo is not None and len(servo) > 4
    return ServoParameters(position_gain_per_s=kp, velocity_bandwidth_hz=bw, velocity_feedforward=ff,
                           interpolator_delay_s=delay_ms / 1e3, velocity_integral_hz=ki,
                           integral_rule="stated" if given else "antiresonance")


def feed_direction(robot, tool_m, q_model_rad, block=4096, to_model=None):
    """The tool point's first horizontal motion along a reference (model
    angles, (N, 6) rad; or other angles and ``to_model``, their map to the
    model's radians): the unit vector (2,) from the start to the first row
    at least FEED_DISTANCE_M away; None when it never moves.  Blocks of
    ``block`` rows from the start until one holds such a row (a long
    reference's kinematics are not held at once)."""
    q = np.asarray(q_model_rad, dtype=float)
    p0 = None
    for start in range(0, len(q), block):
        qb = q[start:start + block]
        p = kin.tool_position(robot.dh, qb if to_model is None else to_model(qb), tool_m)
        if p0 is None:
            p0 = p[0, :2].copy()
        d = p[:, :2] - p0
        far = np.nonzero(np.linalg.norm(d, axis=1) >= FEED_DISTANCE_M)[0]
        if len(far):
            return d[far[0]] / np.linalg.norm(d[far[0]])
    return None


def _pose_text(q_deg):
    return ", ".join(f"{v:.2f}" for v in q_deg)


class LoopGuard:
    """The check for one compensate run (its robot, model stiffness, filter
    and timing); ``at(...)`` checks one start pose."""

    def __init__(self, *, robot, k_Nm_per_rad, servo, sensor_rate_hz, period_s, delay_steps, filter_kind,
                 filter_ba, cutoff_hz, filter_order, allow_unstable):
        self.robot, self.k, self.servo = robot, np.asarray(k_Nm_per_rad, dtype=float), servo_parameters(servo)
        self._servo_option = None if servo is None else [float(v) for v in servo]
        self.rate_hz, self.period_s, self.delay_steps = float(sensor_rate_hz), float(period_s), int(delay_steps)
        self.filter_kind, self.ba, self.cutoff_hz, self.order = filter_kind, filter_ba, cutoff_hz, int(filter_order)
        self.allow = bool(allow_unstable)
        self.result = None  # the last check's dict (for summary.json)
        self.warning = None  # the override's warning line, when it ran an unstable loop

    def _verdict(self, q_ctrl_deg, where, feed_xy, search_cutoff=True, assumed_damping=True):
        """(Verdict, the process stiffnesses) at the controller's angles
        (degrees; ``where``: the pose's name and angles, for the message)."""
        from robstiff_drake.identification.threads import single_blas_thread

        q = self.robot.joint_map.to_model(np.radians(np.asarray(q_ctrl_deg, dtype=float)))
        setup = loop_check.LoopSetup(robot=self.robot, q_rad=q, k_Nm_per_rad=self.k, servo=self.servo,
                                     sensor_rate_hz=self.rate_hz, period_s=self.period_s,
                                     delay_steps=self.delay_steps, filter_order=self.order)
        modes = {"air": np.zeros((3, 3)), "cutting": loop_check.process_stiffness_along(feed_xy)}
        try:
            with single_blas_thread():  # (many threads on small matrices: 10x slower on a busy machine)
                v = loop_check.check(setup, self.ba, modes, search_cutoff=search_cutoff,
                                     assumed_damping=assumed_damping,
                                     cutoff_hz=self.cutoff_hz if self.filter_kind == "lowpass" else None)
                self.servo = setup.arm(loop_check.MARGIN_DAMPING_RATIO)[0].servo  # (tuned here, if not yet)
        except (np.linalg.LinAlgError, ValueError) as e:  # no loop to check (a mass matrix without inertia): refused
            raise InputError(f"the correction loop cannot be checked at {where}: {e}; check the robot file's links "
                             "and payload") from None
        return v, modes

    def _best_cutoff_text(self, f):
        if f is None:
            return "no low-pass cutoff down to 0.1 Hz is stable"
        if self.filter_kind == "lowpass":
            return f"the largest cutoff the model finds stable is {f:g} Hz (--cutoff-hz {f:g})"
        return f"the largest low-pass cutoff the model finds stable is {f:g} Hz (--filter lowpass --cutoff-hz {f:g})"

    def along(self, q_ctrl_deg_rows, what, times_s, to_model=None):
        """Check the loop at PATH_CHECK_SAMPLES rows of a reference after
        its first (``at`` checks that one first: it tunes the drives), each
        cutting along the tool's motion from there; ``what`` names the
        reference, ``times_s`` its rows' times (s; or one number: their
        period).  The worst pose (largest spectral radius at the margin's
        damping) goes into the result (``along_path``).  InputError (one
        line, naming the row, its time, the pose, the radius and the
        largest stable cutoff there) when a pose is predicted unstable and
        not overridden; returns the line to print."""
        q = np.asarray(q_ctrl_deg_rows, dtype=float)
        t = np.asarray(times_s, dtype=float)
        t = t if t.ndim else np.arange(len(q)) * float(t)
        rows = np.unique(np.linspace(0, len(q) - 1, PATH_CHECK_SAMPLES + 1).round().astype(int))[1:]
        if not len(rows):
            return None
        t0 = time.perf_counter()
        found = []
        for r in rows:
            feed = feed_direction(self.robot, self.robot.payload.tool_point_m, q[r:], to_model=to_model)
            v, modes = self._verdict(q[r], f"{what}'s row {r + 1} ({_pose_text(q[r])} deg)", feed,
                                     search_cutoff=False, assumed_damping=False)
            found.append((max(v.radius.values()), int(r), v, modes))
        worst = max(found, key=lambda x: x[0])
        _, r, v, modes = worst
        seconds = time.perf_counter() - t0
        T_ms = self.period_s * 1e3
        pose = f"row {r + 1}, t = {t[r]:.2f} s: {_pose_text(q[r])} deg"
        along = {"rows_checked": [int(x) + 1 for x in rows], "worst_row": r + 1, "worst_t_s": float(t[r]),
                 "worst_pose_deg": [float(x) for x in q[r]], "spectral_radius": v.radius,
                 "spectral_radius_by_row": {int(x[1]) + 1: max(x[2].radius.values()) for x in found},
                 "unstable_modes": v.unstable, "check_s": seconds}
        if self.result is not None:
            self.result["along_path"] = along
        if not v.unstable:
            return (f"the correction loop is stable along {what} by the loop model ({len(rows)} poses after its first "
                    f"row): worst spectral radius {v.radius['air']:.4f} in air, {v.radius['cutting']:.4f} cutting per "
                    f"{T_ms:g} ms period at {pose} with {loop_check.MARGIN_DAMPING_RATIO * 100:g} % modal damping "
                    f"(checked in {seconds:.2f} s)")
        f = self.largest_stable_cutoff(q[r], modes)
        along["largest_stable_cutoff_hz"] = f
        if self.result is not None:
            self.result["overridden"] = bool(self.result.get("overridden") or self.allow)
        modes_text, radii, filt = self._unstable_parts(v)
        line = (f"the correction loop is predicted UNSTABLE {modes_text} along {what} at {pose} with {filt}: spectral "
                f"radius {radii} per {T_ms:g} ms period with {loop_check.MARGIN_DAMPING_RATIO * 100:g} % modal "
                f"damping (the check's margin); {self._best_cutoff_text(f)} there")
        if not self.allow:
            raise InputError(f"{line}; nothing was sent ({OVERRIDE} runs it anyway)")
        self.warning = f"{OVERRIDE}: running anyway: {line}"
        return self.warning

    def _unstable_parts(self, v):
        """(the unstable modes, their spectral radii, the filter option) as
        the refusal's line names them, for a verdict ``v``."""
        modes_text = " and ".join("in air" if m == "air" else "cutting" for m in v.unstable)
        radii = ", ".join(f"{v.radius[m]:.4f} {'in air' if m == 'air' else 'cutting'}" for m in v.unstable)
        filt = f"--cutoff-hz {self.cutoff_hz:g}" if self.filter_kind == "lowpass" else f"--filter {self.filter_kind}"
        return modes_text, radii, filt

    def largest_stable_cutoff(self, q_ctrl_deg, modes):
        """The largest low-pass cutoff (Hz) stable at a pose (None: none)."""
        q = self.robot.joint_map.to_model(np.radians(np.asarray(q_ctrl_deg, dtype=float)))
        setup = loop_check.LoopSetup(robot=self.robot, q_rad=q, k_Nm_per_rad=self.k, servo=self.servo,
                                     sensor_rate_hz=self.rate_hz, period_s=self.period_s,
                                     delay_steps=self.delay_steps, filter_order=self.order)
        upper = min(self.cutoff_hz if self.filter_kind == "lowpass" else loop_check.SEARCH_UPPER_HZ,
                    0.45 * self.rate_hz)
        return setup.largest_stable_cutoff_hz(upper, modes, upper_unstable=self.filter_kind == "lowpass")

    def at(self, q_ctrl_deg, where, feed_xy=None):
        """Check the loop at the controller's joint angles ``q_ctrl_deg``
        (``where``: which pose this is, for the message).  InputError (one
        line) when it is predicted unstable and not overridden; returns the
        line to print (information, or the override's warning)."""
        t0 = time.perf_counter()
        v, _ = self._verdict(q_ctrl_deg, f"the start pose ({where}: {_pose_text(q_ctrl_deg)} deg)", feed_xy)
        seconds = time.perf_counter() - t0
        self.result = dict(v.as_dict(), pose_deg=[float(x) for x in q_ctrl_deg], pose=where,
                           feed_direction_xy=None if feed_xy is None else [float(x) for x in feed_xy],
                           check_s=seconds, overridden=bool(v.unstable and self.allow))
        T_ms = self.period_s * 1e3
        if not v.unstable:
            return (f"the correction loop is stable at the start pose ({where}) by the loop model: spectral radius "
                    f"{v.radius['air']:.4f} in air, {v.radius['cutting']:.4f} cutting per {T_ms:g} ms period with "
                    f"{loop_check.MARGIN_DAMPING_RATIO * 100:g} % modal damping (checked in {seconds:.2f} s)")
        modes_text, radii, filt = self._unstable_parts(v)
        assumed = ", ".join(f"{v.radius_assumed[m]:.4f}" for m in v.unstable)
        best = self._best_cutoff_text(v.largest_stable_cutoff_hz)
        line = (f"the correction loop is predicted UNSTABLE {modes_text} at the start pose ({where}: "
                f"{_pose_text(q_ctrl_deg)} deg) with {filt}: spectral radius {radii} per {T_ms:g} ms period with "
                f"{loop_check.MARGIN_DAMPING_RATIO * 100:g} % modal damping (the check's margin; {assumed} at the assumed "
                f"{joint_dynamics.DEFAULT_MODAL_DAMPING_RATIO * 100:g} %); {best}")
        if not self.allow:
            raise InputError(f"{line}; nothing was sent ({OVERRIDE} runs it anyway)")
        self.warning = f"{OVERRIDE}: running anyway: {line}"
        return self.warning

    def elsewhere(self, robot_spec):
        """This check in a process of its own, started now (its imports and
        setup done while the controller's first message is awaited):
        ``RemoteCheck.at`` then checks one pose there.  A loop's thread
        shares no interpreter lock with the check's numerical calls, which
        hold it for several milliseconds at a time (up to 8.6 ms measured
        beside a thread waking every millisecond), longer than KUKA RSI's
        4 ms cycle.  ``robot_spec``: the robot file or name this guard's
        robot was loaded from."""
        return RemoteCheck(self, robot_spec)


class RemoteCheck:
    """``LoopGuard.at`` in another process: the same line, warning and
    figures (set on the guard), InputError alike.  A fork of this process
    when it has one thread (started before the sensor's reader and the
    sockets' use: everything imported, nothing to start), else a new
    interpreter (2.3 s of imports at a load of 7, done while the controller
    is awaited)."""

    def __init__(self, guard, robot_spec):
        import json
        import os
        import subprocess
        import sys
        import threading

        self.guard = guard
        self.pid = self.proc = None
        if hasattr(os, "fork") and threading.active_count() == 1:
            ask_r, ask_w = os.pipe()
            out_r, out_w = os.pipe()
            pid = os.fork()
            if pid == 0:  # the child: one pose asked, one verdict written, nothing else
                code = 0
                try:
                    os.close(ask_w)
                    os.close(out_r)
                    with os.fdopen(ask_r) as f_in, os.fdopen(out_w, "w") as f_out:
                        f_out.write(_verdict(guard, f_in.readline()))
                except BaseException:
                    code = 1
                finally:
                    os._exit(code)
            os.close(ask_r)
            os.close(out_w)
            self.pid, self._ask, self._out = pid, os.fdopen(ask_w, "w"), os.fdopen(out_r)
            return
        spec = {"robot": None if robot_spec is None else str(robot_spec), "k": guard.k.tolist(),
                "servo": guard._servo_option, "sensor_rate_hz": guard.rate_hz, "period_s": guard.period_s,
                "delay_steps": guard.delay_steps, "filter_kind": guard.filter_kind,
                "filter_ba": [np.asarray(x, dtype=float).tolist() for x in guard.ba], "cutoff_hz": guard.cutoff_hz,
                "filter_order": guard.order, "allow_unstable": guard.allow}
        self.proc = subprocess.Popen([sys.executable, "-m", __name__], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                     stderr=subprocess.PIPE, text=True)
        self.proc.stdin.write(json.dumps(spec) + "\n")
        self.proc.stdin.flush()

    def at(self, q_ctrl_deg, where):
        import json
        import os

        ask = json.dumps({"q_deg": [float(v) for v in q_ctrl_deg], "where": where}) + "\n"
        status = "?"
        try:
            if self.pid is not None:
                with self._ask as f:
                    f.write(ask)
                with self._out as f:
                    out = f.read()
                status = os.waitpid(self.pid, 0)[1]
                self.pid = None
            else:
                out, _ = self.proc.communicate(ask)
                status = self.proc.returncode
            doc = json.loads(out)
        except (ValueError, OSError):
            raise InputError(f"the correction loop's check at the start pose ({where}) failed in its process "
                             f"(status {status})") from None
        if "error" in doc:
            raise InputError(doc["error"])
        self.guard.result, self.guard.warning = doc["result"], doc["warning"]
        return doc["line"]

    def close(self):
        """Ended if it was never asked (a run that stopped before its first message)."""
        import os
        import signal

        if self.pid is not None:
            try:
                os.kill(self.pid, signal.SIGKILL)
                os.waitpid(self.pid, 0)
            except OSError:
                pass
            self.pid = None
        elif self.proc is not None and self.proc.poll() is None:
            self.proc.kill()
            self.proc.communicate()


def _verdict(guard, ask_line):
    """The JSON verdict of ``guard`` at the pose of ``ask_line`` (JSON: q_deg, where)."""
    import json

    ask = json.loads(ask_line or "null")
    if ask is None:
        return "null"  # (never asked)
    try:
        line = guard.at(ask["q_deg"], ask["where"])
        return json.dumps({"line": line, "warning": guard.warning, "result": guard.result}, default=float)
    except InputError as e:
        return json.dumps({"error": str(e)})


def _main():
    """``RemoteCheck``'s new interpreter: the guard's spec, then the pose, as JSON lines on stdin; the verdict as
    JSON on stdout."""
    import json
    import sys

    from robstiff_drake.model.robot import load_robot

    spec = json.loads(sys.stdin.readline())
    try:
        guard = LoopGuard(robot=load_robot(spec["robot"]), k_Nm_per_rad=spec["k"], servo=spec["servo"],
                          sensor_rate_hz=spec["sensor_rate_hz"], period_s=spec["period_s"],
                          delay_steps=spec["delay_steps"], filter_kind=spec["filter_kind"],
                          filter_ba=tuple(np.asarray(x) for x in spec["filter_ba"]), cutoff_hz=spec["cutoff_hz"],
                          filter_order=spec["filter_order"], allow_unstable=spec["allow_unstable"])
    except InputError as e:
        print(json.dumps({"error": str(e)}))
        return 0
    print(_verdict(guard, sys.stdin.readline()))
    return 0


if __name__ == "__main__":
    raise SystemExit(_main())
