"""`compensate --mode preview` never waits on the job's table: while it is
computed in the background (cell/preview_job.BackgroundTable) every
message is answered by the plain chain; once it is ready the loop
previews from that message on, its check of the controller's clock
counting from the session's time then (a table taken 0.2 s into the
session is not "out of step" for it), and says so.  Scripted messages in
lockstep (one message, then its answer), the table's readiness switched
at a given message: no timing.  And the disk cache: the same job with the
same numbers is read back whole, other numbers miss it."""

import io
import time

import numpy as np
import pytest

import cell_helpers as h
from robstiff_drake.cell import preview_cache
from robstiff_drake.cell.compensate import CompensatorLoop, LoopSettings, Reference
from robstiff_drake.cell.link import Message
from robstiff_drake.cell.preview_job import load_job, table_file
from robstiff_drake.cell.preview_table import PreviewDeflection
from robstiff_drake.model.filters import filter_coefficients

READY_AT = 50  # the message at which the table is ready (0.2 s of the controller's clock)
MESSAGES = 120


class _Table:
    """A BackgroundTable stand-in: ``done`` once the link has handed out message READY_AT."""

    def __init__(self, preview):
        self.done, self.preview, self.error, self.seconds = False, None, None, 1.0
        self._ready = preview
        self.taken_at_s = None


class _Link:
    name, option, port = "EGM", "--egm-port", 0
    strangers = malformed = 0

    def __init__(self, q_rows, table):
        self.q, self.table, self.k, self.sent = q_rows, table, 1, []

    def send_targets(self, msg, target, env):
        self.sent.append((msg.seq, list(target)))

    def receive(self, timeout_s):
        self.k += 1
        if self.k > MESSAGES:
            raise KeyboardInterrupt  # (the script's end)
        if self.k == READY_AT:
            self.table.preview, self.table.done = self.table._ready, True
        return [(_msg(self.k, self.q), time.monotonic())]


def _msg(k, q):
    return Message(k, (k - 1) * 4, list(q[min(k - 1, len(q) - 1)]), echo=k)


class _Sensor:
    def __init__(self, w):
        self.w = w

    def drain(self):
        return [(self.w, time.monotonic(), 0, False)] * 4


@pytest.fixture(scope="module")
def job():
    sc, robot = load_job(h.os.path.join(h.ROOT, "tests", "data", "short_block.yaml"), None, period_s=0.004)
    file = h.cached_preview_table(h.os.path.join(h.ROOT, "tests", "data", "short_block.yaml"))
    return sc, robot, file


def test_the_loop_answers_plain_until_the_table_is_ready_then_previews(job):
    sc, robot, file = job
    plan = preview_cache.load(file)
    assert plan is not None
    q = plan.q_plan_deg  # the feedback where the plan puts it (in step with the plan)
    w = h.hold_wrench(robot, np.radians(q[0]))(0.0).tolist()
    comp = h.hold_compensator(robot, w)
    plain = comp.model
    ref = Reference(plan.t_ref_s, plan.q_ref_deg, period_s=0.004)
    table = _Table(PreviewDeflection(plain, plan, sync_s=0.025, force_bound_N=150.0, force_bound_fraction=0.5))
    link = _Link(q, table)
    loop = CompensatorLoop(comp, link, _Sensor(w), ref, robot, LoopSettings(max_jump_Nm=350.0), out=io.StringIO())
    loop.pending_preview = table
    models = []
    cycle = loop.cycle

    def watched(msg, t_arr, dt, **how):  # (how: whether it counts late, cell/compensate's)
        out = cycle(msg, t_arr, dt, **how)
        models.append((msg.seq, loop.comp.model, loop.preview))
        return out

    loop.cycle = watched
    loop.run((_msg(1, q), time.monotonic()))
    # every message answered, the plain chain until the table was ready, the preview from that message on
    assert [s for s, _ in link.sent] == list(range(1, MESSAGES + 1))
    assert all(m is plain and p is None for s, m, p in models if s < READY_AT)
    assert all(m is table._ready and p is table._ready for s, m, p in models if s >= READY_AT)
    pv = loop.preview
    assert table.taken_at_s == pytest.approx((READY_AT - 1) * 0.004)
    # its clock check counts from then: not stopped (before: its clock from zero against the session's 0.2 s)
    assert pv.fallback is None, pv.fallback
    said = loop.out.getvalue()
    assert "preview: the job's table is ready" in said, said
    assert [e for _, _, e in loop.n.events] == ["interrupted: the run ends"]  # (the script's end; the table's a note)


def test_the_table_is_read_back_from_the_cache_whole_and_other_numbers_miss_it(job):
    sc, robot, file = job
    plan = preview_cache.load(file)
    ba = filter_coefficients("lowpass", 2.0, 2, 1000.0, 3600.0)
    same = table_file(sc, robot, robot.joint_stiffness_Nm_per_rad, period_s=0.004, filter_ba=ba, rate_hz=1000.0,
                      delay_steps=0, servo=None)
    assert same == file
    again = preview_cache.load(same)
    for name in preview_cache.ARRAYS:
        np.testing.assert_array_equal(getattr(again, name), getattr(plan, name))
    assert again.servo == plan.servo and again.lag_s == plan.lag_s
    others = [table_file(sc, robot, robot.joint_stiffness_Nm_per_rad * 0.9, period_s=0.004, filter_ba=ba,
                         rate_hz=1000.0, delay_steps=0, servo=None),
              table_file(sc, robot, robot.joint_stiffness_Nm_per_rad, period_s=0.004,
                         filter_ba=filter_coefficients("lowpass", 3.0, 2, 1000.0, 3600.0), rate_hz=1000.0,
                         delay_steps=0, servo=None),
              table_file(sc, robot, robot.joint_stiffness_Nm_per_rad, period_s=0.004, filter_ba=ba, rate_hz=1000.0,
                         delay_steps=1, servo=None),
              table_file(sc, robot, robot.joint_stiffness_Nm_per_rad, period_s=0.004, filter_ba=ba, rate_hz=1000.0,
                         delay_steps=0, servo=[12.0, 60.0, 30.0, 1.0])]
    assert len({file, *others}) == 5
    # a file that is not a table is not taken
    bad = file.with_name("preview-table-not-a-table.npz")
    bad.write_bytes(b"not a table")
    assert preview_cache.load(bad) is None
