"""The online compensator on top of a program corrected offline hears the
measured wrench less the model's only where the model's force is steady
(model/program_correction.steady_mask, systems/steady_residual.py): at an
entry the measured force follows the tool's real motion, later than the
model's, and that difference is timing, not a force the program misses."""

import numpy as np

from robstiff_drake.model.program_correction import steady_mask
from robstiff_drake.systems.steady_residual import SteadyResidual


def _step(t):
    """A model force (N, 3): zero, then a 0.1 s ramp to (80, 200, -30) N at 1 s."""
    return np.outer(np.clip((t - 1.0) / 0.1, 0.0, 1.0), [80.0, 200.0, -30.0])


def test_the_mask_is_off_while_the_force_changes_and_for_its_window_after():
    t = np.arange(0.0, 3.0, 0.002)
    m = steady_mask(t, _step(t), window_s=0.6, ahead_s=0.1)
    assert m[t < 0.9].all()  # in the air: nothing changes, nor will for 0.1 s
    assert not m[(t > 0.905) & (t < 1.69)].any()  # the rise ahead, rising, then within the window of the rise
    assert m[t > 1.71].all()  # steady for the whole window


def test_the_residual_is_held_where_the_model_is_not_steady():
    t = np.arange(0.0, 3.0, 0.002)
    w = np.hstack([_step(t), np.zeros((len(t), 3))])
    block = SteadyResidual(t, w, steady_mask(t, w[:, :3], window_s=0.6), period_s=0.001)
    ctx = block.CreateDefaultContext()
    state = block.AllocateDiscreteVariables()
    gravity = np.array([3.0, -2.0, 397.0, 0.1, 0.2, 0.0])
    out = {}
    for k in range(3000):
        tk = k * 0.001
        ctx.SetTime(tk)
        # the measured force: the model's 0.4 s late and 10 % stronger, plus the payload's weight
        late = np.hstack([1.1 * _step(np.array([tk - 0.4]))[0], np.zeros(3)])
        block.get_input_port().FixValue(ctx, gravity + late)
        block._update(ctx, state)
        ctx.SetDiscreteState(state)
        out[round(tk, 3)] = block.get_output_port().Eval(ctx).copy()
    assert np.allclose(out[0.9], gravity)  # air: measured less zero
    for tk in (1.05, 1.2, 1.45, 1.6):  # the model's rise and its window: one residual held, the air's
        # (to the mask's 5 N floor: the ramp's first ticks count as steady), not the 200 N of the late rise
        assert np.array_equal(out[tk], out[1.05]), tk
        assert np.allclose(out[tk], gravity, atol=10.0), tk
    tail = gravity + np.r_[0.1 * np.array([80.0, 200.0, -30.0]), np.zeros(3)]
    assert np.allclose(out[2.5], tail)  # steady: measured less model, the 10 % the model misses


def _exit(t):
    """A model force (N, 3): zero, a 0.1 s ramp to (80, 200, -30) N at 0.1 s, then a 0.1 s ramp to zero at
    1 s (the cutter leaving)."""
    return np.outer(np.clip(np.minimum(t - 0.1, 1.1 - t) / 0.1, 0.0, 1.0), [80.0, 200.0, -30.0])


def test_the_mask_closes_before_the_model_force_moves():
    t = np.arange(0.0, 3.0, 0.002)
    m = steady_mask(t, _exit(t), window_s=0.6, ahead_s=0.1)
    assert m[(t > 0.805) & (t < 0.91)].all()
    # closed 0.1 s before the model's force has moved by 10 %: a residual held there is the steady cut's
    assert not m[(t > 0.915) & (t < 1.69)].any()
    assert m[t > 1.7].all()


def _run(block, measured, n=3000, dt=0.001):
    ctx = block.CreateDefaultContext()
    state = block.AllocateDiscreteVariables()
    out = {}
    for k in range(n):
        tk = k * dt
        ctx.SetTime(tk)
        block.get_input_port().FixValue(ctx, measured(tk))
        block._update(ctx, state)
        ctx.SetDiscreteState(state)
        out[round(tk, 3)] = block.get_output_port().Eval(ctx).copy()
    return out


def test_the_held_residual_goes_with_the_model_force_at_an_exit():
    """face_contour_fanuc (issue 29): the steady contour's law difference,
    held at full size through the lead-out and exit where the cut's force
    was gone, lowered the tool 0.09 mm into the floor.  Held, it now goes
    with the model's force: to the air's residual when the model's is nil."""
    t = np.arange(0.0, 3.0, 0.002)
    w = np.hstack([_exit(t), np.zeros((len(t), 3))])
    block = SteadyResidual(t, w, steady_mask(t, w[:, :3], window_s=0.6), period_s=0.001)
    gravity = np.array([3.0, -2.0, 397.0, 0.1, 0.2, 0.0])

    def measured(tk):  # the model's force 10 % stronger, 0.05 s late
        return gravity + np.hstack([1.1 * _exit(np.array([tk - 0.05]))[0], np.zeros(3)])

    out = _run(block, measured)
    diff = np.r_[0.1 * np.array([80.0, 200.0, -30.0]), np.zeros(3)]
    assert np.allclose(out[0.85], gravity + diff)  # steady: the 10 % the model misses
    assert np.allclose(out[0.95], gravity + diff)  # held from before the model's force moves: the same
    assert np.allclose(out[1.05], gravity + 0.5 * diff, atol=1e-6)  # half the model's force: half the difference
    for tk in (1.1, 1.3, 1.6):  # the model's force nil, its window not yet past: the air's residual
        assert np.allclose(out[tk], gravity), tk


def _arc(t):
    """A model wrench (N, 6): in the air, then from 0.1 s (a 0.1 s ramp) a 200 N feed-plane force with a -30 N
    axial part, turning 90 degrees about the tool's axis from 1 to 2.5 s (an arc), steady before and after; its
    torque at the sensor that of the force at a tool point 0.3 m down the axis (N m)."""
    a = np.clip((t - 1.0) / 1.5, 0.0, 1.0) * np.pi / 2
    f = np.column_stack([200.0 * np.cos(a), 200.0 * np.sin(a), np.full_like(a, -30.0)])
    f *= np.clip((t - 0.1) / 0.1, 0.0, 1.0)[:, None]
    return np.hstack([f, np.cross([0.0, 0.0, 0.3], f)])


def test_the_turn_falls_back_to_the_force_alone_without_a_lever():
    from robstiff_drake.systems.steady_residual import turn

    w0, w1 = np.r_[200.0, 0.0, -30.0, 0.0, 0.0, 0.0], np.r_[0.0, 200.0, -30.0, 0.0, 0.0, 0.0]
    R = turn(w0, w1)
    assert np.allclose(R @ w0[:3], w1[:3]) and np.allclose(R @ R.T, np.eye(3))
    back = turn(w0, -w0)  # a reversal: a half turn
    assert np.allclose(back @ w0[:3], -w0[:3]) and np.allclose(back @ back.T, np.eye(3))


def test_the_held_residual_turns_with_the_model_force_through_an_arc():
    """Through an arc the model's force turns and steady_mask holds the residual (the force moves by more than
    10 % over its window): the law's difference, a force of the cut, turns with it.  Unturned (before), at the
    arc's end the held difference pointed along the old feed: 28 N across the new one."""
    t = np.arange(0.0, 4.0, 0.002)
    w = _arc(t)
    mask = steady_mask(t, w[:, :3], window_s=0.6)
    block = SteadyResidual(t, w, mask, period_s=0.001)
    gravity = np.array([3.0, -2.0, 397.0, 0.1, 0.2, 0.0])

    def measured(tk):  # the model's wrench 10 % stronger
        return gravity + 1.1 * _arc(np.array([tk]))[0]

    out = _run(block, measured, n=4000)
    assert not mask[(t > 1.2) & (t < 2.5)].any()  # the arc is held
    for tk in (1.6, 2.0, 2.4, 2.6):
        want = gravity + 0.1 * _arc(np.array([tk]))[0]
        # force and torque alike, axial force and all (the smallest turn of the force alone left the torque 1.0 N m
        # off at 2.0 s, 17 % of its difference)
        assert np.allclose(out[tk], want, atol=1e-6), (tk, out[tk], want)
    assert np.allclose(out[3.9], gravity + 0.1 * _arc(np.array([3.9]))[0])  # steady again: measured less model
