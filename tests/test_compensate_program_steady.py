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
    m = steady_mask(t, _step(t), window_s=0.6)
    assert m[t < 1.0].all()  # in the air: nothing changes
    assert not m[(t > 1.005) & (t < 1.69)].any()  # rising, then within the window of the rise
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
