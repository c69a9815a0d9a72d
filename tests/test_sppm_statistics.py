"""SPPM's per-pixel statistics: the density form (what gdlearn stores) equals the tau / (pi R^2 N)
form of Hachisuka & Jensen 2009 over 20 passes on a synthetic photon stream (PHOTONS.md, T6)."""
import math

import numpy as np

from gdlearn.integrators.photon.sppm import accumulate_density, ppm_radius2_factor, reduce_radius


def _tau_form(M, Phi, r0, alpha, n_emitted, rescale=True):
    """Hachisuka et al. 2008's updates (PHOTONS.md Sec. 1.4), written independently: tau is
    rescaled by R'^2 / R^2."""
    N = np.zeros(M.shape[1:])
    R = np.full(M.shape[1:], r0)
    tau = np.zeros(M.shape[1:])
    out = []
    for i in range(M.shape[0]):
        Nn = N + alpha * M[i]
        Rn = np.where(N + M[i] > 0, R * np.sqrt(Nn / np.where(N + M[i] > 0, N + M[i], 1)), R)
        tau = (tau + Phi[i]) * ((Rn / R) ** 2 if rescale else 1.0)
        N, R = Nn, Rn
        out.append(tau / (math.pi * R ** 2 * n_emitted * (i + 1)))
    return out


def _density_form(M, Phi, r0, alpha, n_emitted):
    N = np.zeros(M.shape[1:])
    r2 = np.full(M.shape[1:], r0 ** 2)
    D = np.zeros(M.shape[1:])
    out = []
    for i in range(M.shape[0]):
        accumulate_density(D, Phi[i], r2)
        N, r2 = reduce_radius(N, r2, M[i], alpha)
        out.append(D / (n_emitted * (i + 1)))
    return out


def _stream(seed=0, passes=20, pixels=64):
    rng = np.random.default_rng(seed)
    M = rng.poisson(rng.uniform(0, 30, pixels), size=(passes, pixels)).astype(float)
    M[:, :3] = 0.0                           # pixels that never find a photon
    Phi = M * rng.gamma(2.0, 0.5, size=(passes, pixels))
    return M, Phi


def test_density_and_tau_forms_agree_over_20_passes():
    M, Phi = _stream()
    a = _tau_form(M, Phi, 0.05, 0.7, 1000)
    b = _density_form(M, Phi, 0.05, 0.7, 1000)
    for i, (x, y) in enumerate(zip(a, b)):
        # the forms are equal algebraically; they differ by rounding only (different operation order)
        np.testing.assert_allclose(x, y, rtol=1e-12, atol=0, err_msg=f"pass {i}")


def test_the_comparison_detects_a_missing_tau_rescale():
    M, Phi = _stream()
    a = _tau_form(M, Phi, 0.05, 0.7, 1000, rescale=False)
    b = _density_form(M, Phi, 0.05, 0.7, 1000)
    assert not np.allclose(a[-1], b[-1], rtol=1e-3)


def test_radius_reduction_and_schedule():
    # alpha = 1 keeps the radius (progression off); otherwise R^2 shrinks by (N + a M) / (N + M)
    N, r2 = reduce_radius(np.array([0.0, 10.0]), np.array([1.0, 1.0]), np.array([10.0, 10.0]), 1.0)
    np.testing.assert_array_equal(r2, [1.0, 1.0])
    N, r2 = reduce_radius(np.array([0.0, 10.0]), np.array([1.0, 1.0]), np.array([10.0, 0.0]), 0.7)
    np.testing.assert_allclose(r2, [0.7, 1.0]) and np.testing.assert_allclose(N, [7.0, 10.0])
    # Knaus & Zwicker 2011: r_{i+1}^2 = r_i^2 (i + alpha) / (i + 1)
    assert ppm_radius2_factor(0, 0.7) == 1.0
    assert math.isclose(ppm_radius2_factor(2, 0.7), (1.7 / 2) * (2.7 / 3))
