"""Best-fit rotations: the Kabsch rotation of numpy's SVD, proper, also for rank-deficient and
reflected covariances."""

import numpy as np

from skin_detach_addon.core.proxy_solve.rotations import best_rotations


def kabsch(covariance):
    u, _, vt = np.linalg.svd(covariance)
    fix = np.ones((covariance.shape[0], 3))
    fix[:, 2] = np.sign(np.linalg.det(u @ vt))
    return (u * fix[:, None, :]) @ vt


def test_matches_the_svd_rotation_and_is_proper():
    rng = np.random.default_rng(3)
    covariance = rng.normal(size=(400, 3, 3))
    covariance[:50, :, 2] = 0.0                                 # rank two
    covariance[50:100] = covariance[50:100] @ np.diag([1.0, 1.0, -1.0])  # reflected
    covariance[100:150] = np.eye(3) + 1e-9 * rng.normal(size=(50, 3, 3))  # almost the identity
    rotations = best_rotations(covariance)
    assert np.abs(rotations - kabsch(covariance)).max() <= 1e-10
    assert np.abs(np.linalg.det(rotations) - 1.0).max() <= 1e-12
    assert np.abs(np.einsum("nki,nkj->nij", rotations, rotations) - np.eye(3)).max() <= 1e-12


def test_recovers_a_known_rotation_and_survives_degenerate_input():
    rng = np.random.default_rng(4)
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    q *= np.sign(np.linalg.det(q))
    rest = rng.normal(size=(5, 3))
    covariance = ((rest @ q.T)[:, :, None] * rest[:, None, :]).sum(axis=0)[None]
    assert np.allclose(best_rotations(covariance)[0], q, atol=1e-12)
    zero = best_rotations(np.zeros((2, 3, 3)))
    rank_one = best_rotations(np.outer([1.0, 2.0, 3.0], [0.0, 1.0, 1.0])[None])
    for rotation in np.concatenate([zero, rank_one]):
        assert np.isfinite(rotation).all() and abs(np.linalg.det(rotation) - 1.0) <= 1e-12


def test_warm_started_rotations_equal_cold_ones():
    from skin_detach_addon.core.proxy_solve.rotations import WarmRotations
    rng = np.random.default_rng(5)
    covariance = rng.normal(size=(300, 3, 3))
    warm = WarmRotations()
    first = warm(covariance)
    nearby = covariance + 1e-3 * rng.normal(size=covariance.shape)
    assert np.abs(first - best_rotations(covariance)).max() <= 1e-12
    assert np.abs(warm(nearby) - best_rotations(nearby)).max() <= 1e-10
    assert np.abs(warm(covariance[:10]) - best_rotations(covariance[:10])).max() <= 1e-12  # other size: cold
