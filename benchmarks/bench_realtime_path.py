"""Benchmark: the compensator's per-cycle path (Jacobian at the measured
joint angles + joint torques tau = J^T F + deflection dq = C_q tau and
dx = J dq) for one configuration per call, beside Drake's own
MultibodyPlant.CalcJacobianSpatialVelocity (Jacobian only) measured in the
same run on the same configurations.

Target: median <= 25 us per call on the project's 2-core machine.
Prints the medians, the ratio to Drake, and PASS/FAIL against the target
(exit status 1 on FAIL).  Run: python3 benchmarks/bench_realtime_path.py
"""

import argparse
import statistics
import sys
import time

import numpy as np
from pydrake.multibody.tree import JacobianWrtVariable

from robstiff_drake.model import kinematics as kin
from robstiff_drake.model import stiffness as st
from robstiff_drake.model.realtime import DeflectionPredictor
from robstiff_drake.model.robot import load_robot
from robstiff_drake.plant import make_irb6400_plant

TARGET_US = 25.0


def median_us(fn, args_list, repeats, inner):
    """Median over ``repeats`` batches of the mean time per call (us); each
    batch cycles through ``args_list`` so no result can be cached."""
    samples = []
    n = len(args_list)
    for r in range(repeats):
        t0 = time.perf_counter()
        for i in range(inner):
            fn(*args_list[(r * inner + i) % n])
        samples.append((time.perf_counter() - t0) / inner * 1e6)
    return statistics.median(samples)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=200)
    ap.add_argument("--inner", type=int, default=100)
    args = ap.parse_args()

    robot = load_robot()
    tool = robot.payload.tool_point_m
    rng = np.random.default_rng(0)
    qs = rng.uniform(robot.q_lower_rad, robot.q_upper_rad, size=(64, 6))
    Fs = rng.normal(size=(64, 6)) * 300.0
    work = list(zip(qs, Fs))

    predictor = DeflectionPredictor(robot.dh, robot.joint_stiffness_Nm_per_rad, tool)

    def numpy_reference(q, F):
        J = kin.jacobian(robot.dh, q, tool)
        return st.deflection_conventional(J, robot.joint_stiffness_Nm_per_rad, F)

    plant, _ = make_irb6400_plant()
    ctx = plant.CreateDefaultContext()
    flange = plant.GetFrameByName("flange")
    world = plant.world_frame()

    def drake_jacobian(q, F):
        plant.SetPositions(ctx, q)
        return plant.CalcJacobianSpatialVelocity(ctx, JacobianWrtVariable.kQDot, flange, tool, world, world)

    # warm up, and check that all three agree before timing them
    for q, F in work[:4]:
        dq, dx = predictor(q, F)
        dq_ref, dx_ref = numpy_reference(q, F)
        Jd = drake_jacobian(q, F)
        assert np.allclose(dq, dq_ref, rtol=1e-12, atol=1e-18) and np.allclose(dx, dx_ref, rtol=1e-12, atol=1e-18)
        assert np.allclose(np.vstack([Jd[3:], Jd[:3]]), predictor.jacobian(q), atol=1e-12)

    t_rt = median_us(predictor, work, args.repeats, args.inner)
    t_drake = median_us(drake_jacobian, work, args.repeats, args.inner)
    t_np = median_us(numpy_reference, work, args.repeats, args.inner)

    print("real-time path per call (median of batch means, us):")
    print(f"  robstiff DeflectionPredictor (J + tau + dq + dx)      {t_rt:8.2f} us")
    print(f"  Drake SetPositions + CalcJacobianSpatialVelocity (J)  {t_drake:8.2f} us")
    print(f"  numpy reference kinematics.jacobian + deflection      {t_np:8.2f} us")
    print(f"  ratio robstiff / Drake Jacobian: {t_rt / t_drake:.2f}")
    ok = t_rt <= TARGET_US
    print(f"  target <= {TARGET_US:.0f} us: {'PASS' if ok else 'FAIL'}")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
