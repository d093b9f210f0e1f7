"""`robstiff compensate` as a process against a scripted controller (the
cell tests' lockstep: one message, then its answer): the controller
(``ScriptedController``: EGM from 127.0.0.1), the process
(``start_compensate``) and its end (``finish``: when the test's script is
over, never on a silence a paused test process would cause too).  Every
wait here ends at its event; HANG_GUARD_S only bounds a hung run."""

import os
import socket
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

# A bound on any wait of the scripted tests, never a deadline they are meant to meet: a wait ends at its event (an
# answer, the process's exit); only a hung or starved compensator meets this
HANG_GUARD_S = 60.0


class ScriptedController:
    """A controller that sends EgmRobot messages exactly as a test says
    (sequence number, clock, joints) from 127.0.0.1 (or ``host``, another
    loopback address) and collects the answers: one message, then its
    answer (lockstep, no timing on a loaded machine)."""

    def __init__(self, compensate_port, host="127.0.0.1"):
        from robstiff_drake.cell.egm import _egm_pb2

        self.pb2 = _egm_pb2()
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind((host, 0))
        self.addr = ("127.0.0.1", compensate_port)
        self.port = self.sock.getsockname()[1]

    def message(self, seq, tm_ms, joints_deg):
        m = self.pb2.EgmRobot()
        m.header.seqno = int(seq)
        m.header.tm = int(tm_ms) & 0xFFFFFFFF
        m.header.mtype = self.pb2.EgmHeader.MSGTYPE_DATA
        m.feedBack.joints.joints.extend([float(v) for v in joints_deg])
        return m.SerializeToString()

    def send(self, seq, tm_ms, joints_deg):
        self.sock.sendto(self.message(seq, tm_ms, joints_deg), self.addr)

    def answers(self, timeout_s=0.0, want=1):
        """The joint targets (deg) of the answers waiting (after waiting up
        to ``timeout_s`` for ``want`` of them; 0: those queued now, which
        after the compensator's exit are all it ever sent here)."""
        import select
        import time

        out, t_end = [], time.monotonic() + timeout_s
        while True:
            r, _, _ = select.select([self.sock], [], [], max(t_end - time.monotonic(), 0.0))
            if not r:
                return out
            data, _ = self.sock.recvfrom(65536)
            m = self.pb2.EgmSensor()
            m.ParseFromString(data)
            out.append(list(m.planned.joints.joints))
            if len(out) >= want and timeout_s:
                return out

    def exchange(self, seq, tm_ms, joints_deg, timeout_s=HANG_GUARD_S):
        self.send(seq, tm_ms, joints_deg)
        got = self.answers(timeout_s)
        return got[-1] if got else None

    def close(self):
        self.sock.close()


def start_compensate(model, payload, sensor, egm_port, *, reference=None, log=None, extra=()):
    """`robstiff compensate` against a scripted controller: it ends when the
    test says so (``finish``), not when the controller has been silent a
    while (--idle-exit-s only as a hang guard: a test process paused on a
    loaded machine is silent too; at 1 s such a pause once ended the run
    mid-script, "a message unanswered")."""
    cmd = [sys.executable, "-m", "robstiff_drake", "compensate", "--egm-port", str(egm_port), "--netft",
           f"127.0.0.1:{sensor.port}", "--netft-http-port", str(sensor.http_port), "--model", model, "--payload",
           payload, "--wait-s", "30", "--idle-exit-s", f"{HANG_GUARD_S:g}", "--sensor-timeout-ms", "200"]
    if reference:
        cmd += ["--reference", reference]
    if log:
        cmd += ["--log", log]
    # (ROBSTIFF_STOP_TRACE: where a SIGTERM that ended the command with "robstiff: terminated" landed, said after
    # that line: a run that should have ended by itself on the test's SIGTERM, once seen in CI at load, says where)
    env = dict(os.environ, ROBSTIFF_STOP_TRACE="1")
    proc = subprocess.Popen(cmd + list(extra), cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=env)
    # ready when it says it waits for the controller (its port is bound); its earlier lines are kept
    proc.early_err, proc.err_bytes = "", b""
    while True:
        line = _err_line(proc)
        proc.early_err += line
        if not line or "waiting for" in line and "messages from" in line:
            return proc


def held_run(model, payload, sensor, port, q0_deg, messages, *, t_ms=4.0, log=None, extra=()):
    """`compensate` (start_compensate on UDP ``port``) answering messages 1
    to ``messages`` - 1 of a scripted controller holding ``q0_deg``
    (message k stamped k * ``t_ms``), each answered, then ended (finish);
    the controller and ``sensor`` closed.  (the process, its exit status,
    its stderr after the start's lines: ``proc.early_err`` holds those)."""
    proc = start_compensate(model, payload, sensor, port, log=log, extra=extra)
    ctrl = ScriptedController(port)
    try:
        for k in range(1, messages):
            assert ctrl.exchange(k, k * t_ms, q0_deg) is not None, f"no answer to message {k}"
        code, err = finish(proc)
    finally:
        ctrl.close()
        sensor.close()
    return proc, code, err


def _err_line(proc):
    """The next line of the stderr of a process of start_compensate ("" at
    its end), read from the pipe itself (so that ``_err_pending`` sees all
    that is unread), within the hang guard."""
    import select

    fd = proc.stderr.fileno()
    while b"\n" not in proc.err_bytes:
        if not select.select([fd], [], [], HANG_GUARD_S)[0]:
            raise TimeoutError(f"compensate wrote no line for {HANG_GUARD_S:g} s (hung?)")
        chunk = os.read(fd, 65536)
        if not chunk:
            line, proc.err_bytes = proc.err_bytes, b""
            return line.decode()
        proc.err_bytes += chunk
    line, _, proc.err_bytes = proc.err_bytes.partition(b"\n")
    return line.decode() + "\n"


def _err_pending(proc):
    import select

    return b"\n" in proc.err_bytes or bool(select.select([proc.stderr.fileno()], [], [], 0)[0])


def finish(proc, timeout=HANG_GUARD_S, end=True):
    """(exit status, the whole stderr) of a process started by
    start_compensate.  ``end``: the script is over (its last answer
    received), so the run is ended as a service manager stops it (SIGTERM:
    the loop ends, writes its log, exit 0), once its loop is idle: it has
    said the controller is silent (its "no message ... for 100 ms" line)
    and no "messages again" line follows; an earlier silence's "again" line
    was written before the answer to the message that ended it, so it is in
    the pipe by now (the test had that answer).  Never mid-cycle: a SIGTERM
    between an answer's send and its count left that answer uncounted.
    ``end`` False: the process ends by itself (a refused start) and is
    waited for."""
    import signal

    if end and proc.poll() is None:
        silent = False
        while not (silent and not _err_pending(proc)):
            line = _err_line(proc)
            proc.early_err += line
            if not line:
                break  # (it ended by itself)
            if "no message from the controller for" in line:
                silent = True
            elif ": messages again" in line:
                silent = False
        if proc.poll() is None:
            proc.send_signal(signal.SIGTERM)
    proc.early_err += proc.err_bytes.decode()
    proc.err_bytes = b""
    out, err = proc.communicate(timeout=timeout)
    return proc.returncode, proc.early_err + err


class EndWhenIdle:
    """``finish``'s end for a run whose controller is not the test's script
    but a simulated cell in a thread (cell_helpers.run_compensate_against_cell,
    lockstep): the process's stderr read as it comes (so that it never
    fills its pipe) and, once the cell is done (``cell_done()``), SIGTERM as
    soon as its loop is idle: it has said the controller is silent and no
    "messages again" line follows, with nothing unread for POLL_S.  Never on
    a silence alone (--idle-exit-s is a hang guard there: a test process
    paused on a loaded machine is silent too).  ``wait``: (exit status,
    stdout, stderr)."""

    POLL_S = 0.05

    def __init__(self, proc):
        import threading

        self.proc, self.err, self.out = proc, [], []
        self.silent = False
        self.done = threading.Event()
        self._reader = threading.Thread(target=self._read_err, daemon=True)
        self._out_reader = threading.Thread(target=lambda: self.out.append(proc.stdout.read().decode(errors="replace")),
                                           daemon=True)
        self._reader.start()
        self._out_reader.start()

    def cell_done(self):
        self.done.set()

    def _read_err(self):
        import select
        import signal

        fd, buf, signalled = self.proc.stderr.fileno(), b"", False
        while True:
            if select.select([fd], [], [], self.POLL_S)[0]:
                chunk = os.read(fd, 65536)
                if not chunk:
                    break  # (the process ended)
                *lines, buf = (buf + chunk).split(b"\n")
                for raw in lines:
                    line = raw.decode(errors="replace")
                    self.err.append(line + "\n")
                    if "no message from the controller for" in line:
                        self.silent = True
                    elif ": messages again" in line:
                        self.silent = False
                continue  # (decide only once nothing is left unread)
            if self.done.is_set() and self.silent and not signalled and self.proc.poll() is None:
                self.proc.send_signal(signal.SIGTERM)
                signalled = True
        self.err.append(buf.decode(errors="replace"))

    def wait(self, timeout):
        self.proc.wait(timeout=timeout)
        self._reader.join(HANG_GUARD_S)
        self._out_reader.join(HANG_GUARD_S)
        return self.proc.returncode, "".join(self.out), "".join(self.err)
