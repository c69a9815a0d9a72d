"""SPPM and memoryless PPM on shipped scenes: consistency with pt, determinism, effects, refusals."""
import math
from pathlib import Path

import numba
import numpy as np
import pytest

import gdlearn.scene
from gdlearn.integrators import make
from gdlearn.integrators.base import render

ROOT = Path(__file__).resolve().parent.parent
#: every class the photons carry; the emitters seen directly are compared apart (their pixels are
#: noisy at 2 camera samples per pass and would dominate an image mean)
NO_EMISSION = ["direct-lighting", "diffuse-interreflection", "glossy", "specular", "caustics"]


def _scene(name, res):
    return gdlearn.scene.load(str(ROOT / "scenes" / name), res=res)


@pytest.fixture(scope="module")
def cornell_pt():
    # pt at 2048 spp: the image mean's relative standard error is ~0.1 % (measured: two seeds at
    # 4096 spp differ by 0.04 %); pt itself is checked against Mitsuba in test_mitsuba_crosscheck
    return render(make("pt", _scene("cornell-box.xml", 16), seed=2, spp_per_pass=512, effects=NO_EMISSION),
                  spp=2048).primal


@pytest.mark.parametrize("name,direct", [("sppm", "photons"), ("ppm", "photons"), ("ppm", "nee")])
def test_converges_to_pt_on_the_cornell_box(name, direct, cornell_pt):
    """20 passes x 100k light paths at 16 x 16 with radius 0.25 x pixel footprint. The blur bias
    scales with r^2 (measured on this scene after 20 passes: +0.9 % at scale 1, +0.37 % at 0.5,
    +0.03 % at 0.25); the noise of the image mean is ~0.2 %. So 1.5 % on the image mean and 6 % on
    each 4 x 4 block (corners and edges carry the largest blur bias) -- the test of the 1-2 % bias
    target. A 3 % error in the photon normalisation or a lost light bounce fails it. ``ppm`` with
    ``direct="nee"`` too (sppm's is checked against Mitsuba 3 in test_sppm_mitsuba.py)."""
    sc = _scene("cornell-box.xml", 16)
    f = render(make(name, sc, seed=1, photons_per_pass=100_000, effects=NO_EMISSION, radius_scale=0.25,
                    direct=direct), passes=20)
    rel = f.primal.mean() / cornell_pt.mean() - 1
    assert abs(rel) < 0.015, rel
    blocks = lambda im: im.mean(-1).reshape(4, 4, 4, 4).mean(axis=(1, 3))   # noqa: E731
    rb = blocks(f.primal) / blocks(cornell_pt) - 1
    assert np.abs(rb).max() < 0.06, rb
    assert f.photons == 20 * 100_000 and f.stats["nonfinite_samples"] == 0
    assert {"photons", "build", "gather", "update"} <= set(f.timings)


def test_emission_seen_directly_and_through_specular_chains_is_exact():
    """effects=emission traces no photon (the plan bounds light paths to zero vertices) and adds the
    emitters the gather paths see: pt's emission image within 4 standard errors per channel sum."""
    sc = _scene("cornell-box.xml", 8)
    f = render(make("sppm", sc, seed=3, photons_per_pass=2, effects=["emission"]), passes=80)
    assert f.stats["photons_stored"] == 0
    g = render(make("pt", sc, seed=4, spp_per_pass=600, effects=["emission"]), spp=600)
    # the sum's standard error from the halves (independent pixels); 2 % more for pt's own noise
    se = math.sqrt(f.variance().sum())
    diff = f.primal.sum() - g.primal.sum()
    assert abs(diff) < 4 * se + 0.02 * g.primal.sum(), (diff, se)


def test_same_image_for_one_and_two_threads():
    sc = _scene("cornell-box.xml", 8)
    imgs = []
    for t in (1, min(2, numba.config.NUMBA_NUM_THREADS)):
        f = render(make("sppm", sc, seed=5, photons_per_pass=6000, threads=t), passes=3)
        imgs.append((f.primal, f.state["radius"], f.halves["primal"][0]))
    for a, b in zip(*imgs):
        assert np.array_equal(a, b)


def test_effects_partition_the_image_and_prune_the_light_paths():
    """Caustics plus every other class is the full image, term for term (the random numbers are
    keyed, so each request traces a subset of the same paths); a caustics-only request traces fewer
    light vertices (paths whose first bounce is not specular stop there), a direct-only request
    stores photons at the first bounce only."""
    sc = _scene("caustics-box.xml", 8)
    kw = dict(seed=6, photons_per_pass=20_000, radius_scale=2.0)
    full = render(make("sppm", sc, **kw), passes=1)
    caus = render(make("sppm", sc, effects=["caustics"], **kw), passes=1)
    rest = render(make("sppm", sc, effects=["emission", "direct-lighting", "diffuse-interreflection", "glossy",
                                             "specular"], **kw), passes=1)
    np.testing.assert_allclose(caus.primal + rest.primal, full.primal, rtol=1e-9, atol=1e-12)
    assert caus.primal.sum() > 0 and caus.stats["light_vertices"] < 0.5 * full.stats["light_vertices"]
    direct = render(make("sppm", sc, effects=["direct"], **kw), passes=1)
    assert direct.stats["light_vertices"] <= 2 * 20_000


def test_parent_subsets_partition_the_image_and_the_specular_one_is_the_first_bounce_caustic():
    """parent="specular" plus parent="non-specular" is the whole photon image, term for term; and
    with paths of at most 3 segments the only photon with a specular parent is the caustic
    L S D (E), so the specular subset must equal the pathclass machinery's "caustics" class (an
    independent classification: the light path's lobe history, not the parent test)."""
    sc = _scene("caustics-box.xml", 8)
    kw = dict(seed=6, photons_per_pass=20_000, radius_scale=2.0, effects=NO_EMISSION)
    img = {p: render(make("sppm", sc, parent=p, **kw), passes=1).primal for p in ("any", "specular", "non-specular")}
    np.testing.assert_allclose(img["specular"] + img["non-specular"], img["any"], rtol=1e-9, atol=1e-12)
    assert img["specular"].sum() > 0.02 * img["any"].sum()
    spec3 = render(make("sppm", sc, parent="specular", max_depth=3, **kw), passes=1).primal
    caus3 = render(make("sppm", sc, max_depth=3, **{**kw, "effects": ["caustics"]}), passes=1).primal
    assert caus3.sum() > 0
    np.testing.assert_allclose(spec3, caus3, rtol=1e-9, atol=1e-12)
    with pytest.raises(ValueError, match="non-specular"):
        make("sppm", sc, parent="mirror")


def test_scenes_with_media_are_refused_naming_the_volumetric_estimators():
    with pytest.raises(ValueError, match="vpm"):
        make("sppm", _scene("fog-box.xml", 8))
    with pytest.raises(ValueError, match="media"):
        make("ppm", _scene("fog-box.xml", 8))


def test_bad_parameters_are_refused():
    sc = _scene("cornell-box.xml", 8)
    with pytest.raises(ValueError, match="alpha"):
        make("sppm", sc, alpha=0.0)
    with pytest.raises(ValueError, match="radius"):
        make("sppm", sc, radius=-1.0)
    with pytest.raises(ValueError, match="photons, nee"):
        make("ppm", sc, direct="light")


def test_sppm_converges_to_pt_through_glass_and_mirror():
    """The caustics box (a glass and a mirror sphere): camera chains through specular vertices,
    light paths refracting in and out of the glass. Measured at 16 x 16 after 20 passes: -0.28 %
    against pt at 4096 spp (two pt seeds differ by 0.29 %); 1.5 % as on the Cornell box."""
    sc = _scene("caustics-box.xml", 16)
    g = render(make("pt", sc, seed=2, spp_per_pass=512, effects=NO_EMISSION), spp=2048)
    f = render(make("sppm", sc, seed=1, photons_per_pass=100_000, effects=NO_EMISSION, radius_scale=0.25),
               passes=20)
    rel = f.primal.mean() / g.primal.mean() - 1
    assert abs(rel) < 0.015, rel
