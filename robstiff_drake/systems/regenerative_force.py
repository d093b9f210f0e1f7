"""The plant's milling force with the regenerative chip (scenario
``cutting.chip: regenerative``; issue 29): the tooth-resolved force source
of systems/milling_force.py whose teeth cut what the tool's own motion
left (model/regenerative_chip.py): each tooth's chip is the tool centre's
displacement since the earlier teeth's passes along the tooth's radius, a
tooth whose chip is <= 0 has left the cut.  So the chip follows the tool
(its direction and its size), the arm's modes feed back into the force
(regenerative chatter, its limit cycle with the teeth leaving the cut),
and no filter stands between them.  Tooth mode only, at a step that
resolves the teeth (diagrams/plant_step.unresolved_tooth_message).
"""

import math

import numpy as np

from robstiff_drake.model.regenerative_chip import RegenerativeChip, ToolHistory
from robstiff_drake.systems.milling_force import MillingForceSource


class RegenerativeForceSource(MillingForceSource):
    """MillingForceSource in tooth mode with the regenerative chip: the
    same ports and held state, plus the tool centre's history over a
    revolution (rows t s, x m, y m, per update) from which each tooth's
    chip is taken.  The feed and the program's direction it still tracks
    (``motion``) serve only the flank wear's clock and ``log``'s count of
    teeth out of the cut.

    ``log`` (None: nothing kept): a list that each update appends (t s,
    tool x, y, z m, force x, y, z N, engaged tooth samples, of them out of
    the cut) to (a study's record; the simulation does not read it)."""

    log = None

    def __init__(self, *, force_model, mode="tooth", log=None, **kw):
        if mode != "tooth":
            raise ValueError("the regenerative chip is tooth-resolved: mode must be 'tooth'")
        chip = RegenerativeChip(force_model, kw.get("phase_rad", 0.0))
        super().__init__(force_model=force_model, mode=mode, **kw)
        self._chip = chip
        self._history = ToolHistory(self._chip.memory_s, self._period)
        self._tool_hist = self.DeclareDiscreteState(self._history.empty())
        self._past_in = self._past_out = None
        if log is not None:
            self.log = log

    def _update(self, context, state):
        # (_step reads the history the update starts from and leaves the new one here: written after it)
        self._past_in = context.get_discrete_state(self._tool_hist).value()
        super()._update(context, state)
        state.get_mutable_discrete_state().set_value(int(self._tool_hist), self._past_out)

    def _regenerative(self, times, p, past, travel, u=None, feed=None):
        """(T, 6) wrenches at ``times`` for the tool point p (3, m) held and
        the history ``past`` (with p's row at the update); with the
        program's direction ``u`` and the feed (m/s), also (engaged, out)
        counts (RegenerativeChip.out_of_cut)."""
        times = np.asarray(times, dtype=float)
        back = ToolHistory.at(past, self._chip.past_times_s(times))  # (T, N, 2)
        out = self._chip.wrenches(times, p, back, self._workpiece, detail=u is not None, **self._wear_args(travel))
        if u is None:
            return out
        w, (theta, depth, h) = out
        return w, self._chip.out_of_cut(theta, depth, h, u, feed)

    def _step(self, t, q, process, hist, instants=()):
        pose = self._kin.pose_only(q)
        p = np.asarray(pose[9:], dtype=float)
        u, feed, hist = self.motion(t, p, hist)
        _, _, feed_held, travel = process.tolist() if hasattr(process, "tolist") else process
        feed = self.smoothed_feed(feed, feed_held)
        past = self._history.pushed(self._past_in if self._past_in is not None else self._history.empty(), t, p[:2])
        self._past_out = past
        n = len(self._sub_t)
        rows, (engaged, out) = self._regenerative(np.concatenate((t + self._sub_t, instants)), p, past, travel, u,
                                                  feed)
        w, inst = rows[:n].sum(axis=0) / n, rows[n:]
        if w[0] != 0.0 or w[1] != 0.0 or w[2] != 0.0:  # in the material: the edges travel (their wear's clock)
            travel += feed * self._period
        if self.log is not None:
            self.log.append((t, p[0], p[1], p[2], w[0], w[1], w[2], engaged, out))
        return w, pose, inst, np.array([float(u[0]), float(u[1]), feed, travel]), hist

    def _tooth_wrench_at(self, context, t, p):
        travel = context.get_discrete_state(self._process).value()[3]
        past = context.get_discrete_state(self._tool_hist).value()
        if math.isnan(past[-3]):
            return np.zeros(6)
        return self._regenerative([t], p, past, travel)[0]
