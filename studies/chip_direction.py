"""Why the plant's chip direction is not taken from the tool's own motion
(issue 29): the plant (systems/milling_force.py) takes the chip's thickness
from the tool's actual progress and its direction from the program's path
where the tool is.  This study runs the paper's block (paper_reproduction's
draw 0, compensated, play on every joint, 0.5 ms step) and the
face-and-contour job (preview on the identified model) with the plant's
direction taken instead from the tool point's own motion, by a force source
that differs from the plant's in that alone (``ToolMotionChip``, here only,
not in the package), and prints for each direction law the surface error
and what happens where the block's cut ends.

Direction laws (the tool point's displacement over a revolution, less its
part along the spindle axis, over the revolution: its velocity v):

  path      the plant's own (the program's direction where the tool is)
  travel    turns toward v over 1.6 mm of travel, the feed |v| low-passed
            at 2 Hz (the law merged and reverted on 2026-11-28)
  vector:F  v low-passed as a vector at F Hz: feed and direction from the
            same smoothed vector
  raw       v's own direction (no filter), the feed |v| low-passed at 2 Hz
  tooth     raw over one tooth period, the force updated every plant step
  vtooth    v over one tooth period unfiltered, feed and direction (the
            chip as it is), the force updated every plant step

    python studies/chip_direction.py            # the block's laws, then face_and_contour's (about 10 minutes)
    python studies/chip_direction.py --block    # the block only (about 4 minutes)
    python studies/chip_direction.py --face-and-contour    # face_and_contour only
    python studies/chip_direction.py --law vtooth --law path --plant-step-ms 0.25    # at a finer plant step
"""

import argparse
import collections
import copy
import math
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "studies"))

import paper_reproduction as pr  # noqa: E402
from robstiff_drake.diagrams import station  # noqa: E402
from robstiff_drake.diagrams.experiment import run_cut  # noqa: E402
from robstiff_drake.diagrams.scenario import load_scenario  # noqa: E402
from robstiff_drake.model.plant_cutting import PlantCuttingLaw, PlantCuttingPhysics  # noqa: E402
from robstiff_drake.model.robot import load_robot  # noqa: E402
from robstiff_drake.systems import milling_force as mf  # noqa: E402

TRAVEL_LENGTH_M = 0.02 / (2.0 * math.pi * mf.FEED_CUTOFF_HZ)  # the reverted law's 1.6 mm
STANDSTILL_M_PER_S = 1e-5  # below it the direction stays the last (the reverted law's)
BASE = station.MillingForceSource


class ToolMotionChip(BASE):
    """The plant's force source with the chip's direction (and feed) from
    the tool point's own motion by ``LAW`` (see the module docstring); the
    compensator's own sources (not a PlantCuttingLaw) keep the plant's
    law (the compensator's twin cuts with the linear law: a source whose
    law is not the plant's rich one is left as it is).  Averaged mode
    only.  Its history of tool points is Python-side (one forward
    simulation); ``log`` collects (t, u_x, u_y, feed m/s, force N (3),
    tool point m (3)) per update of the plant's source."""

    LAW = "path"
    log = []

    def __init__(self, **kw):
        super().__init__(**kw)
        fm = kw["force_model"]
        self._plant = isinstance(fm, PlantCuttingLaw) and fm.physics != PlantCuttingPhysics.linear()
        self._on = self._plant and self.LAW != "path"
        teeth = self.LAW in ("tooth", "vtooth")
        self._win = (1.0 / kw["force_model"].cutter.tooth_pass_hz) if teeth else mf.chip_window_s(
            kw["force_model"].cutter)
        self._pts = collections.deque()

    def _velocity(self, t, p, axis):
        """The revolution's (or tooth's) displacement over its span, less
        its part along the spindle axis: (v_x, v_y) m/s."""
        self._pts.append((t, float(p[0]), float(p[1]), float(p[2])))
        while len(self._pts) > 2 and self._pts[1][0] <= t - self._win:
            self._pts.popleft()
        a, b = self._pts[0], self._pts[-1]
        if len(self._pts) > 1 and a[0] < t - self._win:  # interpolated at t - window
            n = self._pts[1]
            f = (t - self._win - a[0]) / (n[0] - a[0])
            a = tuple(a[k] + f * (n[k] - a[k]) for k in range(4))
        span = b[0] - a[0]
        if span <= 0:
            return 0.0, 0.0
        d = [(b[k] - a[k]) / span for k in (1, 2, 3)]
        da = d[0] * axis[0] + d[1] * axis[1] + d[2] * axis[2]
        return d[0] - da * axis[0], d[1] - da * axis[1]

    def _chip(self, v, u_held, feed_held):
        law = self.LAW
        ux, uy = u_held
        speed = math.hypot(*v)
        if law.startswith("vector") or law == "vtooth":
            g = 1.0 if law == "vtooth" else 1.0 - math.exp(-2.0 * math.pi * float(law.split(":")[1]) * self._period)
            vx, vy = feed_held * ux + g * (v[0] - feed_held * ux), feed_held * uy + g * (v[1] - feed_held * uy)
            feed = math.hypot(vx, vy)
            return ((vx / feed, vy / feed) if feed > STANDSTILL_M_PER_S else (ux, uy)), feed
        feed = feed_held + self._feed_gain * (speed - feed_held)
        if feed < STANDSTILL_M_PER_S or speed < STANDSTILL_M_PER_S:
            return (ux, uy), max(feed, 0.0)
        if law == "travel":
            g = 1.0 - math.exp(-feed * self._period / TRAVEL_LENGTH_M)
            ux, uy = ux + g * (v[0] / speed - ux), uy + g * (v[1] / speed - uy)
            n = math.hypot(ux, uy)
            return ((ux / n, uy / n) if n > 1e-9 else tuple(u_held)), feed
        return (v[0] / speed, v[1] / speed), feed  # raw, tooth

    def _step(self, t, q, process, hist, instants=()):
        w, pose, inst, proc, hist = super()._step(t, q, process, hist, instants)
        if self._on:
            p = pose[9:]
            u0, u1, feed_held, travel = process.tolist() if hasattr(process, "tolist") else process
            u, feed = self._chip(self._velocity(t, p, (pose[2], pose[5], pose[8])), (u0, u1), feed_held)
            w = self._model.average_wrench(p, u, self._workpiece, feed, **self._wear_args(travel))
            if w[0] != 0.0 or w[1] != 0.0 or w[2] != 0.0:
                travel += feed * self._period
            proc = np.array([u[0], u[1], feed, travel])
        if self._plant:
            ToolMotionChip.log.append([t, proc[0], proc[1], proc[2], *w[:3], *pose[9:]])
        return w, pose, inst, proc, hist


def run(law, sc, robot, compensation=True):
    """(run result, log array) of scenario ``sc`` with the plant's direction law ``law``."""
    ToolMotionChip.LAW, ToolMotionChip.log = law, []
    saved = station.AVERAGED_FORCE_PERIOD_S
    station.MillingForceSource = ToolMotionChip
    if law in ("tooth", "vtooth"):
        station.AVERAGED_FORCE_PERIOD_S = 0.0  # every plant step
    try:
        res = run_cut(copy.deepcopy(sc), robot, compensation=compensation)
    finally:
        station.MillingForceSource, station.AVERAGED_FORCE_PERIOD_S = BASE, saved
    return res, np.array(ToolMotionChip.log)


def exit_summary(log, t_exit):
    """What happens over 0.7 s from t_exit: the direction's range (deg from
    +x), the tool's lateral (y) range and its lowest point (um from the
    commanded bottom, 700 mm; - = deeper)."""
    m = (log[:, 0] >= t_exit) & (log[:, 0] < t_exit + 0.7)
    ang = np.degrees(np.arctan2(log[m, 2], log[m, 1]))
    y, z = log[m, 8] * 1e6, (log[m, 9] - 0.7) * 1e6
    return f"{ang.min():+.1f} to {ang.max():+.1f} | {y.min():+.0f} to {y.max():+.0f} | {z.min():+.0f}"


def coupling(robot):
    """The chip's coupling on the block: the plant's force's change per
    m/s of tool velocity at 20 mm/s along +x (along x: the feed; across,
    y: the direction turned by v_y / 20 mm/s), mid-pass and where the
    cutter's front has left the block; a negative eigenvalue of the
    in-plane part's symmetric half is a direction of motion the chip
    pushes along (negative damping: the mode coupling)."""
    from robstiff_drake.diagrams.scenario_models import plant_cutting_setup
    _, law, wp = plant_cutting_setup(pr.paper_scenario("block", robot, 0))
    v, d = 0.02, math.radians(0.5)
    print("The chip's coupling on the block (the force's change per m/s of tool velocity, G):")
    print("| tool at x (mm) | force (N) | dF/dv_x (N*s/m) | dF/dv_y (N*s/m) | the in-plane coupling's damping "
          "(eigenvalues of -(G + G^T) / 2, N*s/m) |")
    print("|---|---|---|---|---|")
    for x in (1.600, 1.640):
        p = [x, 0.0, 0.700]
        f0 = law.average_wrench(p, (1.0, 0.0), wp, v)[:3]
        fp, fm = (law.average_wrench(p, (math.cos(d), sg * math.sin(d)), wp, v)[:3] for sg in (1.0, -1.0))
        g = (fp - fm) / (2.0 * d) / v
        gx = (law.average_wrench(p, (1.0, 0.0), wp, 1.01 * v)[:3] - law.average_wrench(p, (1.0, 0.0), wp,
                                                                                     0.99 * v)[:3]) / (0.02 * v)
        G = np.array([[gx[0], g[0]], [gx[1], g[1]]])  # in-plane force per in-plane velocity
        lam = np.linalg.eigvalsh(-0.5 * (G + G.T))
        print(f"| {x * 1e3:.0f} | ({f0[0]:.0f}, {f0[1]:.0f}, {f0[2]:.0f}) | ({gx[0]:.0f}, {gx[1]:.0f}, {gx[2]:.0f}) | "
              f"({g[0]:.0f}, {g[1]:.0f}, {g[2]:.0f}) | {lam[0]:.0f}, {lam[1]:.0f} |")
    print()


def block(robot, laws, step_s=None):
    print("The paper's block, draw 0, compensated (plain), play on every joint"
          + (f", the plant's step {step_s * 1e3:g} ms:" if step_s else ":"))
    print("| direction law | play | mean (mm) | max (mm) | face from x = 1610 mm on, mean (mm) | "
          "after the cutter's front leaves the block (t 8.2-8.9 s): direction (deg) | tool y (um) | "
          "tool's lowest (um) |")
    print("|---|---|---|---|---|---|---|---|")
    for law, play in laws:
        sc = pr.paper_scenario("block", robot, 0)
        if step_s:
            sc.plant_config.time_step = step_s
        if not play:
            sc.plant.lost_motion_rad = [0.0] * 6
        res, log = run(law, sc, robot)
        f = pr.field_mm(res)
        x = np.concatenate([np.asarray(line.x_m, dtype=float) for line in res.scans]) * 1e3
        s = pr.stats_of(f)
        late = f[(x >= 1610.0) & np.isfinite(f)]
        # the cutter's front (its centre + 37.5 mm) reaches the block's end (1675 mm) at x = 1637.5 mm
        t_exit = float(log[np.argmax(log[:, 7] >= 1.6375), 0])
        print(f"| {law} | {'every joint' if play else 'none'} | {s['mean']:+.3f} | {s['max']:.3f} | "
              f"{late.mean():+.3f} | {exit_summary(log, t_exit)} |", flush=True)


def face_and_contour(robot, laws):
    sc = load_scenario(ROOT / "diagrams" / "face_and_contour.yaml")
    print("\nface_and_contour, preview on the identified model:")
    print("| direction law | mean (mm) | RMS (mm) | max abs (mm) |")
    print("|---|---|---|---|")
    for law in laws:  # (the path first: the preview's table is built, or read from its cache, on the plant's law)
        res, _ = run(law, sc, robot)
        s = res.surface_error_mm
        print(f"| {law} | {s['mean']:+.4f} | {s['rms']:.4f} | {s['max_abs']:.4f} |", flush=True)


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--block", action="store_true", help="the block only")
    ap.add_argument("--face-and-contour", action="store_true", help="face_and_contour only")
    ap.add_argument("--law", action="append", help="the block with this law only (repeatable; play on every joint)")
    ap.add_argument("--plant-step-ms", type=float, help="the block's plant step, ms (default: the study's 0.5)")
    args = ap.parse_args(argv)
    robot = load_robot()
    step_s = args.plant_step_ms / 1e3 if args.plant_step_ms else None
    if args.law:
        return block(robot, [(law, True) for law in args.law], step_s)
    if not args.face_and_contour:
        coupling(robot)
        block(robot, [("path", True), ("travel", True), ("vector:2", True), ("vector:5", True), ("vector:10", True),
                      ("raw", True), ("tooth", True), ("vtooth", True), ("path", False), ("travel", False)], step_s)
    if not args.block:
        face_and_contour(robot, ["path", "travel", "vector:2", "raw"])


if __name__ == "__main__":
    main()
