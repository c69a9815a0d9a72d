"""Image files: EXR and npy round-trip exactly (float32 / float64), PNG within its 8-bit sRGB
quantisation, an unknown extension is refused with the fix."""
import numpy as np
import pytest

from gdlearn.io import read_image, tonemap, write_image
from gdlearn.io.tonemap import srgb_decode, srgb_encode


def _img():
    rng = np.random.default_rng(0)
    return rng.uniform(0, 1, (5, 7, 3)) ** 2


def test_npy_and_exr_round_trip(tmp_path):
    a = _img()
    write_image(tmp_path / "a.npy", a)
    assert np.array_equal(read_image(tmp_path / "a.npy"), a)
    write_image(tmp_path / "sub" / "a.exr", a)          # folders are created
    b = read_image(tmp_path / "sub" / "a.exr")
    assert b.shape == a.shape and np.array_equal(b, a.astype(np.float32))


def test_png_is_srgb_within_quantisation(tmp_path):
    a = _img()
    write_image(tmp_path / "a.png", a)
    b = read_image(tmp_path / "a.png")
    # one 8-bit step in sRGB space is at most 1/255; the decode slope is <= 2.4 * 1.055 / 1.055
    assert np.max(np.abs(srgb_encode(b) - srgb_encode(a))) <= 0.5 / 255 + 1e-9
    assert np.max(np.abs(b - a)) < 2.5 / 255


def test_tonemap_clamps_and_kills_nonfinite():
    t = tonemap(np.array([[[2.0, -1.0, np.nan]]]))
    assert t.tolist() == [[[255, 0, 0]]]
    x = np.linspace(0, 1, 101)
    assert np.allclose(srgb_decode(srgb_encode(x)), x, atol=1e-12)
    assert srgb_encode(np.array([0.5]))[0] == pytest.approx(0.735356983, abs=1e-8)   # the sRGB standard


def test_unknown_extension_names_the_fix(tmp_path):
    with pytest.raises(ValueError, match="fix: use one of .exr, .png, .npy"):
        write_image(tmp_path / "a.jpg", _img())
