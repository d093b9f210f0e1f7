"""Would the cut chatter?  A check of a scenario before it runs (robstiff
simulate's warnings).

The plant's chip takes its direction from the program
(systems/milling_force.py): the regenerative chip, the tool's in-plane
displacement over one tooth period, is left out, so a simulated surface
assumes a stable cut.  model/chip_coupling.py couples the station's linear
joints to the plant's law linearised at one pose with the regenerative
chip; studies/chip_coupling_stability.py found the arm unstable on the
paper's block at the paper's forces (+36.7 1/s at 68.6 Hz, docs/results.md,
"Physics or numerics: the arm with its own chip, linearised") and stable
on diagrams/block_milling.yaml at its own forces.

This check does what that study does along the cut, without running the
simulation: the path sampled at ``SAMPLES`` times, the plant's
revolution-averaged wrench there, and every time that cuts a pose checked
(``MAX_POSES``; the poses of the largest force alone miss the partial
engagement of a cutter entering the block, where the KR 240's block is at
the edge of stability: studies/chatter_check_scenarios.py --dense).  At
each: the station's joints (diagrams/compliant_arm.arm_joints, the same
call as the station's, so its cache serves the run) moved to the pose's
mass matrix, the law linearised there, and the delay law's rightmost root
by Pade [``PADE_ORDER``/``PADE_ORDER``] (the study shows [4/4] within
0.005 1/s of [8/8]); at the ``REFINED_POSES`` poses of the rightmost Pade
roots those are refined by Newton on the exact characteristic equation.
Where it grows, diagrams/chatter_damping.py finds the modal damping that
would make it stable.  Only for the revolution-averaged cutting mode (the
tooth-resolved plant is another law) and a cut that touches the workpiece.

What it rests on: the arm's modal damping is the scenario's plant damping
(plant.damping_ratios / plant.modal_damping_ratio, an assumption unless
measured), the cutting coefficients independent of speed, the law linear
about the pose (model/chip_coupling.py's docstring says what it cannot say).
"""

import math

import numpy as np

from robstiff_drake.diagrams.chatter_damping import damping_phrase, damping_to_stabilise
from robstiff_drake.model import chip_coupling as cc
from robstiff_drake.model import joint_dynamics as jd
from robstiff_drake.model import kinematics as kin

SAMPLES = 41  # times along the cut where the wrench is evaluated (a wrench is about 20 us)
MAX_POSES = SAMPLES  # poses linearised: every time that cuts (each about 3 ms for the Pade roots and the joints)
MIN_SPACING = 0.0  # of the cut's span between two poses checked
REFINED_POSES = 3  # the poses of the rightmost Pade roots whose roots are refined by Newton (each about 3 ms)
PADE_ORDER = 4  # studies/chip_coupling_stability.py: [4/4] within 0.005 1/s of [8/8] and of Newton's root
REFINED = 4  # the rightmost Pade roots refined (with [4/4] converged, the rightmost exact root is the first's)
MAX_HZ = 400.0  # the roots searched up to this frequency (the arms' modes are below 130 Hz)
IN_CUT_N = 1.0  # an in-plane force above this: the tool cuts
DEPTH_RESOLUTION_MM = 0.05  # the largest stable depth's bisection
# A growth g at f Hz is the damping ratio -g / (2 pi f) for a lightly damped root: below this much negative damping
# the root is at the edge of stability, well inside what the assumed modal damping (its 1 %-point uncertainty at
# least, when not measured) can decide, and the warning says so instead of calling the cut unstable
MARGINAL_DAMPING = 0.005
# The chip (feed per tooth) below which the law is not linearised (model/chip_coupling.linearise_law's min_chip_m;
# a thinner one is taken at this size): the plant law's edge ramp (model/plant_cutting.py: 10 um, the hone of a sharp
# insert for aluminium, ASSUMPTION 5-20 um by grade).  Below it no chip forms (the minimum chip thickness is 0.2-0.4
# of the edge radius: Liu, DeVor and Kapoor, J. Manuf. Sci. Eng. 126(4), 2004): the law's force there is its ramp, a
# stand-in for ploughing, whose slope (edge coefficient / ramp) would be taken for a chip stiffness and whose process
# damping the linear model leaves out (docs/results.md: the slow feed).  A law without a ramp: this default.
MIN_CHIP_M = 10e-6


def min_chip_m(law):
    """The chip (m) below which ``law`` is not linearised: its edge ramp, else MIN_CHIP_M."""
    ramp = float(getattr(getattr(law, "physics", None), "edge_ramp_chip_m", 0.0) or 0.0)
    return ramp if ramp > 0 else MIN_CHIP_M


def poses_to_check(path, law, wp, samples=SAMPLES, max_poses=MAX_POSES, min_spacing=MIN_SPACING):
    """[(t s, p (3,) m, u (2,) unit feed direction, in-plane force N, feed
    m/s)]: up to
    ``max_poses`` times of the largest in-plane revolution-averaged force,
    at least ``min_spacing`` of the cut's span apart, largest first; [] when
    the tool never cuts."""
    t0, t1 = path.dwell_s, path.duration_s - path.dwell_s
    if not t1 > t0:
        return []
    rows = []
    for t in np.linspace(t0, t1, samples):
        p = np.asarray(path.position(t), dtype=float)
        u = np.asarray(path.feed_direction(t), dtype=float)[:2]
        if not np.linalg.norm(u) > 0:
            continue
        u = u / np.linalg.norm(u)
        feed = feed_at(path, t, law)
        F = float(np.linalg.norm(law.average_wrench(p, u, wp, feed)[:2]))
        if F > IN_CUT_N:
            rows.append((float(t), p, u, F, feed))
    chosen = []
    for r in sorted(rows, key=lambda r: -r[3]):
        if all(abs(r[0] - c[0]) >= min_spacing * (t1 - t0) for c in chosen):
            chosen.append(r)
        if len(chosen) == max_poses:
            break
    return chosen


def feed_at(path, t, law):
    """The feed (m/s) the chip follows at t: the programmed speed of the move
    the tool is on (a program's own feeds), else the scenario's feed."""
    v = float(path.programmed_speed(t)) if hasattr(path, "programmed_speed") else 0.0
    return v if v > 0 else law.feed_m_per_s


def rightmost_root(arm, chip, refined=REFINED, pade=None):
    """The delay law's rightmost exact root (1/s, complex): the ``refined``
    rightmost Pade roots (``pade``: given, else computed) each refined by
    Newton on the exact characteristic equation
    (model/chip_coupling.refine_root), the rightmost of those that converge
    (the Pade root itself if none does)."""
    pade = cc.pade_roots(arm, chip, PADE_ORDER, MAX_HZ) if pade is None else pade
    A0, A1 = cc.delay_matrices(arm, chip)
    exact = [r for r in (cc.refine_root(A0, A1, chip.tooth_period_s, s) for s in pade[:refined]) if r is not None]
    return max((complex(r.real, abs(r.imag)) for r in exact), key=lambda r: r.real, default=pade[0])


def modes_involved(jm, arm, chip, s, top=2):
    """[(mode number, drives-closed frequency Hz, share)]: the arm's modes
    (motors held, numbered from the lowest) the root's link motion is most
    made of (mass-weighted shares, as the study's ``unstable_mode``)."""
    _, share, f_closed = cc.root_modes(jm, arm, chip, s)
    return [(int(i) + 1, float(f_closed[i]), float(share[i])) for i in np.argsort(-share)[:top]]


def largest_stable_depth_mm(arm, chip_at, p_m, depth_mm):
    """The largest depth of cut (mm) at the pose the delay law keeps stable
    (the tool raised in the workpiece, the arm's pose kept; the law
    linearised there by ``chip_at(p)``), by bisection to
    DEPTH_RESOLUTION_MM; 0.0 when not even the shallowest is."""
    def stable(d_mm):
        p = np.array(p_m, dtype=float)
        p[2] += (depth_mm - d_mm) / 1e3
        return rightmost_root(arm, chip_at(p)).real < 0
    if not stable(DEPTH_RESOLUTION_MM):
        return 0.0
    lo, hi = DEPTH_RESOLUTION_MM, float(depth_mm)
    while hi - lo > DEPTH_RESOLUTION_MM:
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if stable(mid) else (lo, mid)
    return lo


def depth_of_cut_mm(boxes_mm, p_m):
    """The depth of cut (mm) at the tool point p (m, the cutter's bottom):
    the highest top of the workpiece boxes under the tool's axis (of all
    boxes when none is) less the tool's height."""
    b = np.asarray(boxes_mm, dtype=float).reshape(-1, 5)
    x, y = p_m[0] * 1e3, p_m[1] * 1e3
    under = (b[:, 0] <= x) & (x <= b[:, 1]) & (b[:, 2] <= y) & (y <= b[:, 3])
    return float(np.max(b[under if under.any() else slice(None), 4]) - p_m[2] * 1e3)


def chatter_check(sc, robot, max_poses=MAX_POSES, min_spacing=MIN_SPACING):
    """The check's result (a dict for summary.json's "chatter_check": stable,
    growth_per_s, frequency_hz, t_s, x_mm, y_mm, z_mm, modes,
    damping_ratio_assumed, damping_to_stabilise, ...), or None when it does
    not apply (the tooth-resolved mode, no cut).  ``max_poses`` and
    ``min_spacing``: ``poses_to_check``'s (a denser check: a study's)."""
    if sc.cutting.mode != "averaged":
        return None
    from robstiff_drake.diagrams.compliant_arm import (arm_joints, controller_model, mass_and_weight_stiffness,
                                                       path_poses)
    from robstiff_drake.diagrams.path_references import planned_path
    from robstiff_drake.diagrams.scenario_models import (plant_cutting_setup, plant_damping_ratios, plant_stiffness,
                                                         servo_parameters)

    tool = robot.tool_point()
    path, t_ref, q_ref = planned_path(sc, robot, tool)  # (the run's own references: kept once per process)
    cutter, law, wp = plant_cutting_setup(sc)
    poses = poses_to_check(path, law, wp, max_poses=max_poses, min_spacing=min_spacing)
    if not poses:
        return None
    plant = controller_model(robot)
    K = jd.stiffness_matrix(plant_stiffness(sc, robot), sc.plant.coupling_c23_rad_per_Nm)
    zeta = plant_damping_ratios(sc)
    jm0 = arm_joints(plant, robot, path_poses(q_ref), K, zeta, servo_parameters(sc), sc.plant.damping_on)
    T = 1.0 / cutter.tooth_pass_hz

    def chip_at(p, u, feed):
        return cc.linearise_law(lambda pp, d, f: law.average_wrench(pp, d, wp, f), p, u, feed, T,
                                min_chip_m=min_chip_m(law))

    def q_at(t):
        return q_ref[min(int(np.argmin(np.abs(np.asarray(t_ref) - t))), len(q_ref) - 1)]

    at = []  # (Pade roots, t, p, u, F, feed, jm, arm, chip) per pose
    for t, p, u, F, feed in poses:
        q = q_at(t)
        jm = jm0.at_pose(*mass_and_weight_stiffness(plant, q))
        arm = cc.arm_from_joint_model(jm, kin.jacobian(robot.dh, q, tool))
        chip = chip_at(p, u, feed)
        at.append((cc.pade_roots(arm, chip, PADE_ORDER, MAX_HZ),) + (t, p, u, F, feed, jm, arm, chip))
    worst = None
    for pade, *rest in sorted(at, key=lambda a: -a[0][0].real)[:REFINED_POSES]:
        s = rightmost_root(rest[-2], rest[-1], pade=pade)
        if worst is None or s.real > worst[0].real:
            worst = (s, *rest)
    s, t, p, u, F, feed, jm, arm, chip = worst
    f_hz, _ = cc.mode_of(s)
    out = {"stable": bool(s.real < 0), "growth_per_s": float(s.real), "frequency_hz": float(f_hz),
           "t_s": float(t), "x_mm": float(p[0] * 1e3), "y_mm": float(p[1] * 1e3), "z_mm": float(p[2] * 1e3),
           "in_plane_force_N": float(F), "feed_mm_per_s": float(feed * 1e3), "poses_checked": len(poses),
           "damping_ratio_assumed": [float(z) for z in zeta], "damping_on": sc.plant.damping_on,
           "tooth_pass_hz": float(cutter.tooth_pass_hz), "modes": None, "largest_stable_depth_mm": None,
           "depth_mm": None, "damping_to_stabilise": None}
    if s.real >= 0:
        involved = modes_involved(jm, arm, chip, s)
        out["modes"] = [{"mode": m, "drives_closed_hz": f, "share": sh} for m, f, sh in involved]
        J = kin.jacobian(robot.dh, q_at(t), tool)
        out["damping_to_stabilise"] = damping_to_stabilise(jm, J, chip, rightmost_root, zeta,
                                                           [m for m, _, _ in involved], sc.plant.damping_on)
        depth = depth_of_cut_mm(sc.workpiece.boxes_mm, p)
        if depth > DEPTH_RESOLUTION_MM:
            out["depth_mm"] = float(depth)
            out["largest_stable_depth_mm"] = float(largest_stable_depth_mm(arm, lambda pp: chip_at(pp, u, feed), p,
                                                                            depth))
    return out


def check_job(sc, robot, warnings):
    """The check of a job before it runs (``simulate``, ``compensate-program``,
    ``sim-cell``): its result (``chatter_check``'s, for the summary's
    "chatter_check"), its warning line added to ``warnings`` (io.Warnings)."""
    check = chatter_check(sc, robot)
    line = chatter_warning(check)
    if line:
        warnings.add(line)
    return check


def chatter_warning(check):
    """The warning line of a check (``chatter_check``), or None if stable or not checked."""
    if not check or check["stable"]:
        return None
    z = check["damping_ratio_assumed"]
    zs = f"{100 * z[0]:g} %" if len(set(z)) == 1 else "(" + ", ".join(f"{100 * v:g}" for v in z) + ") %"
    modes = " and ".join(f"{m['mode']} ({m['drives_closed_hz']:.1f} Hz, share {m['share']:.2f})"
                         for m in check["modes"] or [])
    depth = ""
    if check["largest_stable_depth_mm"] is not None:
        depth = (f"; at that pose a depth of cut up to {check['largest_stable_depth_mm']:.2f} mm (now "
                 f"{check['depth_mm']:.2f}) would be stable")
    on = check["damping_on"].replace("_", "-")
    # what to measure: the modes the root is made of (the chip moves the root off them: 39-40 Hz -> 69 Hz)
    hz = sorted({round(m["drives_closed_hz"]) for m in check["modes"] or []})
    span = f"{hz[0]}-{hz[-1]}" if len(hz) > 1 else f"{hz[0]}" if hz else None
    tested = (f"the arm's modes near {span} Hz with the drives on" if span else
              f"the arm's modes near {check['frequency_hz']:.0f} Hz")
    g = check["growth_per_s"]
    doubling_s = math.log(2.0) / g if g > 0 else math.inf
    doubling = f"{doubling_s * 1e3:.0f} ms" if doubling_s < 1.0 else f"{doubling_s:.1f} s"
    short = g / (2.0 * math.pi * check["frequency_hz"]) if check["frequency_hz"] > 0 else math.inf
    verdict = ("is unstable" if short >= MARGINAL_DAMPING else
               f"is at the edge of stability (short of {100 * short:.2g} % of damping, inside what the damping "
               "assumption below can decide)")
    return (f"chatter: with the regenerative chip (the tool's displacement over a tooth) the arm at x = "
            f"{check['x_mm']:.0f}, y = {check['y_mm']:.0f} mm (t = {check['t_s']:.2f} s) {verdict}: growth "
            f"{g:+.{1 if g >= 1 else 2}f} 1/s (doubling in {doubling}) at {check['frequency_hz']:.1f} Hz, "
            f"arm modes {modes}; the simulation's plant leaves the regenerative chip out, so its surface figures "
            f"assume a stable cut. This rests on the arm's modal damping ratio {zs} on its "
            f"{on} modes (the scenario's plant damping, an assumption unless "
            f"measured): a modal test of {tested} would decide it"
            f"{damping_phrase(check.get('damping_to_stabilise'))}{depth}; a faster spindle may avoid it "
            "(docs/results.md: the arm with its own chip)")
