"""The path tracer's image is a pure function of (scene, seed, samples): identical for 1 and 2
threads, and an effects request of "direct" renders exactly Mitsuba's max_depth 2.

Both are exact (bitwise) comparisons: every random number is rand(seed, pixel, sample, dim), so
the thread schedule cannot change any sample, and a restricted effects mask must not change the
random numbers of the paths it keeps.
"""
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(__file__))
from _pt_scenes import cornell_box  # noqa: E402

from gdlearn.integrators import make, render  # noqa: E402
from gdlearn.scene.model import Medium, rgb  # noqa: E402


def _img(scene, **kw):
    return render(make("pt", scene, seed=5, spp_per_pass=2, **kw), spp=4).primal


def test_one_and_two_threads_give_identical_images():
    for scene in (cornell_box(res=20), cornell_box(res=20, integrator="volpath",
                                                   medium=Medium(sigma_t=rgb(0.3), albedo=rgb(0.8)))):
        a = _img(scene, threads=1)
        b = _img(scene, threads=2)
        assert a.std() > 0 and np.array_equal(a, b)


def test_effects_direct_equals_max_depth_2():
    full = _img(cornell_box(res=20, max_depth=8), effects="direct")
    md2 = _img(cornell_box(res=20, max_depth=2))
    assert md2.mean() > 0 and np.array_equal(full, md2)
    # and it is not the full image: indirect light is missing
    assert _img(cornell_box(res=20, max_depth=8)).mean() > 1.2 * md2.mean()


def test_effects_direct_plus_single_scattering_equals_max_depth_2_in_fog():
    fog = Medium(sigma_t=rgb(0.3), albedo=rgb(0.8), phase="hg", g=0.3)
    a = _img(cornell_box(res=16, max_depth=8, integrator="volpath", medium=fog),
             effects="direct,single-scattering")
    b = _img(cornell_box(res=16, max_depth=2, integrator="volpath", medium=fog))
    assert b.mean() > 0 and np.array_equal(a, b)


def test_effect_classes_partition_the_image():
    # the classes are disjoint and cover every path: their images sum to the full image (up to
    # floating-point summation order, 1e-12 relative)
    scene = cornell_box(res=12, max_depth=5)
    parts = sum(_img(scene, effects=e) for e in ("emission", "direct-lighting", "diffuse-interreflection"))
    full = _img(scene)
    np.testing.assert_allclose(parts, full, rtol=1e-12, atol=1e-12)
