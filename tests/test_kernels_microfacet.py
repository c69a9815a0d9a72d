"""Microfacet and Fresnel building blocks against independent references (scipy, textbook formulas)."""
import math

import numpy as np
import pytest
from scipy import integrate, special

from gdlearn.kernels.bsdf.dispatch import fresnel as FR
from gdlearn.kernels.bsdf.dispatch import microfacet as MF
from gdlearn.kernels.layout import BECKMANN, GGX


def test_erfinv_matches_scipy():
    x = np.concatenate([np.linspace(-0.999999, 0.999999, 2001), [1e-300, -1e-12, 1 - 1e-15]])
    ours = np.array([MF.erfinv(v) for v in x])
    np.testing.assert_allclose(ours, special.erfinv(x), rtol=1e-13, atol=1e-300)
    assert MF.erfinv(1.0) == math.inf and MF.erfinv(-1.0) == -math.inf


@pytest.mark.parametrize("dist", [BECKMANN, GGX])
@pytest.mark.parametrize("alpha", [0.05, 0.3, 1.0])
def test_D_projected_area_is_one(dist, alpha):
    """int D(m) cos(theta_m) dw = 1 (Walter et al. 2007, Eq. 4)."""
    f = lambda c: 2 * np.pi * MF.mf_D(dist, alpha, (math.sqrt(max(0, 1 - c * c)), 0.0, c)) * c
    tot = integrate.quad(f, 0, 1, points=[1 - alpha**2, 1 - 0.1 * alpha**2], limit=500, epsrel=1e-10)[0]
    assert tot == pytest.approx(1.0, rel=1e-7)


def smith_g1_exact(dist, alpha, cos_t):
    """Smith G1 for normal-aligned m: GGX (Walter Eq. 34), Beckmann (Walter Eq. 27, with erf)."""
    tan_t = math.sqrt(1 - cos_t**2) / cos_t
    a = 1 / (alpha * tan_t)
    if dist == GGX:
        return 2 / (1 + math.sqrt(1 + 1 / a**2))
    lam = (math.erf(a) - 1) / 2 + math.exp(-a * a) / (2 * a * math.sqrt(math.pi))
    return 1 / (1 + lam)


@pytest.mark.parametrize("dist,rtol", [(GGX, 1e-12), (BECKMANN, 3.5e-3)])
def test_G1_against_smith(dist, rtol):
    """GGX is exact; Mitsuba's Beckmann G1 is a rational fit with < 0.35% relative error."""
    for alpha in (0.1, 0.5):
        for c in (0.05, 0.3, 0.7, 0.99):
            v = (math.sqrt(1 - c * c), 0.0, c)
            assert MF.mf_G1(dist, alpha, v, (0.0, 0.0, 1.0)) == pytest.approx(
                smith_g1_exact(dist, alpha, c), rel=rtol)


@pytest.mark.parametrize("dist,tol", [(GGX, 1e-6), (BECKMANN, 4e-3)])
@pytest.mark.parametrize("cos_i", [0.95, 0.5, 0.1])
def test_visible_normal_pdf_normalised(dist, tol, cos_i):
    """int G1(wi, m) max(0, wi.m) D(m) / cos_i dm = 1 (Heitz 2014, Eq. 2) -- exact for GGX, within
    the rational-fit error for Beckmann."""
    wi = (math.sqrt(1 - cos_i**2), 0.0, cos_i)
    alpha = 0.4

    def f(phi, c):
        s = math.sqrt(max(0.0, 1 - c * c))
        return MF.mf_pdf(dist, alpha, wi, (s * math.cos(phi), s * math.sin(phi), c))
    tot = integrate.dblquad(f, 0, 1, 0, 2 * np.pi, epsabs=1e-9, epsrel=1e-8)[0]
    assert tot == pytest.approx(1.0, abs=tol)


def fresnel_textbook(cos_i, n1, n2):
    s_t = n1 / n2 * math.sqrt(1 - cos_i**2)
    if s_t >= 1:
        return 1.0
    c_t = math.sqrt(1 - s_t**2)
    rs = (n1 * cos_i - n2 * c_t) / (n1 * cos_i + n2 * c_t)
    rp = (n2 * cos_i - n1 * c_t) / (n2 * cos_i + n1 * c_t)
    return 0.5 * (rs * rs + rp * rp)


def test_fresnel_dielectric_both_sides_and_tir():
    eta = 1.5
    for c in np.linspace(-1, 1, 41):
        F, cos_t, eta_it, eta_ti = FR.fresnel_dielectric(c, eta)
        n1, n2 = (1.0, eta) if c >= 0 else (eta, 1.0)
        assert F == pytest.approx(fresnel_textbook(abs(c), n1, n2), abs=1e-14)
        assert eta_it == pytest.approx(n2 / n1) and eta_ti == pytest.approx(n1 / n2)
        if F < 1:
            assert np.sign(cos_t) == -np.sign(c) or c == 0
            assert (1 - cos_t**2) * n2**2 == pytest.approx((1 - c * c) * n1**2, abs=1e-12)
    assert FR.fresnel_dielectric(0.3, 1.0)[0] == 0.0
    assert FR.fresnel_dielectric(0.0, 1.5)[0] == 1.0


@pytest.mark.parametrize("eta", [1 / 1.5, 1.33, 1.5, 2.0])
def test_fresnel_diffuse_reflectance_fit(eta):
    """F_dr = 2 int_0^1 F(mu) mu dmu; Mitsuba's fits are within 0.6% for eta in [1/2, 2]."""
    exact = 2 * integrate.quad(lambda m: fresnel_textbook(m, 1.0, eta) * m, 0, 1, limit=200)[0]
    assert FR.fresnel_diffuse_reflectance(eta) == pytest.approx(exact, rel=6e-3)


def test_refraction_helpers_are_consistent():
    rng = np.random.default_rng(0)
    for _ in range(100):
        m = rng.normal(size=3)
        m[2] = abs(m[2])
        m /= np.linalg.norm(m)
        wi = rng.normal(size=3)
        wi /= np.linalg.norm(wi)
        F, cos_t, eta_it, eta_ti = FR.fresnel_dielectric(float(wi @ m), 1.5)
        r = np.array(FR.reflect_m(tuple(wi), tuple(m)))
        assert r @ m == pytest.approx(wi @ m) and np.linalg.norm(r) == pytest.approx(1.0)
        if F < 1:
            t = np.array(FR.refract_m(tuple(wi), tuple(m), cos_t, eta_ti))
            assert np.linalg.norm(t) == pytest.approx(1.0)
            assert t @ m == pytest.approx(cos_t)            # on the other side of the microfacet
            # Snell: tangential components scale by eta_ti
            np.testing.assert_allclose(t - (t @ m) * m, -eta_ti * (wi - (wi @ m) * m), atol=1e-12)
