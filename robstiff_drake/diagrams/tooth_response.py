"""The arm's answer to the tooth-pass force at a plant step: the bare
compliant arm (diagrams/compliant_arm.py, no play) holding its pose, a
torque ripple A sin(2 pi f t) on one joint's link handed to the plant as
the milling force source hands it the tooth-resolved force
(systems/milling_force.py): held over each plant step at its mean over
the step, sampled ``samples_per_tooth`` times per tooth pass.  A step that
does not resolve the ripple folds it down (360 Hz at a 2 ms step: to
140 Hz, next to the IRB 6400's 126 Hz wrist mode) and moves the mode it
lands near (joint_dynamics.JointModel.step_modes).

``twist_per_Nm`` is the RMS of the joint's gear twist theta - q (its mean
removed) over the RMS of the ripple, in steady state: rad/(N*m).
studies/time_step_convergence.py reports it against the plant's step.
"""

import math

import numpy as np
from pydrake.multibody.plant import MultibodyPlantConfig
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import BasicVector, DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource, VectorLogSink

from robstiff_drake.diagrams.compliant_arm import add_compliant_arm, gravity_holding_torque, set_drives_at_rest
from robstiff_drake.systems.leaf_system import LeafSystem


class StepMeanRipple(LeafSystem):
    """A torque ``amplitude_Nm`` sin(2 pi ``f_hz`` t) on joint ``joint``'s
    link (generalized force, N*m), held over each ``step_s`` at its mean
    over the step (the milling force source's rule: round(step f
    samples_per_tooth) samples, at least one)."""

    def __init__(self, joint, amplitude_Nm, f_hz, step_s, samples_per_tooth=20):
        super().__init__()
        self._j, self._A, self._w = int(joint), float(amplitude_Nm), 2 * math.pi * float(f_hz)
        n = max(1, int(round(step_s * f_hz * samples_per_tooth)))
        self._sub = np.arange(n) * (step_s / n)
        self._tau = self.DeclareDiscreteState(6)
        self.DeclarePeriodicDiscreteUpdateEvent(step_s, 0.0, self._update)
        self.DeclareStateOutputPort("tau", self._tau)

    def _update(self, context, discrete):
        tau = np.zeros(6)
        tau[self._j] = self._A * np.mean(np.sin(self._w * (context.get_time() + self._sub)))
        discrete.set_value(0, tau)


def twist_per_Nm(robot, q_rad, *, step_s, servo, joint=5, f_hz=360.0, amplitude_Nm=10.0, duration_s=0.6,
                 settle_s=0.3, damping_ratios=0.05, samples_per_tooth=20):
    """The joint's RMS gear twist per RMS N*m of the tooth ripple (rad/(N*m))
    in steady state (after ``settle_s``): see the module docstring."""
    builder = DiagramBuilder()
    k = np.asarray(robot.joint_stiffness_Nm_per_rad, dtype=float)
    arm = add_compliant_arm(builder, robot=robot, plant_config=MultibodyPlantConfig(time_step=step_s),
                            joint_stiffness_Nm_per_rad=k, damping_ratios=damping_ratios, q_modes_rad=q_rad,
                            servo=servo, interpolator_period_s=step_s)
    plant = arm["plant"]
    for port, value in ((arm["position_command"], q_rad), (arm["velocity_command"], np.zeros(6))):
        builder.Connect(builder.AddSystem(ConstantVectorSource(value)).get_output_port(), port)
    ripple = builder.AddSystem(StepMeanRipple(joint, amplitude_Nm, f_hz, step_s, samples_per_tooth))
    builder.Connect(ripple.get_output_port(), plant.get_applied_generalized_force_input_port())
    links = builder.AddSystem(VectorLogSink(12, step_s))
    motors = builder.AddSystem(VectorLogSink(12, step_s))
    builder.Connect(plant.get_state_output_port(), links.get_input_port())
    builder.Connect(arm["motor_state"], motors.get_input_port())
    sim = Simulator(builder.Build())
    root = sim.get_mutable_context()
    theta = q_rad + gravity_holding_torque(arm["controller_plant"], q_rad) / k
    plant.SetPositions(plant.GetMyMutableContextFromRoot(root), q_rad)
    set_drives_at_rest(arm, root, theta, q_rad)
    sim.AdvanceTo(duration_s)
    t = links.FindLog(sim.get_context()).sample_times()
    phi = motors.FindLog(sim.get_context()).data()[joint] - links.FindLog(sim.get_context()).data()[joint]
    y = phi[t >= settle_s]
    return float(np.std(y) / (amplitude_Nm / math.sqrt(2.0)))
