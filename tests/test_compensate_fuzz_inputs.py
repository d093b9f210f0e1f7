"""`robstiff compensate`'s input files fuzzed where they broke: a joint
reference that is a FIFO (the open blocked for ever, before any check) or
a device (/dev/zero was read as one endless line until memory ran out), and
a file of one endless line (a sparse file's gigabyte of NUL bytes read
whole before the first check).  Each is now one line naming the file (and
the line), exit 2, before any socket opens, in bounded memory.  The wire's
side: tests/test_compensate_fuzz.py."""

import os
import socket
import subprocess
import sys
import threading
import tracemalloc

import pytest

import cell_helpers as h
from robstiff_drake.cell import reference_file
from robstiff_drake.errors import InputError
from robstiff_drake.model.robot import load_robot

HEADER = b"t_s,q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg\n"
ROW = b"0.0000,0.000000000,13.621639298,21.952625304,0.000000000,54.425735398,0.000000000\n"


def _without_blocking(fn, fifo):
    """fn() in a thread; if it is still blocked (a FIFO's open waits for a writer) after 20 s, a writer opens the
    FIFO to free it and the test fails: the result (value or exception) otherwise."""
    out = {}

    def run():
        try:
            out["value"] = fn()
        except Exception as e:  # noqa: BLE001 (handed to the test)
            out["error"] = e

    th = threading.Thread(target=run, daemon=True)
    th.start()
    th.join(20.0)
    if th.is_alive():
        fd = os.open(fifo, os.O_WRONLY | os.O_NONBLOCK)
        os.close(fd)
        th.join(5.0)
        pytest.fail(f"{fn} blocked on the FIFO {fifo}")
    return out


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no FIFOs on this system")
def test_a_fifo_reference_is_refused_without_opening_it(tmp_path):
    fifo = str(tmp_path / "ref.csv")
    os.mkfifo(fifo)
    got = _without_blocking(lambda: reference_file.corrected_mark(fifo), fifo)
    assert got == {"value": None}, got  # (the mark's look leaves the refusal to the reader)
    got = _without_blocking(lambda: reference_file.read_reference_rows(fifo), fifo)
    assert isinstance(got.get("error"), InputError), got
    assert str(got["error"]) == f"--reference {fifo}: a device, FIFO or socket, not a file of joint references"


def test_a_device_and_a_folder_are_refused_by_name(tmp_path):
    with pytest.raises(InputError, match=r"^--reference /dev/zero: a device, FIFO or socket, not a file of joint"):
        reference_file.read_reference_rows("/dev/zero")
    with pytest.raises(InputError, match=r": a folder, not a file of joint references$"):
        reference_file.read_reference_rows(tmp_path)


@pytest.mark.parametrize("where", ["after the rows", "before the header"])
def test_an_endless_line_is_refused_without_reading_it_whole(tmp_path, where):
    """A 256 MB sparse file (NUL bytes, no line end) after a header and a
    row, or in place of the header: refused naming its line, the peak of
    Python's allocations below 32 MB (before: the line read whole, 256 MB
    and more)."""
    path = tmp_path / "sparse.csv"
    with open(path, "wb") as f:
        f.write(HEADER + ROW if where == "after the rows" else b"# a comment\n")
        f.truncate(256 << 20)
    tracemalloc.start()
    try:
        with pytest.raises(InputError) as e:
            reference_file.read_reference_rows(path)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    line = 3 if where == "after the rows" else 2
    assert str(e.value).startswith(f"{path}:{line}: a line longer than {reference_file.MAX_LINE_BYTES} bytes"), e.value
    assert peak < 32 << 20, peak
    assert reference_file.corrected_mark(path) is None


def test_long_lines_up_to_the_limit_and_the_line_numbers_after_blocks_are_kept(tmp_path, monkeypatch):
    """Blocks cut at line ends (a small block size: many cuts, one inside a
    comment of nearly MAX_LINE_BYTES): every row read, numbered as in the file,
    and a bad cell after the cuts named by its line; CRLF and a BOM read as before."""
    monkeypatch.setattr(reference_file, "BLOCK_BYTES", 1000)
    rows = [f"{0.004 * i:.4f},0,13.6,21.9,0,54.4,0\r\n".encode() for i in range(400)]
    comment = b"#" + b"x" * (reference_file.MAX_LINE_BYTES - 3) + b"\r\n"
    path = tmp_path / "r.csv"
    path.write_bytes(b"\xef\xbb\xbf" + HEADER.replace(b"\n", b"\r\n") + b"".join(rows[:200]) + comment
                     + b"".join(rows[200:]))
    t, q, lines = reference_file.read_reference_rows(path)
    assert len(t) == 400 and lines[0] == 2 and lines[199] == 201 and lines[200] == 203 and lines[-1] == 402
    assert t[-1] == pytest.approx(0.004 * 399) and q[-1, 4] == pytest.approx(54.4)
    path.write_bytes(HEADER + b"".join(rows[:300]) + b"0.2,0,abc,21.9,0,54.4,0\n")
    with pytest.raises(InputError, match=r"r.csv:302, column 3 \(q2_deg\): 'abc' is not a number"):
        reference_file.read_reference_rows(path)


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no FIFOs on this system")
@pytest.mark.parametrize("kind", ["fifo", "/dev/zero", "endless line"])
def test_compensate_refuses_such_a_reference_in_one_line_before_any_socket(tmp_path, kind):
    """The command: exit 2, one line naming the file, no traceback, and the
    controller's port never bound (held here: binding it would say so)."""
    robot = load_robot()
    model, payload, _, _ = h.write_inputs(str(tmp_path), robot, duration_s=0.1)
    if kind == "fifo":
        ref = str(tmp_path / "ref.csv")
        os.mkfifo(ref)
    elif kind == "/dev/zero":
        ref = "/dev/zero"
    else:
        ref = str(tmp_path / "ref.csv")
        with open(ref, "wb") as f:
            f.write(HEADER + ROW)
            f.truncate(64 << 20)
    held = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    held.bind(("127.0.0.1", 0))
    try:
        cp = subprocess.run([sys.executable, "-m", "robstiff_drake", "compensate", "--egm-port",
                             str(held.getsockname()[1]), "--netft", "127.0.0.1:1", "--model", model, "--payload",
                             payload, "--reference", ref, "--wait-s", "0.1"], cwd=h.ROOT, capture_output=True,
                            text=True, timeout=120)
    finally:
        held.close()
    lines = cp.stderr.strip().splitlines()
    assert cp.returncode == 2 and len(lines) == 1 and "Traceback" not in cp.stderr, cp.stderr
    assert ref in lines[0] and ("FIFO" in lines[0] or "a line longer than" in lines[0]), lines[0]


@pytest.mark.parametrize("args, words", [
    (["--netft", "127.0.0.1:{listen}"], "--netft 127.0.0.1:{listen} is this compensator's own --listen-port {listen}"),
    (["--netft", "127.0.0.1:49152", "--controller", "127.0.0.1:{listen}"],
     "--controller 127.0.0.1:{listen} is this compensator's own --listen-port {listen}"),
    (["--netft", "127.0.0.1:5000", "--controller", "localhost:5000"],
     "--controller and --netft name the same address and port (127.0.0.1:5000)"),
], ids=["sensor-on-the-listen-port", "controller-on-the-listen-port", "controller-is-the-sensor"])
def test_the_controller_and_the_sensor_on_one_port_are_refused_before_any_socket(tmp_path, args, words):
    """Before: the sockets opened, the RDT start request went to this
    compensator's own port (taken for a malformed controller message) and
    the run was refused seconds later for a silent sensor."""
    robot = load_robot()
    model, payload, _, _ = h.write_inputs(str(tmp_path), robot, duration_s=0.1)
    listen = h.free_udp_port()
    cp = subprocess.run([sys.executable, "-m", "robstiff_drake", "compensate", "--egm-port", str(listen), "--model",
                         model, "--payload", payload, "--wait-s", "0.1", "--netft-open-s", "0.1",
                         "--netft-counts", "1000000,1000000", "--netft-units", "N,N-m"]
                        + [a.format(listen=listen) for a in args], cwd=h.ROOT, capture_output=True, text=True,
                        timeout=120)
    lines = cp.stderr.strip().splitlines()
    assert cp.returncode == 2 and len(lines) == 1 and "Traceback" not in cp.stderr, cp.stderr
    assert words.format(listen=listen) in lines[0], lines[0]


def test_a_robot_file_without_axis_speeds_is_refused_even_without_a_reference(tmp_path):
    """Without joint_limits.speed_deg_per_s the check of every target's step
    (cell/safety.motion_reason) checks nothing; with --reference the
    reference's check refused such a file, but holding the first pose it
    ran, and an RSI start learnt from a setpoint 5 deg off the arm was
    answered: the KRC commanded its real start plus that AK, 5 deg off (the
    loop on the library's IRB 6400 file refuses it by the step check).  Now
    refused in one line before any socket."""
    robot = load_robot()
    model, payload, _, _ = h.write_inputs(str(tmp_path), robot, duration_s=0.1)
    text = open(os.path.join(h.ROOT, "models", "irb6400.yaml")).read()
    line = "  speed_deg_per_s: [100.0, 90.0, 90.0, 170.0, 140.0, 190.0]\n"
    assert line in text
    robot_file = tmp_path / "no_speeds.yaml"
    robot_file.write_text(text.replace(line, ""))
    held = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    held.bind(("127.0.0.1", 0))
    try:
        cp = subprocess.run([sys.executable, "-m", "robstiff_drake", "compensate", "--controller-protocol", "rsi",
                             "--listen-port", str(held.getsockname()[1]), "--netft", "127.0.0.1:1", "--model", model,
                             "--payload", payload, "--robot", str(robot_file), "--wait-s", "0.1"], cwd=h.ROOT,
                            capture_output=True, text=True, timeout=120)
    finally:
        held.close()
    lines = cp.stderr.strip().splitlines()
    assert cp.returncode == 2 and len(lines) == 1 and "Traceback" not in cp.stderr, cp.stderr
    assert lines[0].startswith(f"robstiff: error: {robot_file}: key 'joint_limits.speed_deg_per_s'"), lines[0]


@pytest.mark.parametrize("where", ["after the header", "at the end"])
def test_a_corrected_mark_after_the_header_is_refused_not_streamed_twice(tmp_path, where):
    """compensate-program writes the mark before the header; one after it
    (a file edited or joined by hand) was skipped as a comment, the file
    streamed with online compensation on top: corrected twice.  Now the
    reader refuses it, naming its line (the mark's own look, corrected_mark,
    still takes only a mark before the header: test_compensate_corrected_reference)."""
    from robstiff_drake.identification.runs.logs import corrected_mark_line

    mark = corrected_mark_line("robstiff compensate-program", "a model").encode()
    rows = [f"{0.004 * i:.4f},0,13.6,21.9,0,54.4,0\n".encode() for i in range(5)]
    body = HEADER + mark + b"".join(rows) if where == "after the header" else HEADER + b"".join(rows) + mark
    path = tmp_path / "r.csv"
    path.write_bytes(body)
    line = 2 if where == "after the header" else 7
    with pytest.raises(InputError, match=rf"r.csv:{line}: a corrected-reference mark after the header"):
        reference_file.read_reference_rows(path)
    assert reference_file.corrected_mark(path) is None
