"""Why the deck's middle pass, run back along -x (a zigzag raster), is cut
deeper compensated than uncompensated (issue 29; docs/results.md, "The
cylinder head as a four-cylinder deck").

One pass of studies/cylinder_head_deck.py, cut uncompensated and
compensated (with the budget's ``--without`` removals, diagrams/budget.py),
read along its own stripe's scan line (y = 2.5 mm from its centre line:
the bridges between the chambers and the end walls).  For each stretch of
material the face mill keeps the deepest cut that ever passed over a
point, so each stretch's depth is set by one moment of the pass: the
sample whose cutter face reached lowest over the stretch's deepest point.
At that moment (found in the compensated run) the script prints

* the depth (mm, + = cut more, against the commanded envelope) of the
  stretch, uncompensated and compensated;
* the tool point's height error then (mm, actual - commanded) in both runs
  (the same moment of the program: both run on one clock);
* the compensator's correction along z then (mm: J(q) times the joint
  correction; - = the tool lowered);
* the z deflection the compensator's own model (its joint compliance and
  Jacobian) gives for the plant's TRUE cutting wrench then, and the
  largest one in the half second before (the re-entry's force peak),
  how long before and the force then: what the correction would be with a
  lag-free loop, and what the lagging one still acts on;
* the model's z deflection per 100 N of force along x and z at the pass's
  middle (the coupling that makes the feed-direction force lower the tool).

    python studies/deck_pass_trace.py --zigzag           # the middle pass along -x (2 cuts, a few minutes)
    python studies/deck_pass_trace.py                     # the same pass along +x, for contrast
    python studies/deck_pass_trace.py --zigzag --without "force filter lag"
    python studies/deck_pass_trace.py --zigzag --mode preview   # the compensator reading the program ahead
"""

import argparse
import copy
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

import cylinder_head_deck as deck  # noqa: E402
import paper_reproduction as pr  # noqa: E402
from robstiff_drake.diagrams import budget  # noqa: E402
from robstiff_drake.diagrams.experiment import run_cut  # noqa: E402
from robstiff_drake.diagrams.scenario_models import model_stiffness  # noqa: E402
from robstiff_drake.model import kinematics as kin  # noqa: E402
from robstiff_drake.model.surface import faces_over_points  # noqa: E402

LINE_Y_MM = 2.5  # the scan line, from the pass's centre line (its stripe is +-12.5 mm)
PEAK_WINDOW_S = 0.5  # how far back from the deepest moment the force peak is looked for


def deepest_samples(x_m, y_m, p_m, n_up):
    """(heights m, index of the sample that cut each point) of the envelope
    of a track over the points (x_m[i], y_m) (-1 where none passed)."""
    h, arg = np.full(x_m.shape, np.inf), np.full(x_m.shape, -1)
    for i, idx, z in faces_over_points(x_m, np.full(x_m.shape, y_m), p_m, n_up, deck.CUTTER_R_MM / 1e3):
        better = z < h[idx]
        h[idx[better]], arg[idx[better]] = z[better], i
    return h, arg


def model_dz_mm(robot, stiffness_Nm_per_rad, tool_m, q_rad, wrench):
    """The z deflection (mm) of the compensator's model (C_q J^T W, moved to
    the tool point by J) for a wrench at the tool point, base frame."""
    J = kin.jacobian(robot.dh, q_rad, tool_m)
    return float((J @ ((J.T @ wrench) / stiffness_Nm_per_rad))[2] * 1e3)


def stretches(x):
    """[a, b) index ranges of contiguous scan points."""
    cut = np.flatnonzero(np.diff(x) > 1.5 * np.median(np.diff(x))) + 1
    edges = np.r_[0, cut, len(x)]
    return list(zip(edges[:-1], edges[1:]))


def trace(k, zigzag=False, removed=(), mode="plain"):
    """The table of pass ``k`` (0, 1, ...) as text lines; ``mode``: the
    compensator's (controller.mode: plain, predictive, preview)."""
    robot = pr.load_robot()
    sc = deck.pass_scenario(pr.paper_scenario("cylinder head", robot, None, yaml=deck.DECK_YAML), k, zigzag)
    sc.scan.lines_y_mm = [deck.PASSES_Y_MM[k] + LINE_Y_MM]
    sc.controller.mode = mode
    s, r = budget.without(sc, robot, set(removed), None)[:2]
    off = run_cut(copy.deepcopy(s), r, compensation=False)
    on = run_cut(s, r, compensation=True)
    line = on.scans[0]
    ok = np.isfinite(line.error_m)
    x, y = np.asarray(line.x_m)[ok], line.y_m
    p_cmd, n_cmd = deck.tool_track_m(on, commanded=True)
    h_cmd, _ = deepest_samples(x, y, p_cmd, n_cmd)
    runs = {}
    for name, res in (("off", off), ("on", on)):
        p, n = deck.tool_track_m(res)
        h, arg = deepest_samples(x, y, p, n)
        runs[name] = (res, p, (h_cmd - h) * 1e3, arg)
    t = on.logs["state"][0]
    q_on = on.logs["state"][1][:, :6]
    tw, w_true = on.logs["cutting_wrench"]
    tc, corr = on.logs["correction"]
    stiffness, tool = model_stiffness(s, r), on.cell.tool_m
    q_mid = q_on[len(q_on) // 2]
    J_mid = kin.jacobian(r.dh, q_mid, tool)
    C = J_mid @ np.diag(1.0 / stiffness) @ J_mid.T
    out = [f"pass {k + 1} along {'-x' if zigzag and k % 2 else '+x'}, compensator {mode}, without "
           f"{', '.join(removed) or 'nothing'}; "
           f"scan line y = {y * 1e3:g} mm",
           f"the model's z deflection per 100 N at mid-pass: along x {C[2, 0] * 1e5:+.3f} mm, along y "
           f"{C[2, 1] * 1e5:+.3f} mm, along z {C[2, 2] * 1e5:+.3f} mm",
           "| stretch x (mm) | depth uncomp. -> comp. (mm) | deepest moment t (s), tool centre x (mm) | tool z error "
           "then, uncomp. / comp. (mm) | correction z then (mm) | model dz of the true wrench then (mm) | its largest "
           f"in the {PEAK_WINDOW_S:g} s before (mm) | true force then: Fx Fy Fz (N) | true force at that largest (N) |",
           "|---|---|---|---|---|---|---|---|---|"]
    for a, b in stretches(x):
        d_off, d_on = runs["off"][2][a:b], runs["on"][2][a:b]
        j = a + int(np.argmax(d_on))
        i = runs["on"][3][j]
        ez = {name: (v[1][i, 2] - p_cmd[i, 2]) * 1e3 for name, v in runs.items()}
        ic = min(np.searchsorted(tc, t[i]), len(tc) - 1)
        cz = float((kin.jacobian(r.dh, q_on[i], tool) @ corr[ic])[2] * 1e3)
        iw = np.searchsorted(tw, t[i])
        dz_now = model_dz_mm(r, stiffness, tool, q_on[i], w_true[iw])
        back = np.flatnonzero((tw >= t[i] - PEAK_WINDOW_S) & (tw <= t[i]))[::5]
        dz_back = [model_dz_mm(r, stiffness, tool, q_on[m], w_true[m]) for m in back]
        m_peak = back[int(np.argmax(dz_back))]
        f, fp = w_true[iw], w_true[m_peak]
        out.append(f"| {x[a] * 1e3:.0f}-{x[b - 1] * 1e3:.0f} | {d_off.mean():+.2f} -> {d_on.mean():+.2f} | "
                   f"{t[i]:.2f}, {p_cmd[i, 0] * 1e3:.0f} | {ez['off']:+.3f} / {ez['on']:+.3f} | {cz:+.3f} | "
                   f"{dz_now:+.3f} | {max(dz_back):+.3f} at {t[i] - tw[m_peak]:.2f} s before | "
                   f"{f[0]:.0f} {f[1]:.0f} {f[2]:.0f} | {fp[0]:.0f} {fp[1]:.0f} {fp[2]:.0f} |")
    cutting = np.linalg.norm(w_true[:, :3], axis=1) > 20.0
    m = w_true[cutting].mean(axis=0)
    out.append(f"the true cutting force while cutting (|F| > 20 N), mean: ({m[0]:.0f}, {m[1]:.0f}, {m[2]:.0f}) N; "
               f"Fx > 0 in {100 * np.mean(w_true[cutting, 0] > 0):.0f} % of it")
    out.append(f"stripe mean depth: {runs['off'][2].mean():+.3f} -> {runs['on'][2].mean():+.3f} mm "
               "(uncompensated -> compensated)")
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--pass", dest="k", type=int, default=2, choices=range(1, len(deck.PASSES_Y_MM) + 1),
                    help="the pass (default: 2, the middle one)")
    ap.add_argument("--zigzag", action="store_true", help="every second pass back along -x")
    ap.add_argument("--without", action="append", default=[], choices=pr.budgets.SOURCES,
                    help="a source removed as the budget removes it (repeatable)")
    ap.add_argument("--mode", choices=("plain", "predictive", "preview"), default="plain",
                    help="the compensator's mode (controller.mode; default: plain, the study's)")
    args = ap.parse_args(argv)
    print("\n".join(trace(args.k - 1, args.zigzag, args.without, args.mode)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
