"""The loop check's verdict when the sensor's records come at another rate
than `compensate --sensor-rate-hz` says (cell/sensor_checks.py's
RATE_TOLERANCE): the force filter designed for the configured rate (a
2nd-order low-pass at compensate's default 2 Hz, 1000 Hz) run at the
actual one, in the loop model (model/loop_check.py) at the block test's
start pose on the IRB 6400 (4 ms period, no extra delay), as
benchmarks/bench_loop_check.py sets it up.

Prints, per actual rate, the filter's actual corner and the spectral
radius per period in air and cutting at the check's 2 % damping margin
(above 1: unstable) and at the assumed 5 %.

    python benchmarks/sensor_rate_margin.py
"""

import numpy as np

from robstiff_drake.cell.loop_guard import LoopGuard, feed_direction
from robstiff_drake.cell.sensor_checks import RATE_TOLERANCE
from robstiff_drake.diagrams.milling_cell import planned_path
from robstiff_drake.diagrams.scenario import load_scenario
from robstiff_drake.model.filters import lowpass_coefficients
from robstiff_drake.model.robot import load_robot
from robstiff_drake.paths import DIAGRAMS_DIR

CONFIGURED_HZ, CUTOFF_HZ, PERIOD_S = 1000.0, 2.0, 0.004  # compensate's defaults


def main():
    robot = load_robot()
    tool = robot.payload.tool_point_m
    sc = load_scenario(DIAGRAMS_DIR / "block_milling.yaml")
    _, _, q_ref = planned_path(sc, robot, tool)
    feed = feed_direction(robot, tool, q_ref)
    ba = lowpass_coefficients(CUTOFF_HZ, CONFIGURED_HZ, 2)  # (designed for the configured rate)
    print(f"IRB 6400 at the block test's start; --sensor-rate-hz {CONFIGURED_HZ:g}, --cutoff-hz {CUTOFF_HZ:g} "
          f"(order 2), period {PERIOD_S * 1e3:g} ms; the rate check's tolerance {RATE_TOLERANCE:.0%}")
    for ratio in (0.125, 0.5, 1 - RATE_TOLERANCE, 1.0, 1 + RATE_TOLERANCE, 2.0):
        rate = CONFIGURED_HZ * ratio
        guard = LoopGuard(robot=robot, k_Nm_per_rad=robot.joint_stiffness_Nm_per_rad, servo=None,
                          sensor_rate_hz=rate, period_s=PERIOD_S, delay_steps=0, filter_kind="lowpass", filter_ba=ba,
                          cutoff_hz=CUTOFF_HZ * ratio, filter_order=2, allow_unstable=True)
        guard.at(np.degrees(robot.joint_map.to_controller(q_ref[0])), "the block test's start", feed)
        r, ra = guard.result["spectral_radius"], guard.result["spectral_radius_assumed_damping"]
        print(f"records at {rate:6.0f} Hz (x{ratio:g}): the corner at {CUTOFF_HZ * ratio:.2f} Hz; radius at 2 % air "
              f"{r['air']:.5f}, cutting {r['cutting']:.5f}; at 5 % {ra['air']:.5f}, {ra['cutting']:.5f}"
              + ("  UNSTABLE" if max(r.values()) > 1 else ""))
    return 0


if __name__ == "__main__":
    main()
