"""Where on a machining path can the gears' lost motion act?  A gear's play
is taken up in the direction of the total torque it carries (gravity,
inertia and the cut: model/transmission.py), so it moves the tool only
where that torque changes sign, or passes within TAU_B of zero.

For each scenario, the uncompensated pass is simulated; along it, each
joint's total torque (the gravity the gear holds plus the cut's J^T W) is
printed: its range over the cut, whether it changes sign, and the share of
the pass within +-TAU_B_NM of zero.  The plot (docs/total_torque_along_path.png)
shows the torques over the pass.
Run: python3 studies/total_torque_sign.py [--plot docs/total_torque_along_path.png]
"""

import argparse

import numpy as np

from robstiff_drake.diagrams.experiment import run_cut
from robstiff_drake.diagrams.scenario import load_scenario
from robstiff_drake.diagrams.station import gravity_holding_torque
from robstiff_drake.io import save_figure_atomic
from robstiff_drake.model import kinematics as kin
from robstiff_drake.model.robot import load_robot
from robstiff_drake.model.transmission import TAU_B_NM
from robstiff_drake.paths import DIAGRAMS_DIR

SCENARIOS = ("block_milling", "cylinder_head")


def torques_along(name, robot):
    """(times s, tool x mm, gravity-held torque (N, 6), cut torque (N, 6), cutting mask) of a pass."""
    sc = load_scenario(DIAGRAMS_DIR / f"{name}.yaml")
    res = run_cut(sc, robot, compensation=False)
    t, w = res.logs["cutting_wrench"]
    ts, x = res.logs["state"]
    q = x[np.clip(np.searchsorted(ts, t), 0, len(ts) - 1), :6]
    tool = robot.payload.tool_point_m
    hold = np.array([gravity_holding_torque(res.cell.station.controller_plant, qi) for qi in q])
    # the gear balances gravity and the cut: tau_gear = hold - J^T W
    cut = -np.einsum("nrj,nr->nj", kin.jacobian(robot.dh, q, tool), w)
    cutting = np.linalg.norm(w[:, :3], axis=1) > 1.0
    return t, kin.tool_position(robot.dh, q, tool)[:, 0] * 1e3, hold, cut, cutting


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--plot", help="write the torques along each pass (PNG)")
    args = ap.parse_args()
    robot = load_robot()
    data = {}
    print(f"| scenario | joint | total torque while cutting (N*m) | cut's share (N*m) | changes sign | share of the "
          f"cut within +-{TAU_B_NM:g} N*m |")
    print("|---|---|---|---|---|---|")
    for name in SCENARIOS:
        t, x, hold, cut, cutting = torques_along(name, robot)
        data[name] = (x, hold + cut, cutting)
        total = (hold + cut)[cutting]
        for j in range(6):
            lo, hi = total[:, j].min(), total[:, j].max()
            near = float(np.mean(np.abs(total[:, j]) < TAU_B_NM))
            span = np.abs(cut[cutting, j]).max()
            print(f"| {name} | {j + 1} | {lo:+.0f} to {hi:+.0f} | up to {span:.0f} | {'yes' if lo < 0 < hi else 'no'} "
                  f"| {100 * near:.0f} % |")
    if args.plot:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, axes = plt.subplots(1, len(SCENARIOS), figsize=(12, 4.5), constrained_layout=True)
        for ax, name in zip(axes, SCENARIOS):
            x, total, cutting = data[name]
            for j in range(6):
                ax.plot(x[cutting], total[cutting, j] / 1e3, lw=1.2, label=f"joint {j + 1}")
            ax.axhspan(-TAU_B_NM / 1e3, TAU_B_NM / 1e3, color="0.85", label=f"|torque| < {TAU_B_NM:g} N*m")
            ax.set_xlabel("tool x along the pass (mm)")
            ax.set_ylabel("total torque on the gear (kN*m)")
            ax.set_title(f"{name}: where lost motion can act")
        axes[-1].legend(fontsize=8, loc="center left", bbox_to_anchor=(1.01, 0.5))
        save_figure_atomic(fig, args.plot, dpi=100)
        print(f"wrote {args.plot}")


if __name__ == "__main__":
    main()
