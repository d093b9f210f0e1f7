"""Does the compensated cell's loop grow or decay?  The Drake closed-loop
cell (diagrams/milling_cell.py: the station with its compliant arm,
drives and wrist sensor, and the compensator) held in air at the path's
first pose, kicked once, and watched: the growth rate of its oscillation's
envelope, to set beside the linear loop model's spectral radius
(model/loop_check.py), which shares neither the Drake plant's multibody
arm nor its discrete scheme.

The kick: the links' velocities at the start (``KICK_RAD_PER_S`` on joints
2 and 3, the first mode's); the sensor's noise is off, so that what grows
or decays is the loop's own motion.  The envelope: in windows of
``WINDOW_S``, the largest deviation of any joint from the window's straight
line (the slow settling taken out); its logarithm fitted by a straight line
over the windows after ``SETTLE_S``.

Units: angles rad, times s, growth rates 1/s (negative: decaying).
"""

import copy
from dataclasses import dataclass

import numpy as np

from robstiff_drake.diagrams.milling_cell import build_milling_cell, make_simulator
from robstiff_drake.diagrams.sweep import configure

KICK_RAD_PER_S = 2e-3  # small: the correction stays far from its saturation and rate limit (linear)
WINDOW_S = 0.5
SETTLE_S = 1.0  # the kick's faster modes die out first


@dataclass
class HoldResponse:
    cutoff_hz: float
    growth_per_s: float  # the envelope's fitted growth rate (1/s)
    envelope_rad: list  # per window
    window_starts_s: list
    simulated_s: float
    wall_s: float

    @property
    def grows(self):
        return self.growth_per_s > 0.0


def held_in_air(sc):
    """A copy of scenario ``sc`` whose path dwells at its first point (the
    cutter clear of the work) for the whole run, without sensor noise."""
    sc = copy.deepcopy(sc)
    sc.path.dwell_s = 60.0
    sc.sensor.noise_N = 0.0
    sc.sensor.noise_Nm = 0.0
    return sc


def hold_response(sc, robot, cutoff_hz, seconds=4.0):
    """Run the cell of scenario ``sc`` (plain compensation, its period and
    delay, a low-pass of ``cutoff_hz``) held in air and kicked; the
    envelope's growth (HoldResponse)."""
    import time

    combo = {"period_ms": sc.controller.period_ms, "delay_steps": sc.controller.delay_steps,
             "cutoff_hz": float(cutoff_hz), "mode": "plain"}
    cell = build_milling_cell(held_in_air(configure(sc, combo)), robot, compensation=True)
    sim = make_simulator(cell)
    root = sim.get_mutable_context()
    plant = cell.station.plant
    pc = plant.GetMyMutableContextFromRoot(root)
    v = plant.GetVelocities(pc).copy()
    v[1] += KICK_RAD_PER_S
    v[2] -= KICK_RAD_PER_S
    plant.SetVelocities(pc, v)
    t0 = time.perf_counter()
    sim.AdvanceTo(seconds)
    wall = time.perf_counter() - t0
    t, x = cell.loggers["state"].read(root)
    q = x[:, :6]
    starts = np.arange(0.0, seconds - WINDOW_S + 1e-9, WINDOW_S)
    env = []
    for a in starts:
        m = (t >= a) & (t < a + WINDOW_S)
        tt = t[m] - t[m].mean()
        coef = np.polyfit(tt, q[m], 1)  # (2, 6): each joint's straight line
        env.append(float(np.abs(q[m] - (np.outer(tt, coef[0]) + coef[1])).max()))
    env = np.array(env)
    use = starts >= SETTLE_S
    growth = float(np.polyfit(starts[use] + 0.5 * WINDOW_S, np.log(env[use]), 1)[0])
    return HoldResponse(float(cutoff_hz), growth, env.tolist(), starts.tolist(), float(seconds), wall)
