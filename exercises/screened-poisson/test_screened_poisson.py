"""Tests of the exercise "screened-poisson". Each docstring is the line `gdlearn check` prints.

References: exact gradients of a known image (computed here with numpy), gdlearn's DCT solver
``poisson_l2`` (lam = alpha^2 in its convention), and the energy of perturbed images. All randomness
is seeded.
"""
import math

import numpy as np
import pytest

from gdlearn.teaching.exercises import load_target
from gdlearn.reconstruct import forward_differences, poisson_l2

ex = load_target("screened-poisson")


def problem(seed, h=9, w=12, noise=0.3):
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:h, 0:w]
    truth = 1.0 + np.sin(xx / 3.0) + 0.2 * yy + (xx > w // 2)
    gx, gy = forward_differences(truth)
    return (truth, truth + noise * rng.normal(size=truth.shape),
            gx + 0.05 * rng.normal(size=gx.shape), gy + 0.05 * rng.normal(size=gy.shape))


def test_energy_hand_values():
    """energy: Eq. 18 for a 2 x 2 image by hand, L2 and L1, with the undefined entries ignored"""
    img = np.array([[1.0, 2.0], [3.0, 5.0]])
    primal = np.array([[1.0, 1.0], [3.0, 3.0]])
    gx = np.array([[0.0, 99.0], [1.0, -99.0]])       # defined: gx[:, 0] -> residuals 1 and 1
    gy = np.array([[2.0, 1.0], [99.0, 99.0]])        # defined: gy[0, :] -> residuals 0 and 2
    got = ex.energy(img, primal, gx, gy, 0.5, 2)
    assert math.isclose(got, 0.5 * (1 + 4) + (1 + 1) + (0 + 4), rel_tol=1e-12), f"L2: expected 8.5, got {got}"
    got = ex.energy(img, primal, gx, gy, 0.5, 1)
    assert math.isclose(got, 0.5 * (1 + 2) + (1 + 1) + (0 + 2), rel_tol=1e-12), f"L1: expected 5.5, got {got}"


@pytest.mark.parametrize("lam", [0.04, 1.0])
def test_exact_gradients_give_the_true_image(lam):
    """reconstruct_l2: exact gradients and an exact primal give back the true image, for any lambda"""
    truth, _, _, _ = problem(0)
    gx, gy = forward_differences(truth)
    got = ex.reconstruct_l2(truth, gx, gy, lam)
    assert np.shape(got) == truth.shape, f"expected an image of shape {truth.shape}, got {np.shape(got)}"
    assert np.allclose(got, truth, atol=1e-9), f"max deviation {np.max(np.abs(got - truth)):.2e}"


@pytest.mark.parametrize("seed", range(3))
def test_agrees_with_gdlearns_dct_solver(seed):
    """reconstruct_l2: the same image as gdlearn's poisson_l2 (alpha = 0.2, i.e. lambda = 0.04) on noisy data"""
    _, primal, gx, gy = problem(seed)
    got = ex.reconstruct_l2(primal, gx, gy, 0.04)
    want = poisson_l2(primal, gx, gy, alpha=0.2).image
    assert np.allclose(got, want, atol=1e-7), (
        f"max difference to poisson_l2 {np.max(np.abs(got - want)):.2e}; is lambda alpha^2, and are "
        "the last column of gx and the last row of gy ignored?")


def test_undefined_entries_are_ignored():
    """reconstruct_l2: the last column of gx and the last row of gy do not change the result"""
    _, primal, gx, gy = problem(1)
    a = ex.reconstruct_l2(primal, gx, gy, 0.1)
    gx2, gy2 = gx.copy(), gy.copy()
    gx2[:, -1] = 1e6
    gy2[-1, :] = -1e6
    b = ex.reconstruct_l2(primal, gx2, gy2, 0.1)
    assert np.allclose(a, b, atol=1e-9), "the undefined gradient entries changed the image"


def test_minimises_the_l2_energy():
    """reconstruct_l2: its energy (your energy(), n = 2) is below that of randomly perturbed images"""
    _, primal, gx, gy = problem(2)
    best = ex.reconstruct_l2(primal, gx, gy, 0.04)
    e0 = ex.energy(best, primal, gx, gy, 0.04, 2)
    rng = np.random.default_rng(3)
    for _ in range(20):
        e = ex.energy(best + 1e-3 * rng.normal(size=best.shape), primal, gx, gy, 0.04, 2)
        assert e >= e0, f"a perturbed image has lower energy ({e:.6g} < {e0:.6g}): not the minimiser"


def test_huge_lambda_returns_the_primal():
    """reconstruct_l2: with a huge lambda the primal term wins and the result is the primal image"""
    _, primal, gx, gy = problem(4)
    got = ex.reconstruct_l2(primal, gx, gy, 1e9)
    assert np.allclose(got, primal, atol=1e-6), f"max deviation from the primal {np.max(np.abs(got - primal)):.2e}"
