"""Benchmark: real-time factor of the closed-loop milling simulation
(diagrams/block_milling.yaml, the seed's block pass, about 12 s simulated),
beside the bare compliant plant (Drake's SAP step of the arm with its gravity
feed-forward, no Python systems) measured in the same run.

Targets (issue 4): >= 20x real time revolution-averaged, >= 1x tooth-resolved.
Prints each figure, the ratio to the bare plant, and PASS/FAIL; exit status 1
when a target is missed.  Run: python3 benchmarks/bench_closed_loop.py
"""

import copy
import sys
import time

import numpy as np
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource

from robstiff_drake.diagrams.experiment import run_cut
from robstiff_drake.diagrams.milling_cell import add_compliant_irb6400, build_milling_cell
from robstiff_drake.diagrams.scenario import load_scenario
from robstiff_drake.model.robot import load_robot
from robstiff_drake.paths import DIAGRAMS_DIR


def bare_plant_rtf(robot, q0, dt, t_end):
    builder = DiagramBuilder()
    arm = add_compliant_irb6400(builder, time_step_s=dt, joint_stiffness_Nm_per_rad=robot.joint_stiffness_Nm_per_rad,
                                damping_ratio=0.1, q_modes_rad=q0)
    des = builder.AddSystem(ConstantVectorSource(np.concatenate([q0, np.zeros(6)])))
    builder.Connect(des.get_output_port(), arm["plant"].get_desired_state_input_port(arm["instance"]))
    sim = Simulator(builder.Build())
    arm["plant"].SetPositions(arm["plant"].GetMyMutableContextFromRoot(sim.get_mutable_context()), q0)
    sim.Initialize()
    t0 = time.perf_counter()
    sim.AdvanceTo(t_end)
    return t_end / (time.perf_counter() - t0)


def main():
    robot = load_robot()
    base = load_scenario(DIAGRAMS_DIR / "block_milling.yaml")
    cases = []
    sc = copy.deepcopy(base)
    cases.append(("averaged, scenario settings (plant 2 ms, sensor 1 kHz)", sc, 20.0))
    sc = copy.deepcopy(base)
    sc.plant.time_step_ms = sc.controller.period_ms
    sc.sensor.rate_hz = 1000.0 / sc.controller.period_ms
    cases.append(("averaged, plant and sensor at the controller period (4 ms)", sc, 20.0))
    sc = copy.deepcopy(base)
    sc.cutting.mode = "tooth"
    cases.append(("tooth-resolved (20 samples per tooth pass, plant 2 ms)", sc, 1.0))
    ok = True
    print("closed-loop block pass, compensation on (real-time factor = simulated s / wall s):")
    for label, sc, target in cases:
        cell = build_milling_cell(sc, robot, compensation=True)
        res = run_cut(sc, robot, compensation=True, cell=cell)
        bare = bare_plant_rtf(robot, cell.q_ref[0], sc.plant.time_step_ms / 1e3, res.sim_seconds)
        passed = res.realtime_factor >= target
        ok &= passed
        print(f"  {label:62s} {res.realtime_factor:6.1f}x   bare plant {bare:6.1f}x   "
              f"ratio {res.realtime_factor / bare:.2f}   target >= {target:g}x: {'PASS' if passed else 'FAIL'}")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
