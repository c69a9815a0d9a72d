"""``make("pt", transport="media")``: light transport ending in the medium, the unbiased reference of
the volumetric photon estimators' ``transport="media"`` (kernels.pathclass, "The camera's end").

* The split is a partition: with the same seed, the media image and its complement
  (``transport="surfaces"``) add up to the full image, to rounding (random numbers are per path and
  vertex, so the three renders trace the same paths and only which contributions count differs).
* It is the quantity vpm computes: vpm with ``transport="media"`` at a small fixed radius agrees
  with it, an independent estimator (light paths and a kernel against camera paths).
"""
import numpy as np
import pytest

import gdlearn.scene
from gdlearn.crosscheck import store
from gdlearn.integrators import make, render

SCENES = store.ROOT / "scenes"


def _scene(name, res):
    return gdlearn.scene.load(str(SCENES / name), res=res)


@pytest.mark.parametrize("name", ["fog-box.xml", "volume-caustic.xml"])
def test_media_and_surfaces_add_up_to_the_full_image(name):
    sc = _scene(name, 10)
    full, media, rest = (render(make("pt", sc, seed=3, transport=t), spp=32).primal
                         for t in ("all", "media", "surfaces"))
    # both parts carry light: the split is not trivially one of them
    assert media.mean() > 0.02 * full.mean() and rest.mean() > 0.02 * full.mean()   # thin fog: ~4 % of the caustic scene
    np.testing.assert_allclose(media + rest, full, rtol=1e-9, atol=1e-12)


def test_media_transport_sees_no_emission_and_no_surface_light():
    """The light seen directly, and the floor and walls lit from outside the block, are surface
    transport: pixels whose camera ray never enters the fog block are exactly zero."""
    sc = _scene("spot-medium.xml", 16)
    img = render(make("pt", sc, seed=0, transport="media"), spp=16).primal
    assert img.min() >= 0 and img.max() > 0
    assert (img.max(-1) == 0).mean() > 0.2        # the block covers only part of the image


def test_a_scene_without_media_is_refused():
    with pytest.raises(ValueError, match="no medium"):
        make("pt", _scene("cornell-box.xml", 8), transport="media")
    with pytest.raises(ValueError, match="choose one of"):
        make("pt", _scene("fog-box.xml", 8), transport="medium")


def _vpm_bias(sc, reference, scale):
    """vpm's image mean (transport media, radius ``scale`` x the default, fixed: alpha 1) over two
    seeds, relative to ``reference``, minus one."""
    means = [render(make("vpm", sc, seed=seed, transport="media", photons_per_pass=100_000,
                         volume_radius_scale=scale, alpha=1.0), passes=48).primal.mean() for seed in (20, 21)]
    return float(np.mean(means)) / reference - 1


def test_vpm_converges_to_pt_in_the_medium():
    """vpm (transport media) against pt (transport media): its bias falls with the radius, towards 0.

    The spot medium's cone enters the block through its top face, where a ball straddling the face
    finds photons on one side only: a bias linear in r (measured: -2.9 % at 0.7 x the default
    radius, -1.8 % at 0.35, -0.5 % at 0.15). The test asks the bias to fall by a quarter at least
    from 0.7 to 0.35 and its linear extrapolation to r = 0, 2 b(r/2) - b(r), to be under 1.5 % (its
    noise: ~0.35 %, two seeds of 48 passes; pt's mean, 4096 spp, ~0.1 %). A path class counted by one
    estimator and not the other (surface-first paths kept, the medium's multiple scattering dropped)
    moves the limit by more."""
    sc = _scene("spot-medium.xml", 16)
    pt = render(make("pt", sc, seed=1, transport="media"), spp=4096).primal.mean()
    b_r, b_half = _vpm_bias(sc, pt, 0.7), _vpm_bias(sc, pt, 0.35)
    assert abs(b_half) < 0.75 * abs(b_r), (b_r, b_half)
    assert abs(2 * b_half - b_r) < 0.015, (b_r, b_half)


def test_the_cli_renders_pt_media_transport(tmp_path):
    import os
    import subprocess
    import sys

    root = str(store.ROOT)
    env = dict(os.environ, PYTHONPATH=root + os.pathsep + os.environ.get("PYTHONPATH", ""))
    out = tmp_path / "a.npy"
    r = subprocess.run([sys.executable, "-m", "gdlearn", "render", str(SCENES / "spot-medium.xml"), "--integrator",
                        "pt", "--transport", "media", "--spp", "8", "--seed", "5", "--set", "res=8", "--out", str(out),
                        "--no-progress"], cwd=root, capture_output=True, text=True, timeout=900, env=env)
    assert r.returncode == 0, r.stderr
    want = render(make("pt", _scene("spot-medium.xml", 8), seed=5, transport="media"), spp=8).primal
    np.testing.assert_array_equal(np.load(out), want.astype(np.load(out).dtype))
