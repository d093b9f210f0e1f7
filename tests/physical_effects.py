"""The named library's effects at physical sizes, for the confusion study
(studies/diagnosis_confusion.py) and the tests: each effect's parameters
drawn in its physical pattern and range, with the range's source or
reasoning next to it.  The diagnosis's plausibility bounds
(robstiff_drake/identification/diagnosis/plausibility.py) are generous limits of what
is physically possible; the ranges here are what real arms and cells show,
inside those bounds, so that a planted effect of physical size is one the
diagnosis may add."""

import numpy as np

from robstiff_drake.identification.stiffness import synth


def _unit(rng):
    v = rng.normal(size=3)
    return v / np.linalg.norm(v)


# The top of each effect's physical range (what table A of the study caps its
# sizes at), with its source or reasoning.
TOP = {
    "lost_motion": "60 urad per main axis (a robot axis typically shows 10-60 urad; RV reducers <= 1 arc-min)",
    "joint_coupling": "0.85 sqrt(c2 c3): axis 3 driven by a parallel rod from a gearbox at the turret, written in the "
                      "model's relative angles, gives c23 = -c2, i.e. sqrt(c2 / c3) = 0.85 with the IRB 6400 file's "
                      "stiffness (a serial elbow drive: a few %)",
    "load_dependent_stiffness": "compliance 30 % lower per kN*m (reducer torsion curves change slope by up to 1:3)",
    "posture_dependent_stiffness": "40 % per rad of q2 (an axis-2 balancer's spring changes its share with q2)",
    "geometric_stiffness": "factor 1: the physics of the load's lever arm (no range)",
    "link_compliance": "0.1 um/N (the forearm as a steel tube, L^3/3EI = 0.044 um/N; a cast arm up to twice that)",
    "force_frame_rotation": "3 deg (a load cell mounted by eye against its drawing)",
    "force_bias": "10 N (a tared load cell's drift over a campaign)",
    "tool_offset": "5 mm (a TCP calibrated by touching up a few points)",
    "drift": "1 um per measurement (a large arm's warm-up, 0.1-0.5 mm over hours)",
}


def physical_params(name, rng, robot):
    """Parameters (SI, as model/effects.py takes them) drawn inside the
    effect's typical physical range (table B of the study)."""
    c = 1.0 / robot.joint_stiffness_Nm_per_rad
    if name == "lost_motion":  # 10-60 urad per main axis
        return {"b_rad": np.r_[rng.uniform(10e-6, 60e-6, 3), 0, 0, 0]}
    if name == "joint_coupling":  # 5-30 % of sqrt(c2 c3): a serial elbow drive or the structure (ASSUMPTION)
        return {"c23_rad_per_Nm": rng.uniform(0.05, 0.3) * np.sqrt(c[1] * c[2]) * rng.choice([-1, 1])}
    if name == "load_dependent_stiffness":  # compliance 5-30 % lower per kN*m
        return {"beta": -np.r_[rng.uniform(0.05, 0.3, 3), 0, 0, 0]}
    if name == "posture_dependent_stiffness":  # balancer: 10-40 % per rad of q2
        return {"gamma_per_rad": rng.uniform(0.1, 0.4) * rng.choice([-1, 1])}
    if name == "geometric_stiffness":  # the physics: factor 1
        return {"lambda": 1.0}
    if name == "link_compliance":  # 0.02-0.1 um/N
        return {"c_link_m_per_N": rng.uniform(0.02e-6, 0.1e-6)}
    if name == "force_frame_rotation":  # sensor mounted 0.5-3 deg off
        return {"phi_rad": _unit(rng) * np.deg2rad(rng.uniform(0.5, 3.0))}
    if name == "force_bias":  # 2-10 N left after taring
        return {"bias_N": _unit(rng) * rng.uniform(2.0, 10.0)}
    if name == "tool_offset":  # TCP error 1-5 mm
        return {"delta_m": _unit(rng) * rng.uniform(1e-3, 5e-3)}
    if name == "drift":  # 0.1-1 um per measurement (warm-up)
        return {"v_m_per_step": _unit(rng) * rng.uniform(0.1e-6, 1e-6)}
    raise KeyError(name)


def top_params(name, rng, robot):
    """The effect's pattern (signs, directions, the joints' shares) drawn at
    random, at the top of its physical range (TOP)."""
    c = 1.0 / robot.joint_stiffness_Nm_per_rad
    if name == "lost_motion":
        return {"b_rad": np.r_[60e-6 * rng.uniform(0.5, 1.0, 3), 0, 0, 0]}
    if name == "joint_coupling":
        return {"c23_rad_per_Nm": 0.85 * np.sqrt(c[1] * c[2]) * rng.choice([-1, 1])}
    if name == "load_dependent_stiffness":
        return {"beta": -np.r_[0.3 * rng.uniform(0.5, 1.0, 3), 0, 0, 0]}
    if name == "posture_dependent_stiffness":
        return {"gamma_per_rad": 0.4 * rng.choice([-1, 1])}
    if name == "geometric_stiffness":
        return {"lambda": 1.0}
    if name == "link_compliance":
        return {"c_link_m_per_N": 0.1e-6}
    if name == "force_frame_rotation":
        return {"phi_rad": _unit(rng) * np.deg2rad(3.0)}
    if name == "force_bias":
        return {"bias_N": _unit(rng) * 10.0}
    if name == "tool_offset":
        return {"delta_m": _unit(rng) * 5e-3}
    if name == "drift":
        return {"v_m_per_step": _unit(rng) * 1e-6}
    raise KeyError(name)


def visible_campaign(robot, name, rng, target_mm, *, seed, force_N, noise_mm, n=120):
    """A synth campaign with effect ``name`` in its physical pattern, scaled
    so that the part beyond the six springs has an RMS of ``target_mm``, but
    never beyond the top of its physical range (TOP): where the range ends
    first, the campaign carries the largest physical size (below the target).
    The CCT factor is the physics' 1 whatever the target."""
    top = top_params(name, rng, robot)
    kw = dict(n=n, noise_mm=noise_mm, seed=seed, force_N=force_N)
    at_top = synth.stiffness_campaign(robot, effect_params={name: top}, **kw)
    visible = at_top.effect_rms_mm[name][1]
    scale = 1.0 if name == "geometric_stiffness" else min(1.0, target_mm / visible)
    if scale == 1.0:
        return at_top
    return synth.stiffness_campaign(robot, effect_params={name: {k: np.asarray(v) * scale for k, v in top.items()}},
                                    **kw)
