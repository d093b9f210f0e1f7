import os

import numpy as np
import pytest

from robstiff_drake.model.robot import load_robot


# Tests that run `compensate` against a simulated controller and sensor in real time on 127.0.0.1: their
# timing is the machine's, so the README's test command runs them first, apart from the rest (`-n 2 -m realtime`),
# and the rest on both cores (`-n 2 -m "not realtime"`, pytest-xdist).  A test of these files that streams nothing
# live (a refusal before any stream, a codec against its reference package) carries the ``untimed`` marker and runs
# with the rest.  The part ran alone, one test at a time, before (63 -> 36 tests, 269 s -> 202-228 s in quiet clean
# clones, 67 % of one core: the other idle): two at a time it took 136 s on a quiet machine and 168 s with a
# CPU-bound process beside it, all passed (2026-12-07, issue 32: the README's command under 15 minutes).  Each test takes
# free ports of its own (tests/cell_helpers.py); a run a late machine can spoil is run once more, saying why
# (tests/test_sim_cell.py's _run_pair_judged).
REALTIME_FILES = {"test_cell_attacks.py", "test_cell_io.py", "test_cell_protocols.py", "test_cell_preview.py",
                  "test_sim_cell.py"}


# The longest tests outside tests/test_wheel_install.py, in the heavy marker's units (about 30 s on this project's
# 2-core machine at load 4; measured with --durations at load 8-9, 2026-12-07, issue 32: 60-145 s each there).
# They run first with the doc pages, so none of them is handed to a worker last while the other idles (the
# order is all that hangs on the numbers).
LONG_TESTS = {
    "test_paper_reproduction.py::test_the_cylinder_head_read_as_the_paper_read_it": 3.0,
    "test_run_vibration_commands.py::test_demo_warns_of_each_run_that_vibrated": 3.0,
    "test_campaign_scale.py::test_100k_rows_under_a_memory_cap": 2.5,
    "test_user_job.py::test_the_users_job_is_not_made_worse_by_compensation": 1.5,
    "test_paper_reproduction.py::test_the_block_is_the_papers_within_25_percent": 1.5,
    "test_rsi_restart.py::test_simulated_krc_restarting_mid_path": 1.5,
    "test_preview.py::test_no_gouge_at_a_fast_corner_needs_preview_and_feed_plan": 1.5,
}


def pytest_configure(config):
    """A pytest started in the background by a non-interactive shell (`cmd &`, as a CI script or `nohup` may
    start it) inherits SIGINT ignored, and CPython then leaves it ignored (it installs its own handler only where
    SIGINT is at its default): the commands the tests start would inherit that too, and a test that interrupts
    one would see it run to its end.  Python's own handler from the start, as in a terminal (before, the first
    test was named by _sigint_left_as_found below for a state it had inherited)."""
    import signal

    if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)
    config.addinivalue_line("markers", "heavy(weight): a long test (a doc page of tests/test_wheel_install.py), run "
                                       "first, the heaviest first (weight: a rough relative size)")


def pytest_collection_modifyitems(config, items):
    for item in items:
        if item.path.name in REALTIME_FILES and item.get_closest_marker("untimed") is None:
            item.add_marker(pytest.mark.realtime)
    # the long tests first, the heaviest first, the rest behind them in their order: pytest-xdist hands the
    # first tests out to its workers in turn, so the long ones start at once on both and the short ones fill
    # in at the end (one 753 s test collected last was CI's critical path, issue 32)
    def weight(item):
        m = item.get_closest_marker("heavy")
        return LONG_TESTS.get(f"{item.path.name}::{item.name}", -1) if m is None else m.args[0]

    items.sort(key=lambda item: -weight(item) if weight(item) >= 0 else 1)


@pytest.fixture(scope="session", autouse=True)
def _urdf_cache(tmp_path_factory):
    """Generated URDFs (and the user models, joint references and preview tables the runs keep in the same
    folder, plant.cache_dir()) go to a temporary folder, not the user's cache: one for the test session, which
    both pytest-xdist workers (and the commands the tests start) share, as a user's processes share their
    ~/.cache/robstiff-drake.  Its files are named by a digest of their inputs and of the code that makes them,
    and written whole (a temporary file renamed), so a worker reads the other's or computes the same.  (One per
    worker before: each computed the identified models of the same scenarios again, about 12 s of CPU each for
    a block test's.)  A test that needs a cold cache sets its own (tests/test_ik_path.py, test_robot_files.py)."""
    from robstiff_drake.plant import CACHE_ENV

    old = os.environ.get(CACHE_ENV)
    base = tmp_path_factory.getbasetemp()
    folder = (base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base) / "robstiff_cache"
    folder.mkdir(exist_ok=True)
    os.environ[CACHE_ENV] = str(folder)
    yield
    if old is None:
        os.environ.pop(CACHE_ENV, None)
    else:
        os.environ[CACHE_ENV] = old


@pytest.fixture(autouse=True)
def _sigint_left_as_found(request):
    """After each test, Ctrl-C's handler is Python's own again.  A test that leaves SIGINT ignored in its
    pytest worker (SIG_IGN) makes every command a later test starts there inherit it: the children of an
    ignoring parent ignore Ctrl-C (CPython installs its handler only where SIGINT is at its default), so the
    tests that interrupt a command saw it run to its end (exit 0; seen once under load, in two tests of one
    worker).  Restored here, and named in a warning, so the test that left it is found."""
    import signal
    import threading
    import warnings

    yield
    if threading.current_thread() is not threading.main_thread():
        return
    handler = signal.getsignal(signal.SIGINT)
    if handler is not signal.default_int_handler:
        signal.signal(signal.SIGINT, signal.default_int_handler)
        warnings.warn(f"{request.node.nodeid} left SIGINT's handler as {handler!r}: restored")


@pytest.fixture(autouse=True)
def _collect_on_the_main_thread():
    """After each test, the garbage cycles it left are collected here, on the main thread.  Left to chance, a
    collection can run in whatever thread allocates next (a Dask client's event loop in test_sweep did): a cycle
    holding a Drake object whose C++ side owns a thread (Meshcat's server) then ends in that thread, and a
    pytest worker aborted ("Fatal Python error: Aborted" while garbage-collecting in tornado's loop).

    Then what survived is frozen (gc.freeze: out of every later collection's walk), so that the next test's
    collection walks only what it made: a full walk of the workers' heap (Drake's, numba's, scipy's modules and
    the session's caches) took about 0.18 s after each of some 1,750 tests, 330 s of the two workers' CPU in a
    profiled run of the suite (2026-12-07, issue 32: the README's command under 15 minutes).  Cyclic garbage
    among the frozen objects is never collected, so never in another thread either: at most memory, which a test
    process gives back when it ends."""
    yield
    import gc

    gc.collect()
    gc.freeze()


@pytest.fixture(scope="session")
def robot():
    return load_robot()


@pytest.fixture
def rng():
    return np.random.default_rng(20261121)


def random_q(robot, rng, n=None):
    """Random configurations inside the joint limits (rad)."""
    size = (6,) if n is None else (n, 6)
    return rng.uniform(robot.q_lower_rad, robot.q_upper_rad, size=size)


@pytest.fixture(scope="session")
def short_run_folder(tmp_path_factory):
    """A run folder of tests/data/short_block.yaml's compensated cut (made
    once; copy it before changing anything in it)."""
    from pathlib import Path

    from robstiff_drake.commands.main import main

    d = tmp_path_factory.mktemp("short_run")
    scenario = Path(__file__).parent / "data" / "short_block.yaml"
    assert main(["simulate", str(scenario), "--compensation", "on", "--out", str(d / "cut"), "--quiet"]) == 0
    return d / "cut"
