"""The compensator process's scheduling: its loop's thread under
SCHED_FIFO (``--rt-priority``) with the threads it started before, on a
CPU of its own (``--cpu``), and the garbage collector kept out of the
answer's way: the objects made before the loop frozen, the automatic
collector off while the loop runs, and the collections it would have made
run by the loop itself after an answer has left (``collect_if_due``),
never between a message's arrival and its answer; and the CPUs kept out
of their deep idle states while it runs (``--cpu-latency-us``,
``CpuLatency``).  The start's own work runs below the loop
(cell/start_gate.below_the_loop)."""

import gc
import os
import struct

# Linux's CPU wake-up latency request (PM QoS): a 32-bit int of microseconds written to this file holds while it is
# open, for every CPU (the kernel's Documentation/power/pm_qos_interface.rst; cyclictest holds it at 0 by default)
CPU_LATENCY_FILE = "/dev/cpu_dma_latency"
CPUIDLE_DIR = "/sys/devices/system/cpu/cpu0/cpuidle"  # (the idle states: name, exit latency in us)

# the CPUs the process could run on before the loop's thread was pinned (threads the loop starts later,
# which inherit its pin, are given them back: cell/start_gate.below_the_loop); None: not pinned
_ALL_CPUS = None


def realtime(priority):
    """Run the loop's thread under SCHED_FIFO at ``priority`` (1-99), as a
    real-time PC would; 0: leave the scheduling alone.  Not permitted (no
    privilege): the warning line returned (None when it worked), and the
    loop runs anyway: a scheduling wish never ends a run.

    The process's threads started before it (the sensor reader's) go to
    SCHED_FIFO one below the loop: they take Python's interpreter lock to
    hand over each record, and one of them preempted by another process
    while it holds the lock would hold up the loop for that process's time
    slice (the loop's own priority does not help it then).  Threads started
    later (the log's writer) inherit the loop's scheduling."""
    if not priority:
        return None
    import threading

    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(int(priority)))
    except (AttributeError, PermissionError, OSError) as e:
        return f"--rt-priority {priority}: cannot switch to real-time scheduling ({e}); running without it"
    me = threading.get_native_id()
    try:
        tids = [int(t) for t in os.listdir("/proc/self/task")]
    except OSError:
        return None  # (not Linux: the loop's thread only)
    for tid in tids:
        if tid != me:
            try:
                os.sched_setscheduler(tid, os.SCHED_FIFO, os.sched_param(max(int(priority) - 1, 1)))
            except OSError:
                pass  # (a thread that ended meanwhile)
    return None


def pin_to_cpu(cpu):
    """Keep the loop's thread on CPU ``cpu`` (None: leave it where the
    scheduler puts it): on a PC whose other work is kept off that CPU
    (isolcpus, or a load pinned elsewhere) nothing else runs there.  The
    threads started before it (the sensor reader's) stay where they were.
    Returns None, or the warning line when the machine does not allow it
    (the run goes on unpinned: a scheduling wish never ends a run)."""
    global _ALL_CPUS
    if cpu is None:
        return None
    try:
        allowed = os.sched_getaffinity(0)
        if int(cpu) not in allowed:
            return (f"--cpu {cpu}: not one of the CPUs this process may use ({', '.join(map(str, sorted(allowed)))}); "
                    "running unpinned")
        os.sched_setaffinity(0, {int(cpu)})  # (Linux: 0 is the calling thread, the loop's)
    except (AttributeError, OSError) as e:
        return f"--cpu {cpu}: cannot pin the loop's thread ({e}); running unpinned"
    _ALL_CPUS = allowed
    return None


class CpuLatency:
    """Ask the kernel to keep every CPU's wake-up latency within
    ``latency_us`` while the loop runs (``--cpu-latency-us``; Linux's PM QoS
    request: the value written to ``/dev/cpu_dma_latency`` holds until the
    file is closed, ``release``).  0: the idle CPUs poll instead of halting,
    as a real-time PC's are usually set up (cyclictest asks the same by
    default); it costs the power of CPUs that never sleep, on every CPU.
    The wake-up and the first instructions after it are what it shortens:
    on this project's 2-core virtual machine a halted virtual CPU is given
    back to its host, and a message's computation after 4 ms of idle took
    1.5 times (median) and 2 times (p99) its back-to-back figure
    (docs/results.md, section 5).  Not permitted (no privilege, no such
    file: not Linux): ``warning`` says so and the run goes on without it
    (a scheduling wish never ends a run).

    On a virtual machine (the CPU's ``hypervisor`` flag) the request is
    held but ``caution`` says what it costs there: CPUs that poll spend the
    host's CPU time whether or not the loop needs it, and a host that
    grants the machine a CPU quota stops it once that is spent.  On this
    project's 2-core virtual machine, with a busy process on the other
    core, ten minutes of RSI with the request held had a p99 of 0.465 ms
    (0.565 without it, the run before) but stalls of over 100 ms (the five
    slowest answers 104.6-106.4 ms after their arrival, spread over the
    run) and 154 cycles unanswered (12.8 ms and 5 without it): the host's
    quota, whose period is 100 ms (docs/results.md, section 5).  It is a
    setting for a real-time PC, not for a virtual one.  (A request the
    CPU's halting idle states all meet, e.g. 100 us where they wake in 1
    us, changes nothing and is not cautioned.)"""

    def __init__(self, latency_us, path=CPU_LATENCY_FILE, cpuinfo="/proc/cpuinfo", cpuidle=CPUIDLE_DIR):
        self.latency_us, self.path, self._fd, self.warning = latency_us, path, None, None
        self.caution = None
        if latency_us is None:
            return
        try:
            fd = os.open(path, os.O_WRONLY)
        except OSError as e:
            self.warning = (f"--cpu-latency-us {latency_us}: cannot open {path} ({e.strerror or e}); "
                            "running without it")
            return
        try:
            os.write(fd, struct.pack("=i", int(latency_us)))
        except OSError as e:
            os.close(fd)
            self.warning = (f"--cpu-latency-us {latency_us}: {path} refused the request ({e.strerror or e}); "
                            "running without it")
            return
        self._fd = fd
        # (only for a request that holds: one not allowed costs nothing)
        if on_a_virtual_machine(cpuinfo) and latency_us < shallowest_halt_us(cpuidle):
            self.caution = (f"--cpu-latency-us {latency_us} on a virtual machine (the CPU's hypervisor flag): idle "
                            "CPUs that poll spend the host's CPU time, and a host with a CPU quota stops the "
                            "machine once it is spent (here: stalls of about 100 ms, docs/results.md); a "
                            "setting for a real-time PC")

    @property
    def held(self):
        """Whether the request holds (its file open)."""
        return self._fd is not None

    def release(self):
        """The request withdrawn (the file closed): the CPUs idle as before."""
        if self._fd is not None:
            fd, self._fd = self._fd, None
            try:
                os.close(fd)
            except OSError:
                pass


def shallowest_halt_us(cpuidle=CPUIDLE_DIR):
    """The exit latency (us) of CPU 0's shallowest idle state that halts
    (cpuidle's states but ``POLL``): a latency request below it keeps the
    idle CPUs polling.  1 where cpuidle says nothing (a request of 0 always
    polls)."""
    found = []
    try:
        for state in os.listdir(cpuidle):
            d = os.path.join(cpuidle, state)
            with open(os.path.join(d, "name")) as f:
                if f.read().strip() == "POLL":
                    continue
            with open(os.path.join(d, "latency")) as f:
                found.append(int(f.read().strip()))
    except (OSError, ValueError):
        pass
    return min(found) if found else 1


def on_a_virtual_machine(cpuinfo="/proc/cpuinfo"):
    """Whether the CPU says it runs under a hypervisor (x86's ``hypervisor``
    flag in /proc/cpuinfo; False where the file or the flag is missing)."""
    try:
        with open(cpuinfo) as f:
            for line in f:
                if line.startswith("flags") and " hypervisor" in line:
                    return True
    except OSError:
        pass
    return False


def unpin_this_thread():
    """A thread the loop started (it inherited the loop's CPU): back on
    every CPU the process had."""
    if _ALL_CPUS is not None:
        try:
            os.sched_setaffinity(0, _ALL_CPUS)
        except (AttributeError, OSError):
            pass


def quiet_gc():
    """Collect once, freeze the objects made so far out of the collector's
    reach (the later collections walk only what the run makes) and turn
    the automatic collector off: it would run inside whatever allocation
    crosses its threshold, on the way to an answer.  The loop collects at
    its safe points instead (``collect_if_due``).  Returns the token for
    ``restore_gc``."""
    gc.collect()
    gc.freeze()
    thresholds = gc.get_threshold()
    enabled = gc.isenabled()
    gc.disable()
    return thresholds, enabled


def collect_if_due(token):
    """At a safe point of the loop (its answer has left): the collection
    the automatic collector would have made by now, if any (generation 0
    after its threshold of new objects, an older one when its own count is
    due, as Python schedules them); the generation collected, or -1.  With
    the collector left on (``token`` None, or the loop run by a test
    without ``quiet_gc``): nothing."""
    if token is None or gc.isenabled():
        return -1
    (t0, t1, t2), _ = token
    c0, c1, c2 = gc.get_count()
    if t0 <= 0 or c0 <= t0:
        return -1
    gen = 2 if c2 > t2 else 1 if c1 > t1 else 0
    gc.collect(gen)
    return gen


def restore_gc(token):
    if token:
        _, enabled = token
        if enabled:
            gc.enable()
        gc.unfreeze()
