"""Aliasing: the 360 Hz tooth-pass force of the paper's cutter, sampled at a
slow controller rate, folds down towards the arm's modes unless it is
filtered at the sensor's rate first.

The block test (diagrams/block_milling.yaml) in tooth-resolved mode with a
24 ms controller period (a controller that corrects once per robot target),
one period of delay, a 5 Hz low-pass:
  (a) the sensor read at 7.2 kHz (20 samples per tooth pass) and filtered at
      that rate, then sampled by the controller (the chain as designed);
  (b) the sensor read only at the controller's 41.7 Hz and filtered there:
      the tooth-pass harmonics fold down below that Nyquist rate (360 Hz to
      15 Hz, 720 Hz to 11.7 Hz, next to the arm's 11 Hz mode, 1080 Hz to
      3.3 Hz, inside the 5 Hz filter's pass band), where no filter after the
      sampling can tell them from the cutting force's real changes.
Prints the ripple of the force estimate and of the correction, their main
frequency, and the surface error (mm).  docs/results.md quotes
`python3 studies/aliasing.py`.
"""

import copy

import numpy as np

from robstiff_drake.diagrams.experiment import run_cut
from robstiff_drake.diagrams.scenario import load_scenario
from robstiff_drake.model.robot import load_robot
from robstiff_drake.paths import DIAGRAMS_DIR


def ripple(t, x, t0, t1):
    """Peak-to-peak and dominant frequency (Hz) of x between t0 and t1, trend removed."""
    sel = (t >= t0) & (t <= t1)
    y = x[sel] - np.polyval(np.polyfit(t[sel], x[sel], 2), t[sel])
    f = np.fft.rfftfreq(len(y), np.mean(np.diff(t[sel])))
    spec = np.abs(np.fft.rfft(y * np.hanning(len(y))))
    return float(y.max() - y.min()), float(f[1:][np.argmax(spec[1:])])


def main():
    robot = load_robot()
    base = load_scenario(DIAGRAMS_DIR / "block_milling.yaml")
    base.cutting.mode = "tooth"
    base.plant_config.time_step = 0.00025  # the step that resolves the tooth pass (the station refuses a coarser one)
    base.controller.period_ms = 24.0
    base.controller.filter.cutoff_hz = 5.0
    base.controller.rate_limit_deg_per_s = 10.0
    cases = {"(a) sensor 7.2 kHz, filtered there": 7200.0, "(b) sensor at the controller's 41.7 Hz": 1000.0 / 24.0}
    print("| case | force estimate ripple (N p-p) | at (Hz) | correction ripple, joint 3 (urad p-p) | at (Hz) | "
          "surface mean (mm) | steady PV (mm) |")
    print("|---|---|---|---|---|---|---|")
    for label, rate in cases.items():
        sc = copy.deepcopy(base)
        sc.sensor.rate_hz = rate
        res = run_cut(sc, robot, compensation=True)
        t, w = res.logs["tool_wrench"]
        tc, c = res.logs["correction"]
        t0, t1 = 5.0, 8.0  # the cutter fully in the block
        fr, ff = ripple(t, w[:, 0], t0, t1)
        cr, cf = ripple(tc, c[:, 2] * 1e6, t0, t1)
        steady = [ln.error_m[(ln.x_m > 1.565) & (ln.x_m < 1.635)] for ln in res.scans]
        steady = np.concatenate(steady) * 1e3
        print(f"| {label} | {fr:.1f} | {ff:.1f} | {cr:.1f} | {cf:.1f} | {res.surface_error_mm['mean']:+.4f} | "
              f"{np.nanmax(steady) - np.nanmin(steady):.4f} |")


if __name__ == "__main__":
    main()
