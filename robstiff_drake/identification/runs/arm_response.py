"""How the arm and its servo respond to what a run logs: the linear model of
the joints (model/loop_model.LoopModel's arm and motor-side servo, without
its compensator) driven by the logged signals instead of a force model.
Plain numpy; the caller supplies the joints' linear model (model/
joint_dynamics.JointModel: mass matrix, the weight's stiffness, the gears'
damping, motors and drives; diagrams/run_arm.py computes it from the robot
file).

In coordinates relative to where the arm is meant to be, the program's
angles a fixed time late (the interpolator's dead time: the path's velocity
is fed forward, so the servo adds no other lag to it), three inputs move
the links (rad, (n, 6)):

* ``motion``: the path's own motion (LoopModel's path terms: its
  acceleration through the soft gears, and the part of the motor
  reference that gets no velocity feed-forward: (f_v - 1) q', and the rate
  of the controller's gravity model, whose twist is added to the position
  reference only, as in diagrams/station.py);
* ``correction``: the compensator's correction, after the interpolator's
  dead time, through the position loop (no feed-forward);
* ``load``: the process load's joint torques J^T W through the gears.

What the linearisation about the path leaves out is added as joint torques
by the caller: the velocity terms of the arm's inertia c(q, q') (the path's
acceleration is in the path terms) and the gears' damping of the gravity
twist's rate, beta K d/dt(C g) = beta g'.

The model is linearised at a few poses along the path (one per segment of
SEGMENT_S seconds) and stepped exactly (zero-order hold) every STEP_S.
"""

import numpy as np

from robstiff_drake.model.loop_model import LoopModel

STEP_S = 1e-3  # the response's step (s): the interpolator's dead time is a whole number of these
SEGMENT_S = 0.5  # the linearisation is redone every this many seconds of the run (s)
_NO_FILTER = (np.array([1.0]), np.array([1.0]))


def arm_matrices(joints, step_s=STEP_S):
    """(Ad, B_load, B_corr, B_path) of the arm, motors and drives at one pose
    (``joints``, a JointModel): state (q - q_path, its rate, theta -
    theta_path, its rate, the drives' integrals) (30), inputs joint torques
    (6, N*m), the drives' reference beyond the path (6, rad) and the path
    terms (18: 0, the velocity term, q_path'')."""
    loop = LoopModel(M=joints.M, K=joints.K, beta_s=None, J=np.eye(6), C_model=1.0 / np.diag(joints.K),
                     filter_ba=_NO_FILTER, rate_hz=1.0 / step_s, period_s=step_s, delay_steps=0,
                     gravity_stiffness=joints.G, joints=joints)
    return loop.Ad, loop.Bw, loop.Bc, loop.Br


def path_terms(q_path, step_s, velocity_feedforward, gravity_twist_rad):
    """(n, 18) path terms on a uniform grid of ``step_s``: (0, f_v q' - q' -
    d/dt(the gravity model's twist), q''); ``q_path`` (n, 6) rad, the
    gravity model's twist C g(q_path) (n, 6) rad."""
    v = np.gradient(q_path, step_s, axis=0)
    a = np.gradient(v, step_s, axis=0)
    twist_rate = np.gradient(gravity_twist_rad, step_s, axis=0)
    return np.hstack([np.zeros_like(q_path), (velocity_feedforward - 1.0) * v - twist_rate, a])


def delayed(x, steps):
    """x (n, k) delayed by ``steps`` samples (the first value held before it)."""
    if steps <= 0:
        return x
    return np.vstack([np.repeat(x[:1], steps, axis=0), x[:-steps]])


def responses(systems, segment, channels):
    """The links' deviation (n, 6, k) rad, one column per channel: each
    channel is (joint torques (n, 6) N*m, the servo's reference beyond the
    path (n, 6) rad, path terms (n, 18)), any of them None.  ``systems``: a
    list of arm_matrices, ``segment`` (n,) which one each step uses; every
    input on the same grid.  The arm starts at rest on the path."""
    n = len(segment)
    out = np.empty((n, 6, len(channels)))
    x = np.zeros((systems[0][0].shape[0], len(channels)))
    bounds = np.flatnonzero(np.diff(segment)) + 1
    for lo, hi in zip(np.r_[0, bounds], np.r_[bounds, n]):
        Ad, *B = systems[segment[lo]]
        push = np.zeros((hi - lo, x.shape[0], len(channels)))
        for c, inputs in enumerate(channels):
            for u, Bu in zip(inputs, B):
                if u is not None:
                    push[:, :, c] += u[lo:hi] @ Bu.T
        for k in range(hi - lo):
            out[lo + k] = x[:6]
            x = Ad @ x + push[k]
    return out
