"""The pose-clustered test of the residual diagnosis is calibrated on few
poses (identification/diagnosis/clustered_test.py: CR2 sandwich, a
Bell-McCaffrey t per contrast, Bonferroni over the q tested).  On the
synthetic regression of tests/clustered_null.py the uncorrected test (CR1
sandwich, F(q, G - 1)) rejected the true null in 31 of the 200 draws of one
parameter at a nominal 5 % (outside the band) and in 83 of 200 for three;
this one in 6 and 1.  The HTZ reference the diagnosis used before (6 and 0)
found one effect planted on one of three parameters in 18 of 200 draws
where this test finds it in 125."""

import numpy as np
from scipy import stats
from scipy.linalg import sqrtm

from clustered_null import DRAWS, LEVEL, SEEDS, null_design, rejections
from robstiff_drake.identification.diagnosis import clustered_test as ct
from robstiff_drake.identification.diagnosis.clustered_test import _eta, clustered_fit

# two-sided binomial band for 200 draws at 5 % (99 %: 3..19 rejections); an exact test stays inside
BAND = (3, 19)


def test_one_parameter_at_ten_poses_is_calibrated():
    hits = rejections(10, 1, SEEDS[1])
    assert BAND[0] <= hits <= BAND[1], f"{hits}/{DRAWS} rejections of a true null at {LEVEL:g}"


def test_three_parameters_at_ten_poses_are_not_liberal():
    # Bonferroni over three contrasts is conservative at 5 % (1 of 200 here); it must never be liberal
    hits = rejections(10, 3, SEEDS[3])
    assert hits <= BAND[1], f"{hits}/{DRAWS} rejections of a true null at {LEVEL:g}"


def test_an_effect_on_one_of_three_parameters_is_found_where_htz_cannot():
    # one tested column's coefficient planted at the noise's RMS; on 10 poses of uneven leverage HTZ's eta is
    # often near q = 3, where its F(q, eta - q + 1) has no tail: it found 18 of 200, this test 125
    rng = np.random.default_rng(3)
    hits = 0
    for _ in range(DRAWS):
        X, y, g, cols = null_design(rng, 10, 3)
        y = y + X[:, cols.start] / np.sqrt(np.mean(X[:, cols.start] ** 2))
        hits += clustered_fit(X, y, g).p(cols) < LEVEL
    assert hits >= 80, f"found in {hits}/{DRAWS}"


def test_the_p_is_q_times_the_smallest_of_the_uncorrelated_contrasts():
    # an effect planted on one of three tested columns; by hand: the eigenvectors of the working model's covariance
    # of the tested coefficients (scaled problem), each one's CR2 t against t(eta_k), the smallest p times three
    rng = np.random.default_rng(4)
    X, y, g, cols = null_design(rng, 10, 3)
    y = y + X[:, cols.start] / np.sqrt(np.mean(X[:, cols.start] ** 2))
    fit = clustered_fit(X, y, g)
    idx = np.arange(cols.start, cols.stop)
    b, V = (fit.coef * fit.scale)[idx], (fit.cov * np.outer(fit.scale, fit.scale))[np.ix_(idx, idx)]
    _, Q = np.linalg.eigh(np.linalg.inv((X / fit.scale).T @ (X / fit.scale))[np.ix_(idx, idx)])
    ps = []
    for c in Q.T:
        C = np.zeros((1, X.shape[1]))
        C[0, idx] = c
        ps.append(2 * stats.t.sf(abs(c @ b) / np.sqrt(c @ V @ c), _eta(fit, C)))
    p = ct.bm_bonferroni(fit, cols)[0]
    assert p < LEVEL and np.isclose(p, 3 * min(ps))
    assert np.isclose(fit.p(slice(cols.start, cols.start + 1)), ct.htz(fit, slice(cols.start, cols.start + 1))[0])


def test_cr2_and_its_degrees_of_freedom_match_the_dense_formulas():
    # clusters of unequal size, rows not sorted by cluster: the batched form equals the textbook one
    rng = np.random.default_rng(1)
    sizes = [3, 6, 6, 9, 3, 6, 9]
    g = np.concatenate([[i] * s for i, s in enumerate(sizes)])
    n, p = len(g), 5
    perm = rng.permutation(n)
    X = (rng.normal(size=(n, p)) * np.exp(rng.normal(size=(n, 1))))[perm]
    y, g = rng.normal(size=n), g[perm]
    fit = clustered_fit(X, y, g)
    Xs = X / fit.scale
    B = np.linalg.pinv(Xs.T @ Xs)
    IH = np.eye(n) - Xs @ B @ Xs.T
    e = IH @ y
    for cols in ([3], [2, 3, 4]):
        C = np.eye(p)[cols]
        Om_ih = np.linalg.inv(np.real(sqrtm(C @ B @ C.T)))
        meat, blocks = np.zeros((p, p)), []
        for k in range(len(sizes)):
            i = np.flatnonzero(g == k)
            A = np.real(np.linalg.inv(sqrtm(np.eye(len(i)) - (np.eye(n) - IH)[np.ix_(i, i)])))
            s = Xs[i].T @ A @ e[i]
            meat += np.outer(s, s)
            blocks.append(Om_ih @ C @ B @ Xs[i].T @ A @ IH[i])
        assert np.allclose(B @ meat @ B / np.outer(fit.scale, fit.scale), fit.cov)
        assert np.allclose(sum(b @ b.T for b in blocks), np.eye(len(cols)))  # CR2: unbiased under the working model
        tot = sum(np.trace(bg @ bh.T) ** 2 + np.trace(bg @ bh.T @ bg @ bh.T) for bg in blocks for bh in blocks)
        assert np.isclose(_eta(fit, C), len(cols) * (len(cols) + 1) / tot)


def test_a_tool_point_20_mm_off_along_z_is_named():
    # Drake's plant campaign (30 poses x 4 loads, studies/setup_mistakes.py) with the declared tool point 20 mm off
    # along the flange's z: the fit needs 21.4 mm, beyond the typical 20 mm, so both tests must reach 1e-6; the
    # three offset parameters' clustered p is 1.4e-6 under HTZ (not named, only a lead) and 7.2e-7 here
    import setup_errors as se

    from robstiff_drake.identification.diagnosis.campaign_diagnosis import diagnose
    from robstiff_drake.model.robot import load_robot

    c = se.make_campaign("none", 11)
    tool_m = np.asarray(c.declared_tool_m, dtype=float) + np.array([0.0, 0.0, 0.020])
    d = diagnose(load_robot(), c.campaign, tool_m=tool_m, noise_mm=se.NOISE_MM)
    assert "tool_offset" in [t["name"] for t in d.terms], d.verdict
    offset_mm = next(t for t in d.terms if t["name"] == "tool_offset")["params"]
    assert abs(offset_mm["d_z (mm)"] + 20.0) < 3.0, offset_mm
