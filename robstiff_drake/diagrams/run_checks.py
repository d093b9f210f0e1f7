"""Plausibility of a closed-loop run's result: legal settings can still give
a result nobody should trust without a second look (compensation that makes
things worse or does nothing, a sensor whose samples the guard throws away,
deflections beyond the small-deflection model).  Each check is one line for
``io.Warnings``.  Plain numpy."""

import numpy as np

# Rejected sensor samples above this share mean the guard, not the sensor,
# drives the loop (a dropout rate of a few per mille is normal for a
# networked sensor; a few percent is a fault).
MAX_REJECTED_SHARE = 0.02
# The stiffness model is linear in small joint deflections; a surface error
# beyond this (mm) means the arm has left that range or the loop diverged.
SMALL_DEFLECTION_MM = 2.0
# Compensation that leaves more than this share of the uncompensated RMS
# error did (almost) nothing: a sensor the guard rejects, a saturation or a
# rate limit too tight, a period too long.
NO_EFFECT_SHARE = 0.9
# Compensated worse than uncompensated by more than this factor (RMS).
WORSE_FACTOR = 1.05
WORSE_PREFIX = "compensation made the surface worse"


def run_warnings(results, sc):
    """Warnings (list of one-line strings) about the runs of one scenario."""
    out = []
    by_label = {("compensated" if r.compensation else "uncompensated"): r for r in results}
    for label, r in by_label.items():
        s = r.surface_error_mm
        state = r.logs["state"][1]
        if not np.all(np.isfinite(state)):
            out.append(f"{label}: the simulation diverged (the arm's state is not finite); the surface error is "
                       "meaningless")
            continue
        if s and s.get("max_abs", 0.0) > SMALL_DEFLECTION_MM:
            out.append(f"{label}: surface error up to {s['max_abs']:.2f} mm, beyond the small-deflection model's "
                       f"range ({SMALL_DEFLECTION_MM:g} mm): the loop may have diverged, or the settings are far "
                       "from a machining cell's")
        n_samples = max(1, int(round(r.sim_seconds * sc.sensor.rate_hz)))
        rejected = int(r.logs["rejected"][1][-1, 0])
        if rejected > MAX_REJECTED_SHARE * n_samples:
            out.append(f"{label}: the wrench guard rejected {rejected} of about {n_samples} sensor samples "
                       f"({100.0 * rejected / n_samples:.1f} %): the compensation ran on held values")
        if r.compensation:
            corr = r.logs["correction"][1]
            sat = np.deg2rad(sc.controller.saturation_deg)
            share = float(np.mean(np.any(np.abs(corr) >= sat * (1 - 1e-9), axis=1))) if len(corr) else 0.0
            if share > 0.05:
                out.append(f"compensated: the correction sat at its saturation ({sc.controller.saturation_deg:g} deg) "
                           f"for {100 * share:.0f} % of the run")
    power = max((r.spindle or {}).get("power_W_max", 0.0) for r in results)
    rating = sc.cutter.spindle_rating_W
    if power > rating:
        out.append(f"the cut takes up to {power / 1e3:.2f} kW at the spindle, more than its {rating / 1e3:.2f} kW "
                   "rating (cutter.spindle_rating_W): the cutting forces are not physical for this spindle, or the "
                   "spindle would stall")
    if "compensated" in by_label and "uncompensated" in by_label:
        a = by_label["uncompensated"].surface_error_mm
        b = by_label["compensated"].surface_error_mm
        if a and b:
            if b["rms"] > WORSE_FACTOR * a["rms"]:
                out.append(f"{WORSE_PREFIX}: RMS {b['rms']:.3f} mm with it against "
                           f"{a['rms']:.3f} mm without (mean {b['mean']:+.3f} against {a['mean']:+.3f} mm)")
            elif b["rms"] > NO_EFFECT_SHARE * a["rms"]:
                out.append(f"compensation removed less than {100 * (1 - NO_EFFECT_SHARE):.0f} % of the surface error "
                           f"(RMS {b['rms']:.3f} mm with it, {a['rms']:.3f} mm without): check the sensor, the guard, "
                           "the saturation, the rate limit and the controller period")
    return out
