"""Corners before and after blending:
the L-shaped contour (diagrams/l_contour.yaml) and the G-code example
(diagrams/contour_with_arcs.yaml + .nc), each run without and with
compensation, with the corner zone at 0 (sharp corners at full speed: the
path as planned before blending) and at the scenario's zone.

Prints the table of docs/toolpaths.md:

    python studies/corner_blending.py

Columns: surface error along the path's scan (mean, RMS, largest |e|,
peak-to-valley, mm, + = cut more); the tool point's largest deviation from
the commanded path during the pass less its median (mm: the excursion,
which includes the deflection's slow change when the force turns with the
path); and its ringing: the deviation's largest departure from its own
0.4 s moving average (mm: the first mode, about 5 Hz, rung by the corner).
Takes about a minute per row on one core.
"""

import copy
import sys
from pathlib import Path

import numpy as np

from robstiff_drake.diagrams.experiment import run_cut
from robstiff_drake.diagrams.scenario import check_scenario, load_scenario
from robstiff_drake.model import kinematics as kin
from robstiff_drake.model.robot import load_robot

ROOT = Path(__file__).resolve().parents[1]
CASES = [("L-shaped contour", ROOT / "diagrams" / "l_contour.yaml"),
         ("contour_with_arcs.nc", ROOT / "diagrams" / "contour_with_arcs.yaml")]


def deviations_m(res, robot):
    """(times, actual - commanded tool point (m, (N, 3))) while the tool moves."""
    t, x = res.logs["state"]
    moving = (t > res.cell.path.dwell_s) & (t < res.cell.path.duration_s)
    T6 = kin.frames(robot.dh, x[moving, :6])[:, 6]
    p = T6[:, :3, 3] + T6[:, :3, :3] @ res.cell.tool_m
    return t[moving], p - res.cell.path.positions(t[moving])


def excursion_mm(res, robot):
    """Largest distance (mm) between the actual and the commanded tool
    point while the tool moves, less the pass's median deviation (the
    static deflection under the cut): the corner's whole excursion."""
    _, d = deviations_m(res, robot)
    return float(np.max(np.linalg.norm(d - np.median(d, axis=0), axis=1)) * 1e3)


def ringing_mm(res, robot, window_s=0.4):
    """Largest distance (mm) of the deviation from its own moving average
    over ``window_s`` (two periods of the ~5 Hz first mode): the ringing,
    without the slow change of the deflection when the force turns."""
    t, d = deviations_m(res, robot)
    n = max(1, int(round(window_s / np.median(np.diff(t)))))
    k = np.ones(n) / n
    smooth = np.column_stack([np.convolve(np.pad(d[:, j], (n // 2, n - 1 - n // 2), mode="edge"), k, mode="valid")
                              for j in range(3)])
    return float(np.max(np.linalg.norm(d - smooth, axis=1)) * 1e3)


def main():
    robot = load_robot()
    rows = []
    for name, path in CASES:
        base = load_scenario(path)
        for zone in (0.0, base.path.zone_mm):
            sc = copy.deepcopy(base)
            sc.path.zone_mm = zone
            check_scenario(sc)
            for comp in (False, True):
                res = run_cut(sc, robot, compensation=comp)
                s = res.surface_error_mm
                rows.append((name, zone, comp, s["mean"], s["rms"], s["max_abs"], s["pv"], excursion_mm(res, robot),
                             ringing_mm(res, robot)))
                print(f"  done: {name}, zone {zone:g} mm, {'compensated' if comp else 'uncompensated'}",
                      file=sys.stderr, flush=True)
    print("| path | corner zone | compensation | mean (mm) | RMS (mm) | max abs (mm) | PV (mm) | excursion (mm) "
          "| ringing (mm) |")
    print("|---|---|---|---|---|---|---|---|---|")
    for name, zone, comp, mean, rms, mx, pv, exc, ring in rows:
        z = "0 (sharp, full speed)" if zone == 0 else f"z{zone:g} ({zone:g} mm)"
        print(f"| {name} | {z} | {'on' if comp else 'off'} | {mean:+.3f} | {rms:.3f} | {mx:.3f} | {pv:.3f} | "
              f"{exc:.3f} | {ring:.3f} |")


if __name__ == "__main__":
    main()
