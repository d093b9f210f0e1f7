"""cell/preview_table.py against the simulator's preview block
(systems/preview_correction.PreviewCorrection, a Drake LeafSystem): the
per-cycle work `compensate --mode preview` does from its precomputed table
(the filter replica offline, the scales' gains ahead) gives the block's
correction, cycle by cycle, for the same measured wrenches and poses."""

import numpy as np
import pytest

from robstiff_drake.cell.preview_job import build_plan, load_job
from robstiff_drake.cell.preview_table import PreviewDeflection
from robstiff_drake.model.compensator import DeflectionModel
from robstiff_drake.model.filters import lowpass_coefficients
from robstiff_drake.model.realtime import DeflectionPredictor
from robstiff_drake.systems.preview_correction import PreviewCorrection

from test_cell_preview import SHORT

T, RATE_HZ = 0.004, 1000.0


class _Loop:
    def __init__(self, comp):
        self.comp, self.faults, self.t_session, self.q_deg = comp, {}, 0.0, None
        self.t_ref = 0.0  # (the reference's played time the table follows: the session's here)

    def event(self, text):
        raise AssertionError(f"the preview stopped: {text}")


class _Comp:
    process_wrench = [0.0] * 6


@pytest.fixture(scope="module")
def plan():
    sc, robot = load_job(SHORT, None, period_s=T)
    ba = lowpass_coefficients(2.0, RATE_HZ)
    return sc, robot, ba, build_plan(sc, robot, robot.joint_stiffness_Nm_per_rad * 0.9, period_s=T, filter_ba=ba,
                                     rate_hz=RATE_HZ, delay_steps=1)


def test_the_tables_cycle_is_the_drake_blocks(plan):
    sc, robot, ba, p = plan
    tool = robot.payload.tool_point_m
    kin = DeflectionPredictor(robot.dh, robot.joint_stiffness_Nm_per_rad * 0.9, tool)
    model = DeflectionModel(kin, tool)
    block = PreviewCorrection(table=(p.u, p.c, p.sensor), deflection=model, filter_ba=ba, rate_hz=RATE_HZ,
                              period_s=T, lead_s=p.lead_s, lag_s=p.lag_s)
    ctx = block.CreateDefaultContext()
    w_port, q_port = block.GetInputPort("process_wrench"), block.GetInputPort("q")
    dq_port, s_port = block.GetOutputPort("dq"), block.GetOutputPort("scales")
    state = block.AllocateDiscreteVariables()
    comp = _Comp()
    prev = PreviewDeflection(model, p, sync_s=1.0, force_bound_N=1e5, force_bound_fraction=0.0)
    loop = _Loop(comp)
    rng = np.random.default_rng(1)
    worst, scale = 0.0, 0.0
    n = len(p.u) - 3
    for k in range(n):
        t = k * T
        # the measured wrench: the model's, 15 % stronger on the tangential group, and noise (the scales learn)
        w = (p.replica[k] * np.array([[1.15], [1.0], [1.0], [1.0]])).sum(axis=0) + rng.normal(size=6) * 2.0
        q = p.q_ref_deg[min(k, len(p.q_ref_deg) - 1)]
        q = np.radians(q)
        ctx.SetTime(t)
        w_port.FixValue(ctx, w)
        q_port.FixValue(ctx, q)
        # (the block's periodic update event; CalcForcedDiscreteVariableUpdate runs only forced ones)
        block._update(ctx, state)
        ctx.SetDiscreteState(state)
        ref = dq_port.Eval(ctx)
        comp.process_wrench = w.tolist()
        loop.t_session = loop.t_ref = t
        prev.update(loop, type("M", (), {"tm_ms": int(round(t * 1e3))})())
        got = np.asarray(prev.dq(w.tolist(), q.tolist()))
        worst = max(worst, float(np.max(np.abs(got - ref))))
        scale = max(scale, float(np.max(np.abs(ref))))
    s_block = s_port.Eval(ctx)
    print(f"{n} cycles: largest difference {worst * 1e6:.2e} urad of corrections up to {scale * 1e6:.1f} urad; "
          f"scales {np.round(prev.s, 4)} (block {np.round(s_block, 4)})")
    assert scale > 100e-6
    assert prev.learned > 100 and abs(prev.s[0] - 1.0) > 0.05  # the tangential scale learnt
    assert np.allclose(prev.s, s_block, atol=1e-6)
    assert worst < 1e-3 * scale
