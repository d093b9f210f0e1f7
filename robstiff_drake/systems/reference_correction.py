"""Joint-reference correction: the next joint target is the path reference
plus a correction that cancels the predicted deflection, updated once per
controller period, with a rate limit (the saturation is Drake's Saturation
block in front of it, and the transport delay a DiscreteTimeDelay).

The compensator diagram runs this inside its one block per tick
(systems/compensator_tick.py); this block alone is the reference that one
is tested against, bit for bit (tests/test_compensator_tick.py)."""

import math

import numpy as np
from robstiff_drake.systems.leaf_system import LeafSystem

from robstiff_drake.model.compensator import rate_limited_step


class RateLimitedCorrection(LeafSystem):
    """Input ``dq`` (6, rad): predicted deflection (already delayed and
    saturated).  Every ``period_s`` the held correction moves towards -dq by
    at most ``rate_limit_rad_per_s * period_s`` per joint.  Output
    ``correction`` (6, rad), held between updates.  A non-finite input
    leaves the correction where it is."""

    def __init__(self, *, period_s, rate_limit_rad_per_s):
        super().__init__()
        self._step = (np.asarray(rate_limit_rad_per_s, dtype=float) * period_s * np.ones(6)).tolist()
        self._dq = self.DeclareVectorInputPort("dq", 6)
        self._state = self.DeclareDiscreteState(6)
        self.DeclarePeriodicDiscreteUpdateEvent(period_s, 0.0, self._update)
        self.DeclareStateOutputPort("correction", self._state)

    def _update(self, context, discrete_state):
        dq = self._dq.Eval(context).tolist()
        if not math.isfinite(sum(dq)):
            return
        held = discrete_state.get_mutable_vector(int(self._state)).get_mutable_value()  # the current correction
        held[:] = rate_limited_step(held.tolist(), dq, self._step)  # (model/compensator.py)
