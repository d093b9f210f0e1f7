"""The pose-clustered test of the residual diagnosis is calibrated on few
poses (identification/diagnosis/clustered_test.py: CR2 sandwich + HTZ
reference).  The uncorrected test (CR1 sandwich, F(q, G - 1)) rejected the
true null in 31 of the 200 draws of one parameter at a nominal 5 % (outside
the band) and in 83 of 200 for three; the corrected one in 6 and 0."""

import numpy as np
from scipy.linalg import sqrtm

from robstiff_drake.identification.diagnosis.clustered_test import _eta, clustered_fit
from robstiff_drake.identification.diagnosis.cross_validation import clustered_wald

DRAWS = 200
LEVEL = 0.05
# two-sided binomial band for 200 draws at 5 % (99 %: 3..19 rejections); an exact test stays inside
BAND = (3, 19)


def _null_design(rng, poses, q, loads=3, p0=6):
    """A regression like a small campaign's: ``poses`` poses x ``loads`` loads x
    3 components, six columns and ``q`` tested ones (all zero), the columns'
    size varying from pose to pose (some poses carry more leverage), and the
    rows of a pose sharing one reference reading's noise."""
    n = poses * loads * 3
    g = np.repeat(np.arange(poses), loads * 3)
    pose_size = rng.normal(size=(poses, p0 + q)) * np.exp(rng.normal(size=(poses, 1)))
    X = np.repeat(pose_size, loads * 3, axis=0) * rng.normal(size=(n, p0 + q))
    y = rng.normal(size=n) + np.repeat(rng.normal(size=(poses, 3)), loads, axis=0).ravel()
    return X, y, g, slice(p0, p0 + q)


def _rejections(poses, q, seed):
    rng = np.random.default_rng(seed)
    hits = 0
    for _ in range(DRAWS):
        X, y, g, cols = _null_design(rng, poses, q)
        hits += clustered_wald(X, y, g, cols)[0] < LEVEL
    return hits


def test_one_parameter_at_ten_poses_is_calibrated():
    hits = _rejections(10, 1, seed=20261207)
    assert BAND[0] <= hits <= BAND[1], f"{hits}/{DRAWS} rejections of a true null at {LEVEL:g}"


def test_three_parameters_at_ten_poses_are_not_liberal():
    # HTZ is conservative here for several parameters on few clusters (0 of 200); it must never be liberal
    hits = _rejections(10, 3, seed=20261208)
    assert hits <= BAND[1], f"{hits}/{DRAWS} rejections of a true null at {LEVEL:g}"


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
