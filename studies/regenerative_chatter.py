"""What the modelled arm does when the plant's chip follows the tool's own
motion (issue 29): the station run with ``cutting.chip: regenerative``
(model/regenerative_chip.py: each tooth's chip the tool centre's
displacement since the earlier teeth's passes, a tooth with none out of
the cut; tooth-resolved, 0.25 ms) against the default plant (the
program's chip direction, revolution-averaged), and the nonlinear time
domain against the linear check (diagrams/chatter_check.py and
studies/chip_coupling_stability.py's exact rightmost root along the
block's entry): the independent check of one by the other.

Cases: the paper's block at the paper's forces (paper_reproduction's
draw 0: play on every joint, plain compensation, the identified model),
and diagrams/block_milling.yaml at its own forces.

    python studies/regenerative_chatter.py                  # the paper's block, then the own-forces block
    python studies/regenerative_chatter.py --paper          # the paper's block only
    python studies/regenerative_chatter.py --own            # block_milling.yaml only
    python studies/regenerative_chatter.py --paper --step-ms 0.125 --until-s 2.6   # a finer step, a short window
    python studies/regenerative_chatter.py --paper --memory-revolutions 16          # the chip's memory doubled
    (--cache DIR keeps each run's log and statistics, so that the tables can be printed again without the runs)
"""

import argparse
import copy
import math
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "studies"))

import paper_reproduction as pr  # noqa: E402
from robstiff_drake.diagrams import experiment  # noqa: E402
from robstiff_drake.diagrams.chatter_check import chatter_check  # noqa: E402
from robstiff_drake.diagrams.scenario import load_scenario  # noqa: E402
from robstiff_drake.model import regenerative_chip as rch  # noqa: E402
from robstiff_drake.model.robot import load_robot  # noqa: E402
# the vibration's definitions (off its 20 ms mean, the 10 ms envelope, the spectrum's peak): the package's, which
# `robstiff simulate` applies to every run (diagrams/run_vibration.py)
from robstiff_drake.model.vibration import ENVELOPE_S, envelope, moving_mean, off_mean, peak_hz  # noqa: E402
from robstiff_drake.systems.regenerative_force import RegenerativeForceSource  # noqa: E402

MEMORY_DEFAULT = rch.MEMORY_REVOLUTIONS
LIMIT_SPAN = (0.4, 0.8)  # the limit cycle's window: this span of the cut (first to last tooth engaged)
LOG_COLUMNS = ("t", "x", "y", "z", "Fx", "Fy", "Fz", "engaged", "out")


def tooth_resolved(sc, step_s, chip):
    """The scenario with the tooth-resolved force and ``chip`` (cutting.chip) at the plant step ``step_s``."""
    s = copy.deepcopy(sc)
    s.cutting.mode, s.cutting.chip = "tooth", chip
    s.plant_config.time_step = step_s
    return s


def run(sc, robot, compensation, cache, key, until_s=None):
    """(surface statistics dict (experiment's: mean, rms, max_abs, pv, mm),
    the force source's log (None for the default plant), wall s) of one
    run; ``until_s``: stop there (no surface)."""
    path = Path(cache) / f"{key}.npz" if cache else None
    if path is not None and path.exists():
        d = np.load(path, allow_pickle=True)
        return d["stats"].item(), (d["log"] if d["log"].size else None), float(d["wall"])
    RegenerativeForceSource.log = log = []
    t0 = time.perf_counter()
    try:
        if until_s is None:
            res = experiment.run_cut(copy.deepcopy(sc), robot, compensation=compensation)
            stats = {k: float(res.surface_error_mm[k]) for k in ("mean", "rms", "max_abs", "pv")}
        else:
            cell = experiment.build_milling_cell(copy.deepcopy(sc), robot, compensation=compensation)
            sim = experiment.make_simulator(cell)  # (the cell kept: the simulator does not own its diagram)
            sim.AdvanceTo(until_s)
            stats = {}
    finally:
        RegenerativeForceSource.log = None
    wall = time.perf_counter() - t0
    arr = np.array(log, dtype=float)
    if path is not None:
        path.parent.mkdir(parents=True, exist_ok=True)
        np.savez(path, stats=np.array(stats, dtype=object), log=arr, wall=wall)
    return stats, (arr if arr.size else None), wall


def vibration(log):
    """(t, x mm, in-plane vibration um (n, 2), force oscillation N (n, 2),
    axial vibration um (n,), each off its MEAN_WINDOW_S mean; the force first averaged over a tooth
    period, so the tooth pass's own ripple leaves it)."""
    t = log[:, 0]
    dt = t[1] - t[0]
    xy = np.stack([off_mean(t, log[:, i]) for i in (1, 2, 3)], axis=1) * 1e6
    k = max(1, int(round(1.0 / 360.0 / dt)))
    F = np.stack([moving_mean(t, log[:, i], k * dt) for i in (4, 5)], axis=1)
    F = np.where(np.isnan(F), log[:, 4:6], F)  # (the record's ends: the held force itself)
    F = np.stack([off_mean(t, F[:, i]) for i in (0, 1)], axis=1)
    xy = np.nan_to_num(xy)
    return t, log[:, 1] * 1e3, xy[:, :2], np.nan_to_num(F), xy[:, 2]


def chatter_summary(log, quiet_s=(0.3, 0.8)):
    """The run's chatter: the cut's entry (first update with teeth
    engaged), the quiet level (the vibration's envelope median over
    ``quiet_s`` after the entry), the onset (the first envelope window
    from which the vibration stays above 3 times the quiet level until
    it reaches 10 times it), the growth from there to there (log of the
    envelope, least squares), the frequency over the onset's 0.1 s and
    in the limit cycle, the limit cycle's vibration and force (median of
    the envelope over LIMIT_SPAN of the cut), the tooth samples out of
    the cut."""
    t, x_mm, xy, F, z = vibration(log)
    engaged, out = log[:, 7], log[:, 8]
    i0 = int(np.argmax(engaged > 0))
    te, a = envelope(t, xy)
    _, aF = envelope(t, F)
    _, az = envelope(t, z[:, None])
    last = t[np.flatnonzero(engaged > 0)[-1]]
    cut = (te >= t[i0]) & (te <= last)
    quiet = np.median(a[(te >= t[i0] + quiet_s[0]) & (te < t[i0] + quiet_s[1])])
    late = (te >= t[i0] + LIMIT_SPAN[0] * (last - t[i0])) & (te < t[i0] + LIMIT_SPAN[1] * (last - t[i0]))
    lc, lcF = float(np.median(a[late])), float(np.median(aF[late]))
    out_d = {"entry_x_mm": float(x_mm[i0]), "quiet_um": float(quiet), "limit_um": lc, "limit_N": lcF,
             "limit_z_um": float(np.median(az[late]))}
    above = a > 3.0 * quiet
    reach = np.flatnonzero(cut & (te > t[i0] + quiet_s[1]) & (a >= 10.0 * quiet))
    if len(reach):
        j = reach[0]
        while j > 0 and above[j - 1]:
            j -= 1
        t_on = te[j]
        m = (te >= t_on) & (te <= max(te[reach[0]], t_on + 2.5 * ENVELOPE_S))  # (at least 3 windows)
        g = np.polyfit(te[m], np.log(a[m]), 1)[0]
        w = (t >= t_on) & (t < t_on + 0.1)
        out_d.update(onset_t_s=float(t_on), onset_x_mm=float(np.interp(t_on, t, x_mm)), growth_per_s=float(g),
                     onset_hz=peak_hz(t[w], xy[w]))
    lw = (t >= te[late][0]) & (t < te[late][-1]) if late.any() else slice(0, 0)
    out_d["limit_hz"] = peak_hz(t[lw], xy[lw]) if late.any() else math.nan
    # the share of tooth passes (a tooth period of updates) where a tooth the law's immersion engages is out
    n = max(1, int(round(1.0 / 360.0 / (t[1] - t[0]))))
    for name, sel in (("quiet", (t >= t[i0] + quiet_s[0]) & (t < t[i0] + quiet_s[1])),
                      ("limit", (t >= te[late][0]) & (t < te[late][-1]) if late.any() else t < 0)):
        e, o = engaged[sel], out[sel]
        m = len(e) // n
        passes_e = e[:m * n].reshape(m, n).sum(axis=1) > 0
        passes_o = o[:m * n].reshape(m, n).sum(axis=1) > 0
        out_d[f"{name}_passes_out"] = float(passes_o[passes_e].mean()) if passes_e.any() else math.nan
        out_d[f"{name}_samples_out"] = float(o.sum() / max(e.sum(), 1))
    return out_d


def linear_onset(sc, robot, xs_mm):
    """The linear check's rightmost root along the entry
    (studies/chip_coupling_stability.py's, the law linearised at each x):
    (first x whose root grows, its growth and frequency, the root at the
    last x)."""
    import chip_coupling_stability as ccs
    from robstiff_drake.model import chip_coupling as cc
    cut = ccs.Cut(sc, robot)
    first, s = None, None
    for x in xs_mm:
        p = np.array([x / 1e3, 0.0, 0.700])
        s = ccs.exact_rightmost(cut.arm(p)[0], cut.chip(p))
        if first is None and s.real > 0:
            first = (x, s.real, cc.mode_of(s)[0])
    return first, (xs_mm[-1], s.real, cc.mode_of(s)[0])


def case(name, sc, robot, args):
    print(f"## {name}\n", flush=True)
    check = chatter_check(copy.deepcopy(sc), robot)
    if check:
        print(f"simulate's linear check (diagrams/chatter_check.py, the worst pose): "
              f"{'stable' if check['stable'] else 'unstable'}, growth {check['growth_per_s']:+.2f} 1/s at "
              f"{check['frequency_hz']:.1f} Hz, x = {check['x_mm']:.0f} mm")
    first, end = linear_onset(sc, robot, list(np.arange(1490.0, 1530.1, 2.5)) + [1600.0])
    print("the exact rightmost root along the entry (chip_coupling_stability's): "
          + (f"first growing at x = {first[0]:.1f} mm ({first[1]:+.2f} 1/s, {first[2]:.1f} Hz)" if first else
             "none growing") + f"; at x = {end[0]:.0f} mm {end[1]:+.2f} 1/s, {end[2]:.1f} Hz\n", flush=True)
    rows = []
    step = args.step_ms / 1e3
    plants = (("default", "the default (program's chip, averaged)", sc),
              ("tooth", "program's chip, tooth-resolved", tooth_resolved(sc, step, "program")),
              ("regen", "regenerative" + (f" (memory {rch.MEMORY_REVOLUTIONS} revolutions)"
                                          if rch.MEMORY_REVOLUTIONS != MEMORY_DEFAULT else ""),
               tooth_resolved(sc, step, "regenerative")))
    for kind, plant, s in plants:
        if args.until_s and kind != "regen":
            continue
        for comp in (False, True):
            if args.until_s and comp:
                continue
            h_ms = float(s.plant_config.time_step) * 1e3
            memory = rch.MEMORY_REVOLUTIONS if kind == "regen" else MEMORY_DEFAULT
            key = f"{name.split()[0]}-{kind}-{h_ms:g}-{'comp' if comp else 'plain'}" + (
                f"-until{args.until_s:g}" if args.until_s else "") + (
                f"-memory{memory}" if memory != MEMORY_DEFAULT else "")
            stats, log, wall = run(s, robot, comp, args.cache, key, args.until_s)
            rows.append((plant, comp, stats, log, wall, float(s.plant_config.time_step)))
            print(f"  ({plant}, {'compensated' if comp else 'uncompensated'}: {wall:.0f} s wall)", flush=True)
    if args.until_s:
        print(f"\nThe regenerative plant up to t = {args.until_s:g} s, uncompensated (quiet, onset, growth and "
              "frequency as the full run's table defines them):")
        print("| step (ms) | quiet (um) | onset x (mm) | growth (1/s) | onset frequency (Hz) |")
        print("|---|---|---|---|---|")
        for _, _, _, log, _, h in rows:
            c = chatter_summary(log)
            on = (f"{c['onset_x_mm']:.1f} | {c['growth_per_s']:+.1f} | {c['onset_hz']:.1f}" if "onset_x_mm" in c
                  else "none | | ")
            print(f"| {h * 1e3:g} | {c['quiet_um']:.2f} | {on} |")
        return
    print("\n| plant | step (ms) | compensation | mean (mm) | rms (mm) | max abs (mm) | PV (mm) | wall (s) |")
    print("|---|---|---|---|---|---|---|---|")
    for plant, comp, st, _, wall, h in rows:
        if st:
            print(f"| {plant} | {h * 1e3:g} | {'yes' if comp else 'no'} | {st['mean']:+.3f} | {st['rms']:.3f} | "
                  f"{st['max_abs']:.3f} | {st['pv']:.3f} | {wall:.0f} |")
    print("\nThe regenerative plant's vibration (the tool point off its 20 ms mean, the largest in each 10 ms: "
          "quiet, its median 0.3-0.8 s after the entry; mid-cut, its median over 40-80 % of the cut; the force "
          "averaged over a tooth period, off its 20 ms mean, likewise; tooth samples the program's chip has in the "
          "cut):")
    print("| compensation | entry x (mm) | quiet (um) | onset x (mm) | growth (1/s) | onset frequency (Hz) | "
          "mid-cut (40-80 % of it): frequency (Hz) | tool in plane (um) | tool axial (um) | force (N) | tooth passes "
          "with a tooth out of the cut, quiet / mid-cut | engaged tooth samples out, quiet / mid-cut |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for plant, comp, st, log, _, _ in rows:
        if log is None:
            continue
        c = chatter_summary(log)
        on = (f"{c['onset_x_mm']:.1f} | {c['growth_per_s']:+.1f} | {c['onset_hz']:.1f}" if "onset_x_mm" in c
              else "none | | ")
        print(f"| {'yes' if comp else 'no'} | {c['entry_x_mm']:.1f} | {c['quiet_um']:.2f} | {on} | "
              f"{c['limit_hz']:.1f} | {c['limit_um']:.1f} | {c['limit_z_um']:.1f} | {c['limit_N']:.1f} | "
              f"{c['quiet_passes_out']:.3f} / "
              f"{c['limit_passes_out']:.3f} | {c['quiet_samples_out']:.3f} / {c['limit_samples_out']:.3f} |",
              flush=True)
    print()


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--paper", action="store_true", help="the paper's block only")
    ap.add_argument("--own", action="store_true", help="block_milling.yaml at its own forces only")
    ap.add_argument("--step-ms", type=float, default=0.25, help="the regenerative plant's step (ms)")
    ap.add_argument("--until-s", type=float, help="the regenerative plant uncompensated only, up to this time (s)")
    ap.add_argument("--cache", help="a directory keeping each run (reused when there)")
    ap.add_argument("--memory-revolutions", type=int, default=MEMORY_DEFAULT,
                    help=f"the regenerative chip's memory (revolutions; the model's {MEMORY_DEFAULT}): its sensitivity")
    args = ap.parse_args(argv)
    rch.MEMORY_REVOLUTIONS = args.memory_revolutions
    robot = load_robot()
    if not args.own:
        case("paper's block (the paper's forces, draw 0, play on every joint)", pr.paper_scenario("block", robot, 0),
             robot, args)
    if not args.paper:
        case("block_milling.yaml (its own forces)", load_scenario(ROOT / "diagrams" / "block_milling.yaml"), robot,
             args)


if __name__ == "__main__":
    main()
