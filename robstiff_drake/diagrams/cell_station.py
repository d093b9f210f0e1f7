"""The Drake station behind a real cell's protocols: what `robstiff
sim-cell` steps one EGM cycle at a time (cell/sim_cell.py's station
interface).

``CellStation(sc, robot)`` builds the scenario's station
(diagrams/station.py) alone, with its commands fixed per cycle:

* ``hold()``: at rest on the path's first point (the controller has not
  engaged yet); the clock does not move;
* ``step(q_cmd_rad)``: the joint target of the cycle (the controller's
  angles, rad) held for one period, its velocity the difference to the
  last target; returns what the controller reports (its joint angles, the
  controller's convention, rad) and every wrench sample the sensor took
  during the period (k, 6);
* ``last_info``: (time s, link angles rad): the truth, for the scan after
  the run; ``times``, ``q_link`` and ``cut_force_N`` (the cutting force's
  size, N) at the end of every cycle: the scan's and the vibration check's
  log (diagrams/run_vibration.cell_vibration);
* ``done``: the path (and its run-out) is over.

The station's clock starts at the first ``step``: the milling source reads
the path's feed direction by time, and the compensator streams the path
from its first answer.
"""

from types import SimpleNamespace

import numpy as np
from pydrake.common import RandomGenerator
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import LogVectorOutput

from robstiff_drake.diagrams.experiment import RUN_OUT_S, scanned_surface
from robstiff_drake.diagrams.milling_cell import build_station, planned_path
from robstiff_drake.diagrams.station import path_poses
from robstiff_drake.diagrams.scenario_models import cutting_setup
from robstiff_drake.identification.runs.logs import joint_reference_text


class CellStation:
    def __init__(self, sc, robot, *, period_s=0.004):
        self.sc, self.robot, self.T = sc, robot, float(period_s)
        tool = robot.tool_point(where="sim-cell")
        _, self.force_model, self.workpiece = cutting_setup(sc)
        self.path, self.t_ref, self.q_ref = planned_path(sc, robot, tool)
        self.station = build_station(sc, robot, q_modes_rad=path_poses(self.q_ref), path=self.path)
        builder = DiagramBuilder()
        st = builder.AddSystem(self.station.diagram)
        self._wrench_log = LogVectorOutput(st.GetOutputPort("wrench_measured"), builder, 1.0 / sc.sensor.rate_hz)
        self._system = st
        self.diagram = builder.Build()
        self.sim = Simulator(self.diagram)
        root = self.sim.get_mutable_context()
        self.diagram.SetRandomContext(root, RandomGenerator(int(sc.sensor.seed)))
        self._rest = self.station.set_initial_state(root, self.q_ref[0])
        self._ctx = st.GetMyMutableContextFromRoot(root)
        self._fix(self.q_ref[0], np.zeros(6))
        self.sim.Initialize()
        self._last_cmd = self.q_ref[0].copy()
        self._read = 0
        self.t_end = self.path.duration_s + RUN_OUT_S
        self.times, self.q_link, self.cut_force_N = [], [], []
        self.last_info = None
        self.tool_m = tool

    def _fix(self, q_model, v_model):
        self._system.GetInputPort("position_command").FixValue(self._ctx, q_model)
        self._system.GetInputPort("velocity_command").FixValue(self._ctx, v_model)

    def _report(self):
        q = self._system.GetOutputPort("position_measured").Eval(self._ctx)
        return self.robot.joint_map.to_controller(q)

    @property
    def done(self):
        return self.sim.get_context().get_time() >= self.t_end

    def hold(self):
        return self._report(), np.atleast_2d(self._rest[2])

    def step(self, q_cmd_rad):
        q = self.robot.joint_map.to_model(np.asarray(q_cmd_rad, dtype=float))
        self._fix(q, (q - self._last_cmd) / self.T)
        self._last_cmd = q
        t = self.sim.get_context().get_time() + self.T
        self.sim.AdvanceTo(t)
        log = self._wrench_log.FindLog(self.sim.get_context())
        data = log.data()
        samples = data[:, self._read:].T.copy()
        self._read = data.shape[1]
        x = self._system.GetOutputPort("plant_state").Eval(self._ctx)
        self.times.append(t)
        self.q_link.append(x[:6].copy())
        self.cut_force_N.append(float(np.linalg.norm(self._system.GetOutputPort("cutting_wrench").Eval(self._ctx)[:3])))
        self.last_info = (t, x[:6].copy())
        return self._report(), samples if len(samples) else np.atleast_2d(self._rest[2])

    def surface(self):
        """(scan lines, surface-error statistics mm) of the cut so far."""
        cell = SimpleNamespace(scenario=self.sc, force_model=self.force_model, robot=self.robot, tool_m=self.tool_m,
                               path=self.path, workpiece=self.workpiece, compensation=True)
        return scanned_surface(cell, np.asarray(self.times), np.asarray(self.q_link))

    def scan_csv(self, scans):
        """The machined face as a scanner outside the project measures it
        (scan.csv's columns and noise line, no run id): ``surface()``'s scan
        lines with the scenario's scanner noise."""
        from robstiff_drake.diagrams.cell_record import scan_of
        from robstiff_drake.identification.runs import logs as rl

        scan = scan_of(scans, self.sc.scan.noise_mm)
        return rl.scan_text(scan, None, [f"the face cut by robstiff sim-cell ({self.sc.name}), as a scanner measures "
                                         f"it: Gaussian height noise of {self.sc.scan.noise_mm:g} mm (scan.noise_mm)"])

    def reference_csv(self):
        """The joint reference the compensator streams (t_s, q1_deg..q6_deg:
        the controller's angles), as `robstiff compensate --reference` reads it."""
        return joint_reference_text(self.robot, self.t_ref, self.q_ref, notes=[
            f"joint reference of the scenario's path, written by robstiff sim-cell (IK every "
            f"{self.sc.path.reference_period_ms:g} ms; the controller's angles)"], period_s=self.T)
