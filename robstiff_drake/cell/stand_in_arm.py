"""The tests' and benchmarks' stand-in for the Drake station behind the
simulated cell (cell/sim_cell.CellNetwork's ``station``): no Drake, the
arm as a servo lag and the joints' compliance, the wrist sensor's reading
with noise.  (In cell/sim_cell.py before: its own idea, and that file over
400 lines.)"""

import math

import numpy as np


class ServoArmStandIn:
    """A stand-in for the Drake station in tests: the arm's motor angles
    follow the command through a first-order servo lag, the links deflect
    by the true joint compliance under a process wrench on the tool, and
    the wrist sensor reads the payload's weight, its bias and the process
    wrench (sensor frame), with Gaussian noise, ``sensor_samples`` times a
    cycle.

    ``process_wrench(t)`` -> (force N, moment N*m about the tool point),
    base frame.  ``reference(t)`` -> the joint reference (rad) the
    compensator streams; ``last_info``: (t, the tool point's error against
    the reference's tool point (m, base frame), 3 values)."""

    def __init__(self, *, robot, joint_stiffness_Nm_per_rad, calibration, process_wrench, reference,
                 q_start_rad, period_s=0.004, servo_lag_s=0.01, sensor_samples=4, noise_N=0.5, noise_Nm=0.05,
                 seed=0):
        from robstiff_drake.model.realtime import DeflectionPredictor

        self.kin = DeflectionPredictor(robot.dh, joint_stiffness_Nm_per_rad, robot.payload.tool_point_m)
        self.tool = tuple(float(v) for v in robot.payload.tool_point_m)
        self.cal = calibration
        self.W = process_wrench
        self.ref = reference
        self.T = float(period_s)
        self.alpha = 1.0 - math.exp(-self.T / servo_lag_s)
        self.theta = np.asarray(q_start_rad, dtype=float).copy()
        self.n = int(sensor_samples)
        self.noise = np.array([noise_N] * 3 + [noise_Nm] * 3)
        self.rng = np.random.default_rng(seed)
        self.k = 0
        self.last_info = None

    def hold(self):
        """At rest before EGM engages: the start pose, no process load, the clock stopped."""
        return self.theta.copy(), self._sensor(self.theta, np.zeros(6))

    def _sensor(self, q_link, W):
        from robstiff_drake.model.payload import payload_wrench
        from robstiff_drake.model.wrench_frames import to_sensor_frame

        R, _ = self.kin.flange_rotation_and_tool_point(q_link)
        w_sensor = payload_wrench(R, self.cal) + np.array(to_sensor_frame(R.ravel().tolist(), self.tool, W.tolist()))
        return w_sensor + self.rng.standard_normal((self.n, 6)) * self.noise

    def step(self, q_cmd_rad):
        t = self.k * self.T
        self.k += 1
        self.theta = self.theta + self.alpha * (np.asarray(q_cmd_rad, dtype=float) - self.theta)
        W = np.asarray(self.W(t), dtype=float)
        dq, _ = self.kin(self.theta, W)
        q_link = self.theta + dq
        _, p = self.kin.flange_rotation_and_tool_point(q_link)
        _, p_ref = self.kin.flange_rotation_and_tool_point(np.asarray(self.ref(t), dtype=float))
        self.last_info = (t, *(p - p_ref).tolist())
        return self.theta.copy(), self._sensor(q_link, W)
