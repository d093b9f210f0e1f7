"""Did the simulated cut itself vibrate?  ``robstiff simulate``'s look at
each run's own signals (chatter found in the run, not the linear
prediction of diagrams/chatter_check.py, which does not run for a
tooth-resolved cut): the tool point from the logged joint angles (as
experiment.scan_surface computes it), the cutter in the material where
the logged cutting force exceeds IN_CUT_N, and model/vibration.py's
sustained amplitude, frequency and onset.  It reads only what every run
logs, so it works for every plant mode; the in-plane vibration is in the
plane normal to the spindle axis (the flange z axis at the logged angles,
as experiment.spindle_load takes it), the axial one apart.  The same
check serves `sweep` (each run's row), `demo` (its three runs) and
`sim-cell` (cell_vibration: the link angles its station logs once per
controller cycle).  Plain numpy (no Drake)."""

import numpy as np

from robstiff_drake.model import kinematics as kin
from robstiff_drake.model.vibration import run_vibration

IN_CUT_N = 1.0  # the cutter is in the material where the cutting force exceeds this (N; as simulate's mid-pass wrench)
# The warning: the sustained in-plane vibration above VIBRATION_FEED_SHARE x the feed per tooth.  A tooth's chip is
# at most the feed per tooth thick (h = f_z sin(phi)), so a tool swinging that much toward the surface takes teeth
# out of the cut: regenerative chatter's signature (the paper's block at the paper's forces with cutting.chip:
# regenerative, 412 um by this measure against f_z = 56 um, three quarters of the teeth out;
# studies/regenerative_chatter.py).  What the runout alone gives stays below it (the own-forces block with the
# regenerative chip: 16 um at 60 Hz mid-cut, 0.6 % of the tooth samples out, the default plant's surface).
VIBRATION_FEED_SHARE = 1.0
PREFIX = "the simulated cut vibrated"


def label(res):
    return "compensated" if res.compensation else "uncompensated"


def tool_motion_m(robot, tool_m, q_rad):
    """(the tool point (n, 3) m, the spindle axis (n, 3): the flange z axis) at link angles ``q_rad`` (n, 6)."""
    T6 = kin.frames(robot.dh, np.asarray(q_rad, dtype=float)[:, :6])[:, 6]
    return T6[:, :3, 3] + T6[:, :3, :3] @ np.asarray(tool_m, dtype=float), T6[:, :3, 2]


def tool_points_m(res):
    """(times s, the actual tool point (n, 3) m, the spindle axis (n, 3)) of a run (experiment.RunResult), from
    its logged link angles."""
    t, x = res.logs["state"]
    return (t,) + tool_motion_m(res.cell.robot, res.cell.tool_m, x)


def in_cut(res, t):
    """Whether the cutter was in the material at times ``t`` (s): the logged cutting force above IN_CUT_N."""
    tw, w = res.logs["cutting_wrench"]
    if len(tw) == 0:
        return np.zeros(len(t), dtype=bool)
    i = np.clip(np.searchsorted(tw, t), 0, len(tw) - 1)
    return np.linalg.norm(w[i, :3], axis=1) > IN_CUT_N


def feed_per_tooth_um(path, cutter, t, cutting):
    """The commanded feed per tooth (um) over the cut: the planned ``path``'s median speed where the cutter is in
    the material over the tooth passing frequency (``cutter``.spindle_rpm / 60 x n_teeth)."""
    tooth_hz = cutter.spindle_rpm / 60.0 * cutter.n_teeth
    tc = t[cutting]
    if len(tc) < 2:
        return None
    p = np.asarray(path.positions(tc), dtype=float)
    speed = np.linalg.norm(np.diff(p, axis=0), axis=1) / np.maximum(np.diff(tc), 1e-12)
    speed = speed[np.diff(tc) < 2.5 * (t[1] - t[0])]  # (within the cut, not across a gap between passes)
    return float(np.median(speed) / tooth_hz * 1e6) if speed.size else None


def vibration_from(t, p_m, axis, cutting, path, cutter):
    """model/vibration.run_vibration's dict (None: it never cut) with ``feed_per_tooth_um``, from the tool
    points ``p_m`` (n, 3 m) and spindle ``axis`` (n, 3) at uniform times ``t`` (s), the cutter in the material
    where ``cutting`` (n, bool)."""
    out = run_vibration(t, p_m, cutting, axis)
    if out is not None:
        out["feed_per_tooth_um"] = feed_per_tooth_um(path, cutter, t, cutting)
    return out


def vibration_of(res):
    """The vibration of one run (experiment.RunResult), from its logs (no simulation)."""
    t, p, axis = tool_points_m(res)
    return vibration_from(t, p, axis, in_cut(res, t), res.cell.path, res.cell.scenario.cutter)


def cell_vibration(station):
    """The vibration of `robstiff sim-cell`'s cut (diagrams/cell_station.CellStation): the link angles its
    station logs at the end of each controller cycle (``times``, ``q_link``) and the cutting force's size there
    (``cut_force_N``); so sampled once per cycle (4 ms: the spectrum up to 0.45 of 250 Hz, a 10 ms envelope
    window of 2-3 samples, which sees less of a sine's peak than the plant-step log of simulate)."""
    t = np.asarray(station.times, dtype=float)
    if len(t) < 3:
        return None
    p, axis = tool_motion_m(station.robot, station.tool_m, np.asarray(station.q_link))
    cutting = np.asarray(station.cut_force_N, dtype=float) > IN_CUT_N
    return vibration_from(t, p, axis, cutting, station.path, station.sc.cutter)


def vibration_summary(results):
    """{"uncompensated": ..., "compensated": ...}: each run's vibration_of."""
    return {label(r): vibration_of(r) for r in results}


def vibration_warnings(summary, sc):
    """One line per run whose sustained vibration exceeds VIBRATION_FEED_SHARE x its feed per tooth."""
    out = []
    chip = getattr(sc.cutting, "chip", "program")
    why = ("the regenerative chip: chatter" if chip == "regenerative" else
           f"cutting.chip: {chip}, cutting.mode: {sc.cutting.mode}")
    for name, v in summary.items():
        if not v or v.get("feed_per_tooth_um") is None:
            continue
        if v["amplitude_um"] > VIBRATION_FEED_SHARE * v["feed_per_tooth_um"]:
            hz = f" at {v['frequency_hz']:.0f} Hz" if v.get("frequency_hz") else ""
            if v.get("onset_mm"):
                x, y = (int(round(c)) for c in v["onset_mm"][:2])  # (no "-0")
                where = f" from x = {x} mm, y = {y} mm (t = {v['onset_t_s']:.2f} s)"
            else:
                where = ""
            axial = f" ({v['axial_um']:.0f} um along it)" if v.get("axial_um") is not None else ""
            out.append(f"{name}: {PREFIX}: {v['amplitude_um']:.0f} um{hz} in the plane normal to the "
                       f"spindle axis{axial}{where}, more than the "
                       f"{v['feed_per_tooth_um']:.0f} um feed per tooth ({why}); its surface figures are a "
                       "chattering cut's")
    return out
