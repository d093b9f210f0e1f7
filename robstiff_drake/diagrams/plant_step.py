"""The plant's step: whether a step keeps every mode of the arm stable and
resolves its physics (the gears' flank impacts in their play, a
tooth-resolved cutting force), the step that would, and, for a scenario
that gives no step, the step the station takes (``scenario_step_s``):
the largest one up to DEFAULT_MAX_STEP_S that does all of it."""

from typing import NamedTuple

import numpy as np

# A scenario that gives no plant_config.time_step (or gives 0: the schema's default, the marker of "not given";
# Drake's 0, a continuous plant, is no step the station runs): the station takes the largest step up to this
# that keeps every mode stable and resolves what the scenario contains (``chosen_step``).  2 ms was every
# scenario's explicit step before, and is the step without play or a tooth-resolved force
# (studies/time_step_convergence.py: the averaged passes within 0.1 um of 0.5 ms).
DEFAULT_MAX_STEP_S = 0.002
NOT_GIVEN = 0.0


def stable_step_on_grid_s(jm, upper_s):
    """The largest step up to ``upper_s`` (s) on the sensor's grid
    (``step_on_grid_s``: 0.1 ms above 1 ms, 1 ms / n below) whose scheme
    keeps every mode of the joints ``jm`` stable, each candidate checked
    (the step map's spectral radius, joint_dynamics.JointModel.is_stable_step),
    so the step returned passes the check whatever step it was asked from;
    None when not even 1 ms / 1000 does."""
    h = step_on_grid_s(upper_s)
    while h >= 1e-6:
        if jm.is_stable_step(h):
            return h
        h = step_on_grid_s(h - 1e-4 * (1 - 1e-6)) if h > 1e-3 + 1e-12 else 1e-3 / (round(1e-3 / h) + 1)
    return None


def _stable_limit_s(jm, stable_s, unstable_s, resolution_s=1e-6):
    """The step (s) between a stable ``stable_s`` and an unstable
    ``unstable_s`` where the scheme stops being stable, by bisection,
    rounded down to ``resolution_s``."""
    lo, hi = float(stable_s), float(unstable_s)
    while hi - lo > resolution_s:
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if jm.is_stable_step(mid) else (lo, mid)
    return np.floor(lo / resolution_s + 1e-9) * resolution_s


def growing_mode(jm, time_step_s):
    """The mode the step ``time_step_s`` (s) grows most (ask just past the
    stable limit: far past it a mode's frequency may be aliased), as a dict:
    growth_per_step (the step map's largest eigenvalue's modulus), and of
    the continuous closed loop's mode it is (the nearest in frequency):
    frequency_hz, damping_ratio, joint (0-based: the gear with the most of
    its elastic energy) and motor_share (the share of its kinetic energy in
    that joint's motor)."""
    h = float(time_step_s)
    z = np.linalg.eigvals(jm.step_map(h)).astype(complex)
    zi = z[np.argmax(np.abs(z))]
    f_step = abs(np.log(zi)) / (2 * np.pi * h)
    lam, V = np.linalg.eig(jm.continuous()[0])
    osc = np.nonzero(lam.imag > 1e-9)[0]
    k = osc[np.argmin(np.abs(np.abs(lam[osc]) / (2 * np.pi) - f_step))]
    v = V[:, k]
    twist = v[12:18] - v[0:6]
    j = int(np.argmax(np.real(twist.conj() * (jm.K @ twist))))
    link_ke = np.real(v[6:12].conj() @ jm.M @ v[6:12])
    motor_ke = np.abs(v[18:24]) ** 2 * jm.motor_inertia_kgm2
    return {"frequency_hz": float(abs(lam[k]) / (2 * np.pi)), "damping_ratio": float(-lam[k].real / abs(lam[k])),
            "growth_per_step": float(abs(zi)), "joint": j,
            "motor_share": float(motor_ke[j] / (link_ke + motor_ke.sum()))}


class StepRefusal(NamedTuple):
    """Why a plant step is refused: ``line``, what is wrong and the fix (one
    line, about 200 characters: the step, the mode and its joint, the step
    that passes); ``why``, the detail (the mode's damping and motor share,
    its motor's rotor inertia, given or assumed, the criterion with its
    numbers), or None."""

    line: str
    why: str | None


class StepError(ValueError):
    """A refused plant step (a ValueError, as the station's other
    refusals), its detail in ``why`` (printed after the error's line:
    commands/main.py)."""

    def __init__(self, refusal):
        super().__init__(refusal.line)
        self.why = refusal.why


def unstable_step_refusal(jm, time_step_s, assumed_motor_inertia=False):
    """None when the plant step keeps every mode of the joints ``jm``
    stable, else a StepRefusal: the line names the mode and which joint's
    gear and motor carry it, and the step on the sensor's grid that passes
    this check (and, when ``assumed_motor_inertia``, the robot file gives no
    motor_inertia_kgm2: joint_dynamics.motor_inertia's assumption, the
    datasheet value as the other way out); the why, the criterion with its
    numbers and the assumed inertia."""
    if jm.is_stable_step(time_step_s):
        return None
    lam = np.linalg.eigvals(jm.continuous()[0])
    worst = lam[np.argmax(lam.real)]
    if worst.real >= 0.0:  # no step helps: the loop itself grows
        return StepRefusal(f"the joints' loop is unstable whatever the step: its {abs(worst) / (2 * np.pi):.1f} Hz "
                           f"mode grows (the drives' loops against too lightly damped gears): raise "
                           f"plant.modal_damping_ratio or plant.damping_ratios, or lower servo.velocity_integral_hz",
                           None)
    h = float(time_step_s)
    ok = stable_step_on_grid_s(jm, h)
    edge = _stable_limit_s(jm, ok or 0.0, h)
    # the mode that sets the limit: the one growing just past it (at ``h`` a mode's frequency may be aliased)
    m = growing_mode(jm, min(edge + 2e-6, h))
    w = 2 * np.pi * m["frequency_hz"]
    j = m["joint"]
    limit = np.floor(edge * 1e5) / 1e5  # (printed to 0.01 ms: rounded down)
    jj = f"joint {j + 1}"
    if assumed_motor_inertia:
        motor = (f"; its motor's rotor inertia is assumed, {jm.motor_inertia_kgm2[j]:.3g} kg*m^2 = the link's "
                 f"inertia on {jj} (the robot file gives no motor_inertia_kgm2: the assumption of "
                 f"model/joint_dynamics.motor_inertia, a load-to-rotor ratio of 1 from the servo-sizing rule)")
        other = (f", or give the motors' rotor inertias (robot file motor_inertia_kgm2; {jj}'s is assumed)")
        datasheet = (f" The motors' datasheet rotor inertias (robot file motor_inertia_kgm2: n^2 J_rotor per joint, "
                     f"kg*m^2) replace the assumption; a heavier rotor on {jj} lowers the mode.")
    else:
        motor = f"; its motor's rotor inertia {jm.motor_inertia_kgm2[j]:.3g} kg*m^2 (motor_inertia_kgm2)"
        other = datasheet = ""
    use = f"use {ok * 1e3:g} ms (plant_config.time_step: {ok:g})" if ok else "no step on the sensor's grid passes"
    line = (f"a {h * 1e3:g} ms plant step is unstable for the arm's {m['frequency_hz']:.0f} Hz mode ({jj}'s gear "
            f"and motor): {use}{other}")
    why = (f"the {m['frequency_hz']:.0f} Hz mode ({jj}'s gear between its motor and the link, "
           f"{m['damping_ratio'] * 100:.1f} % damped, {m['motor_share'] * 100:.0f} % of its motion in {jj}'s "
           f"motor{motor}): the plant steps each motor through its drive with the gear's torque held over the step, "
           f"which feeds the mode energy its damping must take out, so it holds only while omega h <= {w * limit:.2f} "
           f"(up to {limit * 1e3:.2f} ms), not the omega h < 2 of an undamped mode; at {h * 1e3:g} ms omega h = "
           f"{w * h:.2f} and it grows x{jm.spectral_radius(h):.3g} a step."
           + (" The step advised is the largest on the sensor's grid (1 ms / n, 0.1 ms steps) that passes." if ok
              else "") + datasheet)
    return StepRefusal(line, why)


def unstable_step_message(jm, time_step_s, assumed_motor_inertia=False):
    """None when the plant step keeps every mode of the joints ``jm``
    stable, else the refusal's one line (``unstable_step_refusal``)."""
    refusal = unstable_step_refusal(jm, time_step_s, assumed_motor_inertia)
    return None if refusal is None else refusal.line


def twist_inertia_kgm2(jm):
    """(6,) J_eff of each gear's twist phi = theta - q (kg*m^2): its link
    (1 / (M^-1)_jj, the rest of the arm free) in series with its motor:
    model/joint_dynamics.JointModel.twist_inertia_kgm2)."""
    return jm.twist_inertia_kgm2()


def contact_frequencies_hz(jm):
    """(6,) each gear's contact mode (Hz): its stiffness on the twist's
    inertia (``twist_inertia_kgm2``), the mode a flank impact rings in."""
    return np.sqrt(np.diag(jm.K) / twist_inertia_kgm2(jm)) / (2 * np.pi)


# A tooth-resolved cutting force is resolved by the plant's step when the step takes at least TOOTH_STEPS_PER_PASS
# samples of each tooth pass (the step's mean then keeps 98 % of the tooth-pass harmonic, and nothing folds
# down) and keeps every mode of the arm within omega h <= RESOLVED_OMEGA_H.  On the IRB 6400 with the paper's
# 360 Hz tooth pass that is 0.25 ms: there joint 6's twist per N*m of tooth force is 3 % above the continuous
# model's and its 126 Hz / 5.5 % wrist mode comes out 126.9 Hz / 5.3 % (joint_dynamics.JointModel.step_modes);
# at 0.5 ms 10 % above, at 2 ms 19 times (the tooth pass folded to 140 Hz, the mode moved to 153 Hz / 3.6 %;
# studies/time_step_convergence.py).
TOOTH_STEPS_PER_PASS = 10.0


def step_on_grid_s(step_s):
    """``step_s`` rounded down to a step that divides 1 ms (1 ms / n) below
    1 ms, to 0.1 ms above: the sensor's and controller's periods stay
    whole numbers of plant steps."""
    if step_s >= 1e-3:
        return float(np.floor(step_s * 1e4 + 1e-9) / 1e4)
    return 1e-3 / np.ceil(1e-3 / step_s - 1e-9)


def tooth_resolving_step_s(jm, tooth_pass_hz):
    """The largest plant step (s) that resolves a tooth-resolved force of
    ``tooth_pass_hz`` on the joints ``jm`` (TOOTH_STEPS_PER_PASS)."""
    f_top = jm.closed_loop_modes()[0].max()
    return step_on_grid_s(min(1.0 / (TOOTH_STEPS_PER_PASS * tooth_pass_hz), RESOLVED_OMEGA_H / (2 * np.pi * f_top)))


def unresolved_tooth_message(jm, tooth_pass_hz, time_step_s, regenerative=False):
    """None when the plant step resolves a tooth-resolved force of
    ``tooth_pass_hz`` (Hz), else why not and the step that would (one
    line); ``regenerative``: the force is the regenerative chip's
    (cutting.chip: regenerative, which needs the teeth resolved)."""
    ok = tooth_resolving_step_s(jm, tooth_pass_hz)
    if time_step_s <= ok * (1 + 1e-9):
        return None
    ok_ms = round(ok * 1e3, 4)
    what, other = (("cutting.chip: regenerative", "cutting.chip: program with cutting.mode: averaged") if regenerative
                   else ("cutting.mode: tooth", "cutting.mode: averaged"))
    return (f"a {time_step_s * 1e3:g} ms plant step does not resolve the tooth-resolved force ({what}, "
            f"{tooth_pass_hz:.0f} Hz tooth pass) on an arm whose stiffest mode is "
            f"{jm.closed_loop_modes()[0].max():.0f} Hz: the step's mean folds it down next to that mode and the "
            f"step moves the mode; use at most {ok_ms:g} ms (plant_config.time_step: {ok_ms / 1e3:g}) or "
            f"{other}")


# A flank impact lasts half a period of the gear's contact mode.  The explicit step locates no contact inside
# itself: the restitution of an impact comes out within 5 % of its converged value (whatever the phase of the
# impact on the step's grid) while omega_c h <= RESOLVED_OMEGA_H (studies/time_step_convergence.py measures
# it on the IRB 6400's joint 6, and the test of tests/test_gear_play_resolution.py keeps it).
RESOLVED_OMEGA_H = 0.4


def resolving_step_s(jm, play_rad):
    """The largest plant step (s) that resolves every gear with play's flank
    impacts (RESOLVED_OMEGA_H), or None without play."""
    b = np.asarray(play_rad, dtype=float)
    if not np.any(b > 0):
        return None
    w = 2 * np.pi * contact_frequencies_hz(jm)[b > 0]
    return step_on_grid_s(RESOLVED_OMEGA_H / w.max())


def under_resolved_play_message(jm, play_rad, time_step_s):
    """None when the plant step resolves the flank impacts of every gear
    with play, else which joint it does not and the step that would (one
    line)."""
    b = np.asarray(play_rad, dtype=float)
    f = contact_frequencies_hz(jm)
    if time_step_s <= resolving_step_s(jm, b) * (1 + 1e-9):
        return None
    bad = [j for j in range(6) if b[j] > 0 and 2 * np.pi * f[j] * time_step_s > RESOLVED_OMEGA_H * (1 + 1e-9)]
    if not bad:
        return None
    j = max(bad, key=lambda i: f[i])
    ok_ms = round(resolving_step_s(jm, b) * 1e3, 4)
    return (f"joint {j + 1}'s play ({b[j] * 1e3:.3g} mrad, plant.lost_motion_rad) hits its flanks in a "
            f"{f[j]:.0f} Hz contact mode that a {time_step_s * 1e3:g} ms plant step does not resolve (its impacts' "
            f"restitution comes out wrong, energy created): use at most {ok_ms:g} ms (plant_config.time_step: "
            f"{ok_ms / 1e3:g}) or no play on that joint")


def chosen_step(jm, play_rad=None, tooth_pass_hz=None, max_step_s=DEFAULT_MAX_STEP_S):
    """(step s, why: one line) the station takes when the scenario gives
    none: the largest step up to ``max_step_s`` on the sensor's grid
    (``step_on_grid_s``) that keeps every mode of the joints ``jm`` stable,
    resolves the flank impacts of every gear with play (``play_rad``, half
    widths) and a tooth-resolved force of ``tooth_pass_hz`` (None: averaged)."""
    needs = []  # (step s, what needs it)
    if not jm.is_stable_step(max_step_s):
        ok = stable_step_on_grid_s(jm, max_step_s)
        m = growing_mode(jm, min(_stable_limit_s(jm, ok or 0.0, max_step_s) + 2e-6, max_step_s))
        needs.append((ok or max_step_s,  # (none: the loop's own refusal)
                      f"the arm's {m['frequency_hz']:.0f} Hz mode (joint {m['joint'] + 1}'s gear) stable"))
    b = np.zeros(6) if play_rad is None or not len(play_rad) else np.asarray(play_rad, dtype=float)
    if np.any(b > 0):
        f = contact_frequencies_hz(jm)
        j = max((i for i in range(6) if b[i] > 0), key=lambda i: f[i])
        needs.append((resolving_step_s(jm, b), f"joint {j + 1}'s play (its {f[j]:.0f} Hz contact mode)"))
    if tooth_pass_hz:
        needs.append((tooth_resolving_step_s(jm, tooth_pass_hz),
                      f"the tooth-resolved force ({tooth_pass_hz:.0f} Hz tooth pass)"))
    h = min([max_step_s] + [s for s, _ in needs])
    what = "; ".join(f"{w} needs {round(s * 1e3, 4):g} ms" for s, w in sorted(needs))
    return h, (f"plant step {round(h * 1e3, 4):g} ms (plant_config.time_step not given: the largest step up to "
               f"{max_step_s * 1e3:g} ms that resolves the scenario's physics; "
               + (what if needs else "no play and no tooth-resolved force need a finer one") + ")")


def step_choice(sc):
    """The one line of why the station took the scenario's plant step
    (diagrams/scenario_step.scenario_step_s), or None when the scenario gave it."""
    c = getattr(sc, "_plant_step_choice", None)
    return c[1] if c is not None and abs(float(sc.plant_config.time_step) - c[0]) < 1e-15 else None
