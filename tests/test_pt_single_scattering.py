"""Single scattering in a homogeneous medium against scipy quadrature (issue 2, "What it must show").

A camera ray along -z crosses a null-bounded medium cube [-1, 1]^3 lit by a point light inside it.
Light scattered once into the ray is the 1D integral (Jarosz et al. 2008, Eq. 1 with one scattering)

    L = int_{-1}^{1} exp(-sigma_t (1 - z)) sigma_s p(cos theta) I exp(-sigma_t r) / r^2 dz,

r = |x(z) - c|, theta the angle between the light's propagation direction (x - c)/r and the direction
to the camera (+z), p the Henyey-Greenstein phase function (forward peak for g > 0). The truth is
computed per channel by ``scipy.integrate.quad`` -- independent of every gdlearn kernel. The RGB
extinction differs per channel to exercise the spectral-MIS distance sampling.
"""
import math
import os
import sys

import numpy as np
import pytest
from scipy.integrate import quad

sys.path.insert(0, os.path.dirname(__file__))
from _pt_scenes import single_scatter_box  # noqa: E402

from gdlearn.integrators import make  # noqa: E402

#: 4.5 standard errors of the mean over independent passes (false alarm ~7e-6 per check)
K = 4.5
LIGHT = (0.3, 0.2, 0.1)


def truth(sigma_t, albedo, g, light=LIGHT):
    c = np.asarray(light)

    def hg(cos_t):
        return (1 - g * g) / (4 * math.pi * (1 + g * g - 2 * g * cos_t) ** 1.5)

    def integrand(z, s):
        v = np.array([0.0, 0.0, z]) - c
        r = np.linalg.norm(v)
        return math.exp(-s * (1 - z)) * s * albedo * hg(v[2] / r) * math.exp(-s * r) / (r * r)

    return np.array([quad(integrand, -1, 1, args=(s,), points=[c[2]], limit=200, epsabs=1e-12)[0]
                     for s in sigma_t])


def estimate(scene, passes=16, spp=4096, **kw):
    pt = make("pt", scene, seed=3, spp_per_pass=spp, **kw)
    pt.warmup()
    px = np.array([pt.render_pass(i).images["primal"][0, 0] for i in range(passes)])
    return px.mean(0), px.std(0, ddof=1) / math.sqrt(passes)


@pytest.mark.parametrize("g", [0.0, 0.6, -0.4])
def test_single_scattering_matches_quadrature(g):
    sigma_t, albedo = (0.5, 1.0, 2.0), 0.8
    m, se = estimate(single_scatter_box(sigma_t, albedo, g), effects="single-scattering")
    t = truth(sigma_t, albedo, g)
    assert np.all(np.abs(m - t) < K * se), (m, se, t)
    # power: the wrong sign of g (a classic convention bug) must be rejected
    if g != 0.0:
        assert np.any(np.abs(m - truth(sigma_t, albedo, -g)) > K * se)


def test_single_scattering_equals_max_depth_2():
    # Mitsuba's max_depth 2 keeps exactly the paths with one interior vertex: here single scattering
    sigma_t, albedo, g = (0.5, 1.0, 2.0), 0.8, 0.3
    a, sa = estimate(single_scatter_box(sigma_t, albedo, g, max_depth=2))
    t = truth(sigma_t, albedo, g)
    assert np.all(np.abs(a - t) < K * sa), (a, sa, t)
    # ... and the full transport (multiple scattering too) is measurably brighter
    b, sb = estimate(single_scatter_box(sigma_t, albedo, g))
    assert np.all(b - t > K * sb), (b, sb, t)
