"""Why block_milling.yaml scales the cutting coefficients as it does.

The revolution-averaged force of the SECO 75 mm cutter (6 inserts, 3600 rpm,
20 mm/s, 3 mm deep) on the 50 mm wide block, against the offset of the block's
centre line from the cutter's axis, with the 6082-T6 coefficients (Duan et
al., Chin. J. Mech. Eng. 2021, Table 5); then, at the chosen offset, with the
scenario's scaling.  Run: python3 studies/cutting_force_calibration.py
"""

import numpy as np

from robstiff_drake.diagrams.milling_cell import cutting_setup
from robstiff_drake.diagrams.scenario import load_scenario
from robstiff_drake.model.milling import Workpiece
from robstiff_drake.paths import DIAGRAMS_DIR


def main():
    sc = load_scenario(DIAGRAMS_DIR / "block_milling.yaml")
    scale_tr, scale_a = sc.cutting.tangential_radial_scale, sc.cutting.axial_scale
    sc.cutting.tangential_radial_scale = sc.cutting.axial_scale = 1.0
    _, raw, _ = cutting_setup(sc)
    depth = 0.003
    print("| block centre line - cutter axis (mm) | feed force Fx (N) | cross-feed Fy (N) | axial Fz (N) |")
    print("|---|---|---|---|")
    for off in np.arange(-35.0, 36.0, 5.0):
        wp = Workpiece.from_boxes([(0.0, 0.150, -0.025 - off / 1e3, 0.025 - off / 1e3, 0.0)])
        w = raw.average_wrench(np.array([0.075, 0.0, -depth]), [1.0, 0.0], wp)
        print(f"| {-off:+.0f} | {w[0]:.1f} | {w[1]:.1f} | {w[2]:.1f} |")
    sc.cutting.tangential_radial_scale, sc.cutting.axial_scale = scale_tr, scale_a
    _, scaled, wp = cutting_setup(sc)
    p = np.array([np.mean(wp.x_m[0]), 0.0, wp.top_m[0] - depth])
    w0 = raw.average_wrench(p, [1.0, 0.0], wp)
    w1 = scaled.average_wrench(p, [1.0, 0.0], wp)
    print(f"\nscenario placement (centre line +15 mm): 6082-T6 coefficients give ({w0[0]:.0f}, {w0[1]:.0f}, "
          f"{w0[2]:.0f}) N; scaled by {scale_tr:g} (tangential, radial) and {scale_a:g} (axial): "
          f"({w1[0]:.0f}, {w1[1]:.0f}, {w1[2]:.0f}) N, against the paper's measured about 300 / 300 / 50 N")


if __name__ == "__main__":
    main()
