"""k-NN and variable-kernel photon radii (gdlearn.photons.radii; Jarosz et al. 2008, Sec. 4)
against a brute-force distance matrix."""
import math

import numpy as np
import pytest

from gdlearn.photons import radii as R


def _kth(pos, k):
    d = np.sqrt(((pos[:, None, :] - pos[None, :, :]) ** 2).sum(-1))
    np.fill_diagonal(d, np.inf)
    return np.sort(d, axis=1)[:, min(k, len(pos) - 1) - 1]


@pytest.fixture
def cloud():
    rng = np.random.default_rng(4)
    return np.concatenate([rng.normal(0, 0.1, (250, 3)), rng.uniform(-1, 1, (250, 3))])


def test_knn_equals_brute_force(cloud):
    for k in (1, 7, 32):
        np.testing.assert_allclose(R.knn_distance(cloud, k), _kth(cloud, k), rtol=1e-12, atol=0)
        np.testing.assert_allclose(R.knn_radii(cloud, k), _kth(cloud, k), rtol=1e-12, atol=0)


def test_variable_radii_take_the_cube_root(cloud):
    n = 400
    m = round(math.sqrt(n))             # the default pilot rank, 20
    r = R.variable_radii(cloud, n)
    np.testing.assert_allclose(r, _kth(cloud, m) * (n / m) ** (1 / 3), rtol=1e-12, atol=0)
    np.testing.assert_allclose(R.variable_radii(cloud, n, m=7), _kth(cloud, 7) * (n / 7) ** (1 / 3), rtol=1e-12)


def test_few_photons_and_duplicates():
    pos = np.array([[0.0, 0, 0], [1.0, 0, 0], [1.0, 0, 0]])
    np.testing.assert_allclose(R.knn_distance(pos, 5), [1.0, 1.0, 1.0])     # fewer than k others: the farthest
    r = R.knn_radii(pos, 1)                                                    # duplicates: distance 0, clamped
    assert r[0] == 1.0 and 0 < r[1] < 1e-8 and r[1] == r[2]
    assert np.isinf(R.knn_distance(pos[:1], 3)).all()


def test_errors_name_the_argument():
    with pytest.raises(ValueError, match="pos"):
        R.knn_radii(np.zeros((4, 2)), 3)
    with pytest.raises(ValueError, match="n_neighbors"):
        R.variable_radii(np.zeros((4, 3)), 0)
    with pytest.raises(ValueError, match="non-finite"):
        R.knn_radii(np.array([[0, 0, np.nan]]), 1)
