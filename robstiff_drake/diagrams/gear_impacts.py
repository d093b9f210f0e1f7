"""Flank impacts in the plant's gears: the bare compliant arm
(diagrams/compliant_arm.py) at a pose, its controller holding the pose, a
torque ``load_Nm`` on one joint's link that presses its gear onto a flank
and is taken away at ``release_s``.  The link then springs off the flank,
crosses the play and hits the other flank, and rattles until the gear's
damping (and the friction inside the play, if any) has taken the energy.

What is measured, from the link and motor angles every plant step:

* the coefficient of restitution of each impact: the twist rate
  phi' = theta' - q' leaving a flank over the rate arriving at it (both
  read in the play, where no gear torque acts: flight is free there, so a
  rate read at any step of it is the impact's);
* the flank crossings after the release and the rattle's duration: the
  time from the release to the last step at which the link leaves a
  flank (a link that stays on a flank or in the play, at rest, has
  stopped).

studies/time_step_convergence.py reports them against the plant's step.
"""

import numpy as np
from pydrake.multibody.plant import MultibodyPlantConfig
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource, VectorLogSink

from robstiff_drake.diagrams.compliant_arm import add_compliant_arm, gravity_holding_torque, set_drives_at_rest
from robstiff_drake.model import transmission
from robstiff_drake.systems.leaf_system import LeafSystem


class JointLoadStep(LeafSystem):
    """A torque ``load_Nm`` on joint ``joint``'s link (generalized force,
    N*m) until ``release_s``, zero after."""

    def __init__(self, joint, load_Nm, release_s):
        super().__init__()
        self._j, self._load, self._t = int(joint), float(load_Nm), float(release_s)
        self.DeclareVectorOutputPort("tau", 6, self._calc)

    def _calc(self, context, output):
        tau = np.zeros(6)
        if context.get_time() < self._t - 1e-12:
            tau[self._j] = self._load
        output.SetFromVector(tau)


def joint_load_run(robot, q_rad, load, *, step_s, play_rad, joint, initial_load_Nm, duration_s, servo,
                   damping_ratios=0.05, gap_friction_Nm=None):
    """(t (n,), phi (n,), phi' (n,)) of joint ``joint``'s gear (rad, rad/s)
    every plant step ``step_s``, the bare arm holding ``q_rad`` with the
    LeafSystem ``load`` (output: generalized forces (6), N*m) on its links,
    started at rest under ``initial_load_Nm`` on that joint (the link on
    the flank it presses); ``play_rad`` (6,) the half-widths,
    ``gap_friction_Nm`` the friction inside the play (None: the plant's
    default)."""
    builder = DiagramBuilder()
    k = np.asarray(robot.joint_stiffness_Nm_per_rad, dtype=float)
    arm = add_compliant_arm(builder, robot=robot, plant_config=MultibodyPlantConfig(time_step=step_s),
                            joint_stiffness_Nm_per_rad=k, damping_ratios=damping_ratios, q_modes_rad=q_rad,
                            servo=servo, interpolator_period_s=step_s, lost_motion_rad=play_rad,
                            gap_friction_Nm=gap_friction_Nm, check_resolution=False)
    plant = arm["plant"]
    for port, value in ((arm["position_command"], q_rad), (arm["velocity_command"], np.zeros(6))):
        builder.Connect(builder.AddSystem(ConstantVectorSource(value)).get_output_port(), port)
    builder.AddSystem(load)
    builder.Connect(load.get_output_port(), plant.get_applied_generalized_force_input_port())
    links = builder.AddSystem(VectorLogSink(12, step_s))
    motors = builder.AddSystem(VectorLogSink(12, step_s))
    builder.Connect(plant.get_state_output_port(), links.get_input_port())
    builder.Connect(arm["motor_state"], motors.get_input_port())
    sim = Simulator(builder.Build())
    root = sim.get_mutable_context()
    # at rest with the load on: the gear carries gravity's torque and the load, the link on the flank they press
    hold = gravity_holding_torque(arm["controller_plant"], q_rad)
    hold[joint] -= initial_load_Nm
    theta = q_rad + transmission.play_twist(hold, 1.0 / k, play_rad)
    plant.SetPositions(plant.GetMyMutableContextFromRoot(root), q_rad)
    set_drives_at_rest(arm, root, theta, q_rad)
    sim.AdvanceTo(duration_s)
    L = links.FindLog(sim.get_context())
    Mo = motors.FindLog(sim.get_context())
    t = L.sample_times()
    phi = Mo.data()[joint] - L.data()[joint]
    rate = Mo.data()[6 + joint] - L.data()[6 + joint]
    return t, phi, rate


def release_run(robot, q_rad, *, step_s, play_rad, joint, load_Nm, release_s, duration_s, damping_ratios=0.05,
                servo, gap_friction_Nm=None):
    """``joint_load_run`` of the release experiment (module docstring): a
    torque ``load_Nm`` on the joint's link until ``release_s``."""
    return joint_load_run(robot, q_rad, JointLoadStep(joint, load_Nm, release_s), step_s=step_s, play_rad=play_rad,
                          joint=joint, initial_load_Nm=load_Nm, duration_s=duration_s, servo=servo,
                          damping_ratios=damping_ratios, gap_friction_Nm=gap_friction_Nm)


def impacts(t, phi, rate, b_rad, after_s):
    """(restitution coefficients of the impacts after ``after_s``, the
    flank crossings after it, the rattle's duration s): see the module
    docstring.  An impact is a stay on a flank (|phi| > b) between two
    flights in the play; its coefficient is |rate leaving| / |rate
    arriving| (rates read in the play, the samples next to the stay)."""
    sel = t >= after_s - 1e-12
    t, phi, rate = t[sel], phi[sel], rate[sel]
    on = np.abs(phi) > b_rad
    change = np.flatnonzero(on[1:] != on[:-1]) + 1  # first sample of each new state
    crossings = len(change)
    leaves = [i for i in change if not on[i]]
    duration = float(t[leaves[-1]] - t[0]) if leaves else 0.0
    e = []
    for a, c in zip(change[:-1], change[1:]):  # a: enters a flank, c: leaves it
        if on[a] and not on[c] and a >= 1 and not on[a - 1]:
            v_in, v_out = rate[a - 1], rate[c]
            if abs(v_in) > 0 and np.sign(phi[a]) * v_in > 0:  # arriving at the flank, not sliding off it
                e.append(abs(v_out) / abs(v_in))
    return np.array(e), crossings, duration
