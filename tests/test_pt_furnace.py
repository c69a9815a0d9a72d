"""Furnace tests of the path tracer: closed spheres whose exact radiance is known in closed form.

A camera inside a closed sphere of diffuse albedo rho whose inside emits Le sees L = Le / (1 - rho)
in every direction (the Neumann series Le sum rho^k). Filling the sphere with a conservative medium
(albedo 1) changes nothing (the medium only redirects light in an isotropic radiance field), and
with black walls L = Le exactly. Every estimate is checked within K standard errors, where the
standard error comes from the spread of independent passes; the tests also show they can fail by
rejecting a slightly wrong albedo.
"""
import sys
import os

import numpy as np
import pytest

sys.path.insert(0, os.path.dirname(__file__))
from _pt_scenes import furnace  # noqa: E402

from gdlearn.integrators import make  # noqa: E402
from gdlearn.scene.model import Medium, rgb  # noqa: E402

#: 4.5 standard errors: a false alarm has probability ~7e-6 per check under a normal approximation
#: (the pass means average 64 pixels x spp samples, so the normal approximation is good)
K = 4.5


def _estimate(scene, passes=16, spp=8, **kw):
    """(mean, standard error) of the image mean over independent passes."""
    pt = make("pt", scene, seed=7, spp_per_pass=spp, **kw)
    pt.warmup()
    means = np.array([pt.render_pass(i).images["primal"].mean() for i in range(passes)])
    return means.mean(), means.std(ddof=1) / np.sqrt(passes)


def test_diffuse_furnace_matches_neumann_series():
    rho, le = 0.6, 0.5
    m, se = _estimate(furnace(rho, le))
    truth = le / (1 - rho)
    assert abs(m - truth) < K * se, (m, se, truth)
    # the test has power: a 3% error in the albedo (rho = 0.618) would be caught
    wrong = le / (1 - 0.618)
    assert abs(m - wrong) > K * se, (m, se, wrong)


def test_furnace_bounded_depth_is_the_truncated_series():
    # max_depth d keeps the first d terms: Le (1 + rho + ... + rho^(d-1)). No Russian roulette acts
    # before depth 5, and in a uniformly bright sphere both MIS strategies estimate each bounce almost
    # exactly (their per-sample spread is ~1e-7, from the sphere's curvature in the solid-angle pdf),
    # so 1e-5 relative is a tight check that still cannot fail by chance.
    rho, le = 0.5, 1.0
    for d in (1, 2, 3):
        m, se = _estimate(furnace(rho, le, max_depth=d), passes=2, spp=2)
        assert m == pytest.approx(le * sum(rho ** k for k in range(d)), rel=1e-5)


@pytest.mark.parametrize("rho, g", [(0.0, 0.0), (0.5, 0.7)])
def test_medium_furnace_conservative_medium_changes_nothing(rho, g):
    le = 0.8
    med = Medium(sigma_t=rgb(0.7, 1.5, 3.0), albedo=rgb(1.0), phase="hg" if g else "isotropic", g=g)
    m, se = _estimate(furnace(rho, le, medium=med), spp=32)
    truth = le / (1 - rho)
    assert abs(m - truth) < K * se, (m, se, truth)
    # an albedo of 0.9 loses ~10% per scattering event (a few per path here); the test must see it
    med_lossy = Medium(sigma_t=rgb(0.7, 1.5, 3.0), albedo=rgb(0.9), phase="hg" if g else "isotropic", g=g)
    m2, se2 = _estimate(furnace(rho, le, medium=med_lossy), spp=32)
    assert m - m2 > K * np.hypot(se, se2), (m, m2, se, se2)
