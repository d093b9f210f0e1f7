"""cell/preview_table.scale_gains (the force scales' Kalman gains along the
table, the rows below the force threshold skipped at once) against the
row-by-row loop it replaced: the same numbers bit for bit."""

import numpy as np

from robstiff_drake.cell.preview_table import (MIN_GROUP_FORCE_N, N_FORCE_GROUPS, NOISE_N, SCALE_SIGMA,
                                               SCALE_WALK_PER_S, scale_gains)


def reference(replica, period_s):
    n = len(replica)
    P = np.eye(N_FORCE_GROUPS) * SCALE_SIGMA ** 2
    Q = np.eye(N_FORCE_GROUPS) * SCALE_WALK_PER_S ** 2 * period_s
    R = np.eye(3) * NOISE_N ** 2
    K = np.zeros((n, N_FORCE_GROUPS, 3))
    Phi = np.zeros((n, 3, N_FORCE_GROUPS))
    for k in range(1, n):
        F = replica[k - 1, :N_FORCE_GROUPS, :3].T
        Phi[k] = F
        if np.max(np.abs(F)) <= MIN_GROUP_FORCE_N:
            continue
        P = P + Q
        K[k] = P @ F.T @ np.linalg.inv(F @ P @ F.T + R)
        P = (np.eye(N_FORCE_GROUPS) - K[k] @ F) @ P
    return K, Phi


def test_the_gains_are_the_row_by_row_loops():
    rng = np.random.default_rng(7)
    replica = rng.normal(size=(3000, 4, 6)) * 80.0
    replica[400:900] *= 1e-3  # out of the cut: below the threshold, no update
    replica[1500:1510, :, :3] = MIN_GROUP_FORCE_N  # exactly at it: no update either
    K, Phi = scale_gains(replica, 0.004)
    K0, Phi0 = reference(replica, 0.004)
    assert np.array_equal(K, K0) and np.array_equal(Phi, Phi0)
    assert not K[0].any() and not K[500].any() and not K[1505].any() and K[2000].any()
