"""Joint-stiffness identification (Eq. 8) on synthetic campaigns."""

import numpy as np
import pytest

from robstiff_drake.identification.stiffness import synth
from robstiff_drake.identification.stiffness.joint_stiffness import identify


def as_campaign(c, moments=None, rot_mrad=None):
    camp = c.to_campaign("synthetic.csv")
    if moments is not None:
        camp.moment_Nm, camp.has_moments = moments, True
    camp.rot_mrad = rot_mrad
    return camp


def reload(robot, c, force_N, noise_mm=0.01, seed=0):
    """Give campaign ``c`` new forces and the displacements that go with them."""
    from robstiff_drake.model import effects as fx

    c.force_N = np.asarray(force_N, dtype=float)
    W = np.hstack([c.force_N, np.zeros_like(c.force_N)])
    ctx = fx.EffectContext(robot.dh, robot.joint_stiffness_Nm_per_rad, np.deg2rad(c.q_deg), W, c.seq, np.zeros(3))
    c.disp_mm = ctx.disp_from_wrench(W) * 1e3 + np.random.default_rng(seed).normal(scale=noise_mm, size=W[:, :3].shape)
    return c


@pytest.mark.parametrize("seed", [1, 2, 3, 4])
def test_joints_1_to_3_within_3_percent(robot, seed):
    c = synth.stiffness_campaign(robot, n=120, noise_mm=0.01, seed=seed)
    fit = identify(robot, as_campaign(c))
    rel = fit.stiffness_Nm_per_rad / robot.joint_stiffness_Nm_per_rad - 1
    assert np.all(np.abs(rel[:3]) < 0.03), rel
    assert fit.rms_residual_mm == pytest.approx(0.01, rel=0.2)
    assert fit.n_measurements == 120


def test_standard_errors_are_honest(robot):
    """Over many seeds the 95 % intervals cover the true stiffness about 95 %
    of the time (binomial bounds for 300 trials), for every identified joint."""
    k_true = np.array([1.3e6, 1.2e6, 0.7e6, 3.5e5, 2.5e5, 2.0e5])  # not the nominal values
    hits = np.zeros(6)
    counted = np.zeros(6)
    for seed in range(300):
        c = synth.stiffness_campaign(robot, n=120, noise_mm=0.01, seed=1000 + seed, true_stiffness_Nm_per_rad=k_true)
        fit = identify(robot, as_campaign(c))
        for j in np.flatnonzero(fit.identifiable):
            lo, hi = fit.stiffness_ci95_Nm_per_rad[j]
            hits[j] += lo <= k_true[j] <= hi
            counted[j] += 1
    coverage = hits[:5] / counted[:5]
    assert np.all(counted[:3] == 300)
    assert np.all(coverage > 0.91) and np.all(coverage < 0.985), coverage


def test_joint6_not_identifiable_with_tool_on_its_axis(robot):
    for tool in (np.zeros(3), np.array([0.0, 0.0, 0.35])):
        c = synth.stiffness_campaign(robot, n=120, seed=5, tool_m=tool)
        fit = identify(robot, as_campaign(c), tool_m=tool)
        assert list(fit.identifiable) == [True] * 5 + [False]
        assert "no torque" in fit.reasons[5]
        assert fit.stiffness_Nm_per_rad[5] == robot.joint_stiffness_Nm_per_rad[5]  # nominal, not invented
        assert np.isnan(fit.stiffness_std_Nm_per_rad[5])


def test_moments_and_rotations_identify_joint6(robot):
    rng = np.random.default_rng(7)
    c = synth.stiffness_campaign(robot, n=120, seed=7, noise_mm=0.0)
    moments = rng.normal(size=(120, 3)) * 50.0  # N*m, e.g. from a lever on the tool
    W = np.hstack([c.force_N, moments])
    from robstiff_drake.model import effects as fx

    ctx = fx.EffectContext(robot.dh, robot.joint_stiffness_Nm_per_rad, np.deg2rad(c.q_deg), W, c.seq, np.zeros(3))
    dq = ctx.tau * ctx.c
    disp = np.einsum("nrj,nj->nr", ctx.J[:, :3], dq) * 1e3 + rng.normal(scale=0.01, size=(120, 3))
    rot = np.einsum("nrj,nj->nr", ctx.J[:, 3:], dq) * 1e3 + rng.normal(scale=0.005, size=(120, 3))
    c.disp_mm = disp
    fit = identify(robot, as_campaign(c, moments=moments, rot_mrad=rot))
    assert fit.identifiable.all()
    rel = fit.stiffness_Nm_per_rad / robot.joint_stiffness_Nm_per_rad - 1
    assert np.all(np.abs(rel) < 0.05), rel
    assert fit.sigma_rot_mrad == pytest.approx(0.005, rel=0.3)


def test_dependent_columns_are_flagged_not_invented(robot):
    # one pose, loads in two directions only: at most two combinations of the
    # joint compliances are observable, the other joints must be flagged
    c = synth.stiffness_campaign(robot, n=8, loads_per_pose=8, seed=3)
    reload(robot, c, np.array([[300.0, 0, 0], [0, 300.0, 0]] * 4) * np.repeat([1.0, -1.0, 0.5, -0.5], 2)[:, None])
    fit = identify(robot, as_campaign(c))
    assert 1 <= fit.identifiable.sum() <= 3
    for j in np.flatnonzero(~fit.identifiable):
        assert fit.stiffness_Nm_per_rad[j] == robot.joint_stiffness_Nm_per_rad[j]
        assert fit.reasons[j]


def test_rank_one_campaign_identifies_at_most_one_joint(robot):
    # one pose, all loads on one line: one combination of six compliances
    c = synth.stiffness_campaign(robot, n=8, loads_per_pose=8, seed=3)
    reload(robot, c, np.outer(np.linspace(-1, 1, 8) + 0.05, [300.0, 0.0, 0.0]))
    fit = identify(robot, as_campaign(c))
    # a single load line still gives three displacement components per load:
    # at most three combinations are observable
    assert 1 <= fit.identifiable.sum() <= 3
    assert sum("combination of the others" in r for r in fit.reasons) >= 2
    for j in np.flatnonzero(~fit.identifiable):
        assert fit.stiffness_Nm_per_rad[j] == robot.joint_stiffness_Nm_per_rad[j]


def test_campaign_that_pins_nothing_down_is_a_clear_error(robot):
    from robstiff_drake.errors import InputError

    c = synth.stiffness_campaign(robot, n=12, loads_per_pose=4, seed=3, force_N=10.0, noise_mm=0.2)
    with pytest.raises(InputError, match="no joint can be identified"):
        identify(robot, as_campaign(c))


def test_robust_fit_resists_outliers(robot):
    c = synth.stiffness_campaign(robot, n=120, seed=11)
    c.disp_mm[[5, 40, 77, 90, 101], 2] += 0.8  # five gross outliers (mis-read CMM points)
    plain = identify(robot, as_campaign(c))
    robust = identify(robot, as_campaign(c), robust=True)
    err_plain = np.abs(plain.stiffness_Nm_per_rad[:3] / robot.joint_stiffness_Nm_per_rad[:3] - 1)
    err_robust = np.abs(robust.stiffness_Nm_per_rad[:3] / robot.joint_stiffness_Nm_per_rad[:3] - 1)
    assert err_robust.max() < 0.03
    assert err_plain.max() > 2 * err_robust.max()
    assert sorted(robust.outlier_rows) == [5, 40, 77, 90, 101]


def test_negative_compliance_is_reported_as_non_physical(robot):
    k_true = robot.joint_stiffness_Nm_per_rad.copy()
    k_true[2] = -8e5  # a data set that only a negative joint-3 spring explains
    c = synth.stiffness_campaign(robot, n=120, seed=2, true_stiffness_Nm_per_rad=k_true)
    fit = identify(robot, as_campaign(c))
    assert fit.non_physical == [3]
    assert fit.compliance_rad_per_Nm[2] < 0
