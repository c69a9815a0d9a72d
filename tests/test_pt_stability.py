"""Hard cases stay finite and bounded (ARCHITECTURE.md, "Tests that can fail": the stability catalogue).

Each case renders a few samples per pixel and checks: no sample was dropped as non-finite, every
pixel is finite and non-negative, and the image is bounded by a physical upper limit of the scene
(so an exploding weight cannot hide behind "finite"); the Cornell box image mean is ~0.25 at
max_depth 8, so a mean above 2 means some weight blew up.
"""
import os
import sys

import numpy as np
import pytest

sys.path.insert(0, os.path.dirname(__file__))
from _pt_scenes import cornell_box, furnace, lookat  # noqa: E402

from gdlearn.integrators import make, render  # noqa: E402
from gdlearn.scene.model import BSDF, Medium, Shape, rgb  # noqa: E402

from _pt_scenes import scale, translate, chain  # noqa: E402


def _check(scene, bound, spp=8, **kw):
    f = render(make("pt", scene, seed=11, spp_per_pass=spp // 2, **kw), spp=spp)
    img = f.primal
    assert f.stats.get("nonfinite_samples", 0) == 0 and f.stats.get("nonfinite_pixels", 0) == 0
    assert np.all(np.isfinite(img)) and img.min() >= 0.0
    assert img.mean() <= bound, (img.mean(), bound)
    return img


def test_grazing_rays_and_rays_along_triangle_edges():
    # camera in the floor's plane, looking along the floor's diagonal edge (the shared edge of its two
    # triangles): rays graze the floor and run along the edge
    sc = cornell_box(res=16)
    sc.sensor.to_world = lookat((-1.5, -1.0, -1.5), (1.0, -1.0, 1.0), (0, 1, 0))
    sc.sensor.fov = 30.0
    _check(sc, bound=2.0)
    # looking exactly along a wall's plane from inside the room
    sc.sensor.to_world = lookat((-1.0, 0.0, 0.9), (-1.0, 0.0, -1.0), (0, 1, 0))
    _check(sc, bound=2.0)


@pytest.mark.parametrize("sigma", [1e-8, 1e4])
def test_thin_and_dense_media(sigma):
    # a furnace with absorbing-scattering fog: the radiance can never exceed le / (1 - rho)
    rho, le = 0.5, 1.0
    med = Medium(sigma_t=rgb(sigma), albedo=rgb(0.5))
    img = _check(furnace(rho, le, medium=med, res=6), bound=le / (1 - rho) * 1.05, spp=16)
    if sigma == 1e-8:      # the medium is invisible: the plain furnace value (8 standard errors slack)
        assert abs(img.mean() - 2.0) < 0.1


@pytest.mark.parametrize("g", [0.999, -0.999])
def test_extreme_hg_anisotropy(g):
    med = Medium(sigma_t=rgb(1.0, 2.0, 4.0), albedo=rgb(0.9), phase="hg", g=g)
    _check(cornell_box(res=12, integrator="volpath", medium=med), bound=2.0)


@pytest.mark.parametrize("bsdf", ["roughconductor", "roughdielectric", "roughplastic"])
def test_nearly_specular_microfacets(bsdf):
    sc = cornell_box(res=16)
    sc.shapes.append(Shape("sphere", chain(scale(0.3), translate(0.2, -0.6, 0.2)),
                           BSDF(bsdf, alpha=1e-4, distribution="ggx")))
    _check(sc, bound=2.0)
