"""Tests of the exercise "cosine-hemisphere". Each docstring is the line `gdlearn check` prints.

They test properties, not one particular mapping: any correct cosine-weighted warp passes. All
randomness is seeded, so a result never changes between runs.
"""
import math

import numpy as np
import pytest
from scipy import integrate, stats

from gdlearn.teaching.exercises import load_target

ex = load_target("cosine-hemisphere")

N = 20_000        # directions for the distribution tests
# KS tests at level 1e-3: a correct warp fails with probability 0.1 % per (fixed) seed; a warp with
# the wrong law (e.g. uniform hemisphere: z^2 has density 1/(2 sqrt(t)) instead of 1) is rejected
# with p ~ 1e-100 at N = 20000, so the threshold separates them by a wide margin.
KS_LEVEL = 1e-3


def _directions(n=N, seed=7):
    u = np.random.default_rng(seed).random((n, 2))
    return np.array([ex.square_to_cosine_hemisphere(float(a), float(b)) for a, b in u])


def test_unit_vectors_in_upper_hemisphere():
    """square_to_cosine_hemisphere returns unit vectors with z >= 0"""
    w = _directions(2000)
    assert w.shape == (2000, 3), f"expected 3-tuples (x, y, z), got an array of shape {w.shape[1:]} per sample"
    length = np.linalg.norm(w, axis=1)
    worst = int(np.argmax(abs(length - 1)))
    # 1e-9: float64 round-off of sqrt/cos/sin is ~1e-16; anything larger is a wrong formula.
    assert abs(length[worst] - 1) < 1e-9, f"direction {w[worst]} has length {length[worst]:.6f}, not 1"
    assert w[:, 2].min() >= 0.0, f"direction {w[np.argmin(w[:, 2])]} points below the horizon (z < 0)"


def test_cos_theta_follows_the_cosine_law():
    """cos(theta) of the samples has the cosine law: P(cos theta <= c) = c^2"""
    z = _directions()[:, 2]
    p = stats.kstest(z ** 2, "uniform").pvalue
    assert p > KS_LEVEL, (f"the distribution of cos(theta) is wrong (KS p = {p:.2g}; mean cos(theta) = "
                          f"{z.mean():.3f}, expected 2/3 for cosine-weighted, 1/2 for uniform)")


def test_azimuth_is_uniform():
    """the azimuth phi of the samples is uniform on [0, 2 pi)"""
    w = _directions()
    phi = np.mod(np.arctan2(w[:, 1], w[:, 0]), 2 * math.pi) / (2 * math.pi)
    p = stats.kstest(phi, "uniform").pvalue
    assert p > KS_LEVEL, f"the azimuth is not uniform around the normal (KS p = {p:.2g})"


def test_pdf_is_cos_theta_over_pi():
    """cosine_hemisphere_pdf(w) = cos(theta) / pi above the horizon and 0 below"""
    for w in [(0.0, 0.0, 1.0), (0.6, 0.0, 0.8), (0.0, -0.8, 0.6)]:
        got = ex.cosine_hemisphere_pdf(w)
        assert got == pytest.approx(w[2] / math.pi, rel=1e-12), f"pdf{w} = {got}, expected {w[2] / math.pi}"
    below = ex.cosine_hemisphere_pdf((0.0, 0.6, -0.8))
    assert below == 0.0, f"pdf of a direction below the horizon must be 0, got {below}"


def test_pdf_integrates_to_one():
    """the pdf integrates to 1 over the sphere of directions"""
    def integrand(theta, phi):
        w = (math.sin(theta) * math.cos(phi), math.sin(theta) * math.sin(phi), math.cos(theta))
        return ex.cosine_hemisphere_pdf(w) * math.sin(theta)      # dw = sin(theta) dtheta dphi

    total, _ = integrate.dblquad(integrand, 0.0, 2 * math.pi, 0.0, math.pi, epsabs=1e-10)
    # 1e-6: adaptive quadrature of a smooth integrand with a kink at the horizon is good to ~1e-8.
    assert total == pytest.approx(1.0, abs=1e-6), f"the pdf integrates to {total:.6f} over the sphere, not 1"


def test_constant_sky_gives_pi_without_noise():
    """a constant sky L = 1 gives E = pi exactly, for every seed (zero variance)"""
    for seed in (1, 2, 3):
        e = ex.irradiance_estimate(lambda w: 1.0, 64, seed)
        # 1e-9 relative: every sample contributes exactly pi up to round-off in cos/pdf.
        assert e == pytest.approx(math.pi, rel=1e-9), (
            f"seed {seed}: E = {e:.6f}, expected pi = 3.141593 with no noise at all: with p = cos/pi each "
            "sample's L cos(theta) / p is exactly pi L")


def test_estimator_is_unbiased():
    """the estimator is unbiased: its mean over 40 seeds matches E = 3 pi / 2 for L = 1 + cos^2(theta)"""
    truth = 1.5 * math.pi              # int (1 + cos^2) cos dw = pi + 2 pi / 4, computed by hand
    estimates = np.array([ex.irradiance_estimate(lambda w: 1.0 + w[2] ** 2, 500, seed) for seed in range(40)])
    mean = estimates.mean()
    se = estimates.std(ddof=1) / math.sqrt(len(estimates))
    assert se > 0, "all 40 seeds gave the same estimate: are you using the seed / n?"
    # 4 standard errors: a correct estimator fails with probability ~6e-5.
    assert abs(mean - truth) < 4 * se, (
        f"mean over 40 seeds = {mean:.4f} +- {se:.4f}, but E = {truth:.4f}: the estimator is biased "
        "(check that you divide by the pdf, and by n)")


def test_estimator_is_reproducible():
    """the same seed gives the same estimate"""
    sky = lambda w: 1.0 + w[0]      # noqa: E731 - a tilted sky, so the estimate is noisy
    a, b = ex.irradiance_estimate(sky, 100, 5), ex.irradiance_estimate(sky, 100, 5)
    assert a == b, f"two runs with seed 5 gave {a} and {b}: draw the samples from default_rng(seed)"
