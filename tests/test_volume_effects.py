"""The effects plan splits vpm's and bre's images exactly: a partition of the light-transport classes
renders, class set by class set with the same seed, images that add up to the full image.

The light paths and camera paths are the same in every render (random numbers are per path and
vertex); only which merged paths count differs, so the sum equals the full image to rounding. A
plan that stored too few photons for a class (surface photons after a medium vertex, L M D E, are
multiple scattering) loses that light and breaks the sum.
"""
import numpy as np
import pytest

import gdlearn.scene
from gdlearn.crosscheck import store
from gdlearn.integrators import make, render

SURFACE_AND_SINGLE = ["emission", "direct-lighting", "diffuse-interreflection", "glossy", "specular", "caustics",
                      "single-scattering"]
MEDIUM_REST = ["multiple-scattering", "volume-caustics"]


@pytest.mark.parametrize("name,opts", [("vpm", {}), ("bre", {"kernel": "3d"}), ("bre", {"kernel": "2d"})])
def test_class_partition_adds_up_to_the_full_image(name, opts):
    sc = gdlearn.scene.load(str(store.ROOT / "scenes" / "fog-box.xml"), res=12)
    full, a, b = (render(make(name, sc, seed=4, photons_per_pass=20_000, effects=e, **opts), passes=2).primal
                  for e in (None, SURFACE_AND_SINGLE, MEDIUM_REST))
    assert b.mean() > 0.05 * full.mean()          # the fog box's multiple scattering is not negligible
    np.testing.assert_allclose(a + b, full, rtol=1e-9, atol=1e-12)
