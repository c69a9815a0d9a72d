"""Homogeneous-medium kernels (gdlearn.kernels.media.medium): distance sampling against the exponential
distribution (chi^2), unbiasedness of the spectral-MIS estimator against closed-form integrals, and
stability for thin (sigma t ~ 1e-8) and dense (sigma = 1e4) media."""
import math

import numpy as np
import pytest
from numba import njit
from scipy import stats

from gdlearn.kernels.media import medium as M
from test_kernels_helpers import chi2_pvalue

N = 100_000
ALPHA = 1e-3


@njit(cache=True)
def _single_many(sigma, t_max, u):
    t = np.empty(u.shape[0])
    sc = np.empty(u.shape[0], dtype=np.bool_)
    pdf = np.empty(u.shape[0])
    for i in range(u.shape[0]):
        t[i], sc[i], pdf[i] = M.sample_distance_1(sigma, t_max, u[i])
    return t, sc, pdf


@njit(cache=True)
def _rgb_many(sigma_t, albedo, t_max, u):
    t = np.empty(u.shape[0])
    sc = np.empty(u.shape[0], dtype=np.bool_)
    w = np.empty((u.shape[0], 3))
    for i in range(u.shape[0]):
        t[i], sc[i], ww = M.sample_distance(sigma_t, albedo, t_max, u[i, 0], u[i, 1])
        w[i, 0], w[i, 1], w[i, 2] = ww
    return t, sc, w


@njit(cache=True)
def _trunc_many(sigma, t_max, u):
    t = np.empty(u.shape[0])
    pdf = np.empty(u.shape[0])
    for i in range(u.shape[0]):
        t[i], pdf[i] = M.sample_distance_truncated_1(sigma, t_max, u[i])
    return t, pdf


def test_transmittance():
    assert M.transmittance((1.0, 0.5, 0.0), 2.0) == pytest.approx((math.exp(-2), math.exp(-1), 1.0))
    assert M.transmittance((1.0, 0.0, 1e4), math.inf) == (0.0, 1.0, 0.0)
    assert M.transmittance((1e-8, 1e-8, 1e-8), 1.0)[0] == pytest.approx(1 - 1e-8, rel=1e-15)


@pytest.mark.parametrize("sigma,t_max", [(2.0, 1.5), (0.3, 1.0), (50.0, 0.2)])
def test_single_channel_chi2(sigma, t_max):
    u = np.random.default_rng(int(sigma * 10)).random(N)
    t, sc, pdf = _single_many(sigma, t_max, u)
    edges = np.linspace(0, t_max, 31)
    obs = np.append(np.histogram(t[sc], bins=edges)[0], np.count_nonzero(~sc))
    ex = stats.expon(scale=1 / sigma)
    exp = np.append(np.diff(ex.cdf(edges)), ex.sf(t_max)) * N
    assert chi2_pvalue(obs, exp) > ALPHA
    assert np.allclose(pdf[sc], ex.pdf(t[sc]), rtol=1e-12)
    assert np.allclose(pdf[~sc], ex.sf(t_max), rtol=1e-12)
    assert np.all(t[~sc] == t_max)


def test_single_channel_wrong_sigma_fails():
    u = np.random.default_rng(1).random(N)
    t, sc, _ = _single_many(2.2, 1.5, u)          # 10% off
    edges = np.linspace(0, 1.5, 31)
    ex = stats.expon(scale=1 / 2.0)
    obs = np.append(np.histogram(t[sc], bins=edges)[0], np.count_nonzero(~sc))
    exp = np.append(np.diff(ex.cdf(edges)), ex.sf(1.5)) * N
    assert chi2_pvalue(obs, exp) < 1e-6


def test_spectral_mis_distance_distribution_chi2():
    """t follows the mixture (1/3) sum_c sigma_c exp(-sigma_c t) (a zero channel never collides)."""
    sig = (0.5, 2.0, 0.0)
    t_max = 3.0
    u = np.random.default_rng(2).random((N, 2))
    t, sc, _ = _rgb_many(sig, (0.8, 0.6, 0.9), t_max, u)
    edges = np.linspace(0, t_max, 31)
    cdf = lambda x: sum(stats.expon(scale=1 / s).cdf(x) if s > 0 else 0 * x for s in sig) / 3
    obs = np.append(np.histogram(t[sc], bins=edges)[0], np.count_nonzero(~sc))
    exp = np.append(np.diff(cdf(edges)), 1 - cdf(t_max)) * N
    assert chi2_pvalue(obs, exp) > ALPHA


@pytest.mark.parametrize("sig", [(0.5, 2.0, 0.0), (1.0, 1.0, 1.0), (0.0, 0.0, 0.0), (1e-8, 3.0, 1e4)])
def test_spectral_mis_unbiased(sig):
    """E[weight * f(t)] over collisions + E[weight] over passes equals, per channel,
    int_0^tmax sigma_s,c T_c(t) f(t) dt + T_c(tmax), with f(t) = 1 + t (closed form below).
    Tolerance: 4 standard errors of the sample mean (+1e-12 for zero-variance channels)."""
    alb = np.array([0.8, 0.6, 0.9])
    t_max = 2.0
    u = np.random.default_rng(3).random((400_000, 2))
    t, sc, w = _rgb_many(sig, tuple(alb), t_max, u)
    assert np.all(np.isfinite(w))
    f = np.where(sc, 1.0 + t, 1.0)[:, None] * w
    mean, se = f.mean(0), f.std(0) / np.sqrt(len(f))
    truth = []
    for c, s in enumerate(sig):
        if s == 0:
            truth.append(1.0)
            continue
        # int_0^T a s e^{-s t} (1 + t) dt, using -expm1 for the thin channel
        e = math.exp(-s * t_max)
        coll = alb[c] * (-math.expm1(-s * t_max) + (1 - e * (1 + s * t_max)) / s if s * t_max > 1e-4
                         else -math.expm1(-s * t_max) + s * t_max**2 / 2)
        truth.append(coll + e)
    assert np.all(np.abs(mean - truth) <= 4 * se + 1e-12), (mean, truth, se)
    if sig == (0.0, 0.0, 0.0):
        assert not sc.any() and np.all(w == 1.0)


def test_truncated_sampler_chi2_and_thin_media():
    for sigma, t_max in ((1.5, 2.0), (1e-8, 1.0), (1e4, 1.0)):
        u = np.random.default_rng(4).random(N)
        t, pdf = _trunc_many(sigma, t_max, u)
        assert np.all((t >= 0) & (t <= t_max)) and np.all(np.isfinite(pdf))
        ex = stats.expon(scale=1 / sigma)
        edges = np.linspace(0, t_max, 31) if sigma < 100 else np.linspace(0, 10 / sigma, 31)
        norm = ex.cdf(t_max)
        obs = np.histogram(t, bins=edges)[0]
        exp = np.diff(ex.cdf(edges)) / norm * N
        obs = np.append(obs, N - obs.sum())
        exp = np.append(exp, N - exp.sum())
        assert chi2_pvalue(obs, exp) > ALPHA
        assert np.allclose(pdf, ex.pdf(t) / norm, rtol=1e-6)


def test_thin_and_dense_media_accuracy():
    # P(collision) for sigma t = 1e-8: 1 - e^{-x} = x - x^2/2 to full precision via expm1
    x = 1e-8
    assert M.scatter_probability_1(1e-8, 1.0) == pytest.approx(x - x * x / 2, rel=1e-14)
    # dense: always collides within t_max, weight = albedo exactly for equal channels
    u = np.random.default_rng(5).random((1000, 2))
    t, sc, w = _rgb_many((1e4, 1e4, 1e4), (0.5, 0.6, 0.7), 1.0, u)
    assert sc.all() and np.allclose(w, [0.5, 0.6, 0.7], rtol=1e-12)
    # thin: passes, weight T/P = 1
    t, sc, w = _rgb_many((1e-8, 1e-8, 1e-8), (0.5, 0.6, 0.7), 1.0, u)
    assert np.all(np.isfinite(w)) and (~sc).all() and np.allclose(w, 1.0)
    # mixed dense / clear channels: finite, bounded weights
    t, sc, w = _rgb_many((1e4, 0.0, 1.0), (0.5, 0.6, 0.7), 5.0, u)
    assert np.all(np.isfinite(w)) and np.all(w >= 0) and np.all(w <= 3.0 + 1e-12)


def test_unbounded_segment():
    """A ray that leaves the scene inside a medium (t_max = inf): channels with sigma > 0 always
    collide; a clear channel passes with weight T / P = 1 / (1/3) in that channel only."""
    u = np.random.default_rng(6).random((3000, 2))
    t, sc, w = _rgb_many((1.0, 0.0, 2.0), (0.5, 0.5, 0.5), math.inf, u)
    assert np.all(np.isfinite(w))
    picked_clear = (np.minimum((u[:, 0] * 3).astype(int), 2) == 1)
    assert np.all(sc == ~picked_clear) and np.all(np.isfinite(t[sc]))
    np.testing.assert_allclose(w[~sc], np.tile([0.0, 3.0, 0.0], ((~sc).sum(), 1)))
    t, sc, w = _rgb_many((1.0, 1.0, 1.0), (0.5, 0.5, 0.5), math.inf, u)
    assert sc.all()


def test_neg_log1m_matches_log1p():
    """The free-flight inversion's -log(1 - u): within an ulp of -log1p(-u) on the renderer's grid
    k 2^-53 (tiny, middle and near-1 values), and exact for off-grid thin-medium values (the log1p
    fallback: log(1 - 1e-20) would be 0)."""
    k = np.concatenate([np.arange(1, 1000), np.random.default_rng(6).integers(0, 2**53, 20000),
                        2**53 - np.arange(1, 1000)])
    for u in k.astype(np.float64) * 2.0**-53:
        ref = -math.log1p(-u)
        assert abs(M.neg_log1m(u) - ref) <= 2.3e-16 * ref
    for u in (1e-20, 3e-17, 1e-300):
        assert M.neg_log1m(u) == -math.log1p(-u)
    assert math.copysign(1.0, M.neg_log1m(0.0)) == 1.0
