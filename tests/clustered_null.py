"""The synthetic regression on which the pose-clustered test's size is
measured (tests/test_clustered_test.py, studies/clustered_test_choice.py):
a true null, 10 poses, fixed seeds."""

import numpy as np

from robstiff_drake.identification.diagnosis.cross_validation import clustered_wald

DRAWS = 200
LEVEL = 0.05
SEEDS = {1: 20261207, 3: 20261208}  # tested parameters q -> seed of the 200 draws


def null_design(rng, poses, q, loads=3, p0=6):
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


def rejections(poses, q, seed, test=None):
    """Rejections of the true null at LEVEL in DRAWS draws; ``test(X, y, g,
    cols)`` -> p (default: the diagnosis's clustered_wald)."""
    test = test or (lambda X, y, g, cols: clustered_wald(X, y, g, cols)[0])
    rng = np.random.default_rng(seed)
    hits = 0
    for _ in range(DRAWS):
        X, y, g, cols = null_design(rng, poses, q)
        hits += test(X, y, g, cols) < LEVEL
    return hits
