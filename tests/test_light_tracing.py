"""``make("lt", scene)``: light tracing into the medium, the kernel-free reference of the volumetric
photon estimators' ``transport="media"`` image where the camera sees the medium directly.

Two independent unbiased estimators of the same quantity must agree: pt with
``transport="media"`` (camera paths, tests/test_pt_media_transport.py) and lt (light paths connected
to the camera). The scene is the spot medium with its phase function made forward-scattering
(g = 0.6), so the phase function's direction convention, the camera's cos^3 and 1/t^2, and the
camera segment's transmittance each change the image by far more than the tolerance.
"""
import numpy as np
import pytest

import gdlearn.scene
from gdlearn.crosscheck import store
from gdlearn.integrators import make, render
from gdlearn.integrators.photon.light_tracing import specular_view_mask

SCENES = store.ROOT / "scenes"


def _spot(res, g=0.6):
    sc = gdlearn.scene.load(str(SCENES / "spot-medium.xml"), res=res)
    sc.media[0].phase, sc.media[0].g = "hg", g
    return sc


def _blocks(img, k=8):
    """Means of k x k blocks of the grey image: less noise per value than a pixel."""
    h, w = img.shape[:2]
    return img.mean(-1).reshape(k, h // k, k, w // k).mean(axis=(1, 3))


def test_light_tracing_agrees_with_the_path_tracer():
    """Image means within 1 % and the means of 2 x 2 pixel blocks (those above a tenth of the
    brightest) within 8 %: pt at 16384 spp (16 x 16) gives a block to 0.4-2 % (one standard error,
    over 4 seeds; the blocks where the cone enters are the noisy ones) and the image mean to ~0.2 %;
    lt at 32 passes of 100k light paths a block to 0.2-1 %; so 8 % is ~3.5 combined standard
    errors of the noisiest block. Dropping the cos^3, flipping the phase function's direction or
    leaving out the transmittance moves the mean or blocks by 10 % or more."""
    sc = _spot(16)
    pt = render(make("pt", sc, seed=1, transport="media"), spp=16384).primal
    lt = render(make("lt", sc, seed=2, photons_per_pass=100_000), passes=32).primal
    assert abs(lt.mean() / pt.mean() - 1) < 0.01, lt.mean() / pt.mean()
    bp, bl = _blocks(pt), _blocks(lt)
    lit = bp > 0.1 * bp.max()
    assert lit.sum() >= 12
    np.testing.assert_allclose(bl[lit], bp[lit], rtol=0.08)


def test_a_scene_without_media_is_refused():
    with pytest.raises(ValueError, match="no"):
        make("lt", gdlearn.scene.load(str(SCENES / "cornell-box.xml"), res=8))


def test_the_specular_view_mask_finds_the_glass_sphere():
    """The volume caustic's lens is seen by the camera: its pixels (and only pixels near its disc)
    are marked; the spot medium has no specular surface."""
    sc = gdlearn.scene.load(str(SCENES / "volume-caustic.xml"), res=32)
    integ = make("lt", sc, photons_per_pass=1000)
    m = specular_view_mask(integ.setup.sa, 32, 32)
    assert 10 < m.sum() < 0.1 * m.size
    ys, xs = np.nonzero(m)
    assert xs.max() - xs.min() < 12 and ys.max() - ys.min() < 12      # one compact disc
    assert not specular_view_mask(make("lt", _spot(8), photons_per_pass=1000).setup.sa, 8, 8).any()
