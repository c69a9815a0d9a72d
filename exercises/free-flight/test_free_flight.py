"""Tests of the exercise "free-flight". Each docstring is the line `gdlearn check` prints.

The references are hand values, gdlearn's compiled kernels on the same random numbers, the
exponential law (chi^2 with scipy) and closed-form integrals.
"""
import math

import numpy as np
from scipy import stats

from gdlearn.kernels.media import medium as M
from gdlearn.teaching.exercises import load_target

ex = load_target("free-flight")


def test_hand_values():
    """free_flight: a collision at t = ln 2 / sigma for u = 1/2, and a pass beyond t_max"""
    t, sc, pdf = ex.free_flight(2.0, 1.0, 0.5)
    assert sc is True or sc == True, f"sigma 2, t_max 1, u 0.5: t = ln2/2 = 0.347 < 1 is a collision, got scattered={sc}"  # noqa: E712
    assert math.isclose(t, math.log(2) / 2, rel_tol=1e-12), f"sigma 2, u 0.5: expected t = ln 2 / 2 = 0.3466, got {t}"
    assert math.isclose(pdf, 1.0, rel_tol=1e-12), f"pdf at t = ln2/2 is sigma exp(-sigma t) = 2 * 0.5 = 1, got {pdf}"
    t, sc, pdf = ex.free_flight(2.0, 1.0, 0.9)
    assert not sc and t == 1.0, f"u 0.9 gives t = 1.15 > t_max = 1: expected (1.0, False, ...), got ({t}, {sc})"
    assert math.isclose(pdf, math.exp(-2.0), rel_tol=1e-12), \
        f"a pass has the probability T(t_max) = exp(-2) = 0.1353, got {pdf}"
    assert ex.free_flight(0.0, 3.0, 0.7) == (3.0, False, 1.0), "sigma 0: always passes, with probability 1"


def test_matches_gdlearn_single_channel():
    """free_flight: the same (t, scattered, pdf) as gdlearn's sample_distance_1 on 2000 random numbers"""
    rng = np.random.default_rng(1)
    for sigma, t_max in ((0.7, 2.0), (5.0, 0.3), (1e-3, 10.0)):
        for u in rng.random(2000 // 3):
            mine, ref = ex.free_flight(sigma, t_max, u), M.sample_distance_1(sigma, t_max, u)
            assert bool(mine[1]) == bool(ref[1]) and math.isclose(mine[0], ref[0], rel_tol=1e-12) \
                and math.isclose(mine[2], ref[2], rel_tol=1e-12), \
                f"sigma {sigma}, t_max {t_max}, u {u:.6f}: got {mine}, gdlearn gives {ref}"


def test_distribution_chi2():
    """free_flight: the distances follow sigma exp(-sigma t), and P(pass) = exp(-sigma t_max) (chi^2)"""
    sigma, t_max, n = 1.3, 1.5, 40000
    u = np.random.default_rng(2).random(n)
    out = [ex.free_flight(sigma, t_max, x) for x in u]
    t = np.array([o[0] for o in out])
    sc = np.array([bool(o[1]) for o in out])
    edges = np.linspace(0, t_max, 21)
    law = stats.expon(scale=1 / sigma)
    obs = np.append(np.histogram(t[sc], bins=edges)[0], np.count_nonzero(~sc))
    exp = np.append(np.diff(law.cdf(edges)), law.sf(t_max)) * n
    p = stats.chisquare(obs, exp).pvalue
    assert p > 1e-3, f"the histogram of t does not follow the exponential law (chi^2 p-value {p:.1e}); " \
                     f"check t = -log(1 - u) / sigma"


def test_thin_medium_precision():
    """free_flight: sigma t ~ 1e-8 keeps full precision (log1p, not log(1 - u))"""
    u = 1e-10
    t, sc, pdf = ex.free_flight(1e-8, 1.0, u)
    exact = -math.log1p(-u) / 1e-8          # 1.00000000005e-2
    assert math.isclose(t, exact, rel_tol=1e-13), \
        f"sigma 1e-8, u 1e-10: expected t = {exact!r}, got {t!r}; -log(1 - u) rounds 1 - u first"


def test_dense_medium_finite():
    """free_flight: sigma = 1e4 gives finite distances of mean 1e-4 and finite densities"""
    u = np.random.default_rng(3).random(5000)
    out = [ex.free_flight(1e4, 1.0, x) for x in u]
    t = np.array([o[0] for o in out]); pdf = np.array([o[2] for o in out])
    assert np.all(np.isfinite(t)) and np.all(np.isfinite(pdf)) and all(bool(o[1]) for o in out), \
        "sigma 1e4 over t_max 1: every sample collides, with finite t and pdf"
    assert abs(t.mean() - 1e-4) < 4 * t.std() / math.sqrt(len(t)), f"mean distance {t.mean():.3e}, expected 1e-4"


def test_matches_gdlearn_spectral():
    """spectral_free_flight: the same (t, scattered, weights) as gdlearn's sample_distance"""
    rng = np.random.default_rng(4)
    for sig in ((0.5, 2.0, 0.0), (1.0, 1.0, 1.0), (0.2, 0.9, 3.0), (0.0, 0.0, 0.0)):
        alb = (0.8, 0.6, 0.9)
        for uc, u in rng.random((600, 2)):
            mine = ex.spectral_free_flight(sig, alb, 1.7, uc, u)
            ref = M.sample_distance(sig, alb, 1.7, uc, u)
            ok = (bool(mine[1]) == bool(ref[1]) and math.isclose(mine[0], ref[0], rel_tol=1e-12)
                  and np.allclose(mine[2], ref[2], rtol=1e-12, atol=0))
            assert ok, f"sigma_t {sig}, u_channel {uc:.4f}, u {u:.4f}: got {mine}, gdlearn gives {ref}"


def test_spectral_unbiased():
    """spectral_free_flight: E[weight (1 + t)] per channel equals int sigma_s T (1 + t) dt + T(t_max)"""
    sig, alb, t_max, n = (0.4, 1.5, 0.0), (0.8, 0.6, 0.9), 2.0, 60000
    u = np.random.default_rng(5).random((n, 2))
    vals = np.array([np.asarray(w) * ((1.0 + t) if sc else 1.0)
                     for t, sc, w in (ex.spectral_free_flight(sig, alb, t_max, a, b) for a, b in u)])
    mean, se = vals.mean(0), vals.std(0) / math.sqrt(n)
    truth = []
    for a, s in zip(alb, sig):
        e = math.exp(-s * t_max)
        truth.append(1.0 if s == 0 else a * ((1 - e) + (1 - e * (1 + s * t_max)) / s) + e)
    for c in range(3):
        assert abs(mean[c] - truth[c]) <= 4 * se[c] + 1e-12, \
            f"channel {c}: estimate {mean[c]:.4f} +- {se[c]:.4f}, exact {truth[c]:.4f} (is pdf the mixture over all three channels?)"
