"""compensate --cpu-latency-us: the kernel's CPU wake-up latency request
(Linux PM QoS, /dev/cpu_dma_latency), held while the loop runs and
withdrawn however it ends (cell/realtime_thread.CpuLatency).

The request is a 32-bit int written to the file and holds while the file
is open: here a regular file stands in for the device (what was written,
and whether the descriptor is still open, are what the kernel would
see); the real device is tried only where the test may open it."""

import os
import struct
import subprocess
import sys

import pytest

from robstiff_drake.cell.realtime_thread import CPU_LATENCY_FILE, CpuLatency


def _open_fds():
    return set(os.listdir("/proc/self/fd")) if os.path.isdir("/proc/self/fd") else None


def test_the_request_is_written_as_the_kernel_reads_it_and_held_until_released(tmp_path):
    dev = tmp_path / "cpu_dma_latency"
    dev.write_bytes(b"")
    before = _open_fds()
    qos = CpuLatency(0, path=str(dev))
    assert qos.warning is None and qos.held
    assert dev.read_bytes() == struct.pack("=i", 0)  # (a native 32-bit int: the device takes 4 bytes or hex text)
    if before is not None:
        assert len(_open_fds() - before) == 1  # (the request holds only while its file is open)
    qos.release()
    assert not qos.held
    if before is not None:
        assert _open_fds() == before
    qos.release()  # (twice: nothing more)


def test_a_latency_in_microseconds_is_written_as_given(tmp_path):
    dev = tmp_path / "cpu_dma_latency"
    dev.write_bytes(b"")
    qos = CpuLatency(250, path=str(dev))
    try:
        assert struct.unpack("=i", dev.read_bytes()) == (250,)
    finally:
        qos.release()


def test_not_asked_opens_nothing(tmp_path):
    dev = tmp_path / "cpu_dma_latency"
    qos = CpuLatency(None, path=str(dev))
    assert not qos.held and qos.warning is None and not dev.exists()


def test_a_machine_that_does_not_allow_it_gives_one_line_and_the_run_goes_on(tmp_path):
    vm = tmp_path / "cpuinfo_vm"
    vm.write_text("flags\t\t: fpu hypervisor\n")
    qos = CpuLatency(0, path=str(tmp_path / "no_such_dir" / "cpu_dma_latency"), cpuinfo=str(vm))
    assert not qos.held and qos.caution is None  # (not held: it costs nothing, no caution)
    assert qos.warning.startswith("--cpu-latency-us 0: cannot open ") and qos.warning.endswith("running without it")
    assert "\n" not in qos.warning
    qos.release()


@pytest.mark.skipif(not os.path.exists(CPU_LATENCY_FILE) or not os.access(CPU_LATENCY_FILE, os.W_OK),
                    reason=f"{CPU_LATENCY_FILE} absent or not writable here (not Linux, or no privilege)")
def test_the_real_device_takes_the_request():
    qos = CpuLatency(0)
    try:
        assert qos.held and qos.warning is None
    finally:
        qos.release()


def test_the_option_outside_its_range_is_one_line_exit_2():
    r = subprocess.run([sys.executable, "-m", "robstiff_drake", "compensate", "--netft", "127.0.0.1:1", "--model",
                        "m.json", "--payload", "p.json", "--cpu-latency-us", "-1"], capture_output=True, text=True)
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert lines[-1].endswith("--cpu-latency-us: -1 is outside the allowed range [0, 100000] us")
    assert "Traceback" not in r.stderr


def test_on_a_virtual_machine_the_request_is_held_with_a_caution(tmp_path):
    """A CPU with the hypervisor flag: the request holds, and one line says what polling idle CPUs cost there
    (the host's CPU time; a quota's stalls); on a machine without the flag, or without /proc/cpuinfo, none."""
    dev = tmp_path / "cpu_dma_latency"
    dev.write_bytes(b"")
    vm, metal = tmp_path / "cpuinfo_vm", tmp_path / "cpuinfo_metal"
    vm.write_text("processor\t: 0\nflags\t\t: fpu vme sse2 hypervisor lahf_lm\n\nprocessor\t: 1\n")
    metal.write_text("processor\t: 0\nflags\t\t: fpu vme sse2 lahf_lm\n")
    for info, cautioned in ((vm, True), (metal, False), (tmp_path / "none", False)):
        qos = CpuLatency(0, path=str(dev), cpuinfo=str(info))
        try:
            assert qos.held and qos.warning is None
            assert (qos.caution is not None) is cautioned
            if cautioned:
                assert qos.caution.startswith("--cpu-latency-us 0 on a virtual machine") and "\n" not in qos.caution
        finally:
            qos.release()
    assert CpuLatency(None, path=str(dev), cpuinfo=str(vm)).caution is None  # (not asked: nothing said)
    # a request every halting idle state meets changes nothing: not cautioned (states as this VM's: POLL 0 us,
    # haltpoll 1 us; one of 200 us as a deep C-state)
    idle = tmp_path / "cpuidle"
    for name, us in (("state0", ("POLL", 0)), ("state1", ("haltpoll", 1)), ("state2", ("C6", 200))):
        (idle / name).mkdir(parents=True)
        (idle / name / "name").write_text(us[0] + "\n")
        (idle / name / "latency").write_text(f"{us[1]}\n")
    for latency, cautioned in ((0, True), (1, False), (100, False)):
        qos = CpuLatency(latency, path=str(dev), cpuinfo=str(vm), cpuidle=str(idle))
        qos.release()
        assert (qos.caution is not None) is cautioned, latency
