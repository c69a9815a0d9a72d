"""The perspective camera against Mitsuba 3's own sensor (its sample_ray for the same film
positions), for every fov_axis and a non-square film, and camera_raster as the exact inverse.
Mitsuba computes in float32, hence the 1e-5 tolerance."""
import math

import numpy as np
import pytest

from gdlearn.kernels.camera import camera_ray, camera_raster, camera_row


def _lookat(o, t, up):
    o, t, up = (np.asarray(v, float) for v in (o, t, up))
    d = (t - o) / np.linalg.norm(t - o)
    left = np.cross(up, d)
    left /= np.linalg.norm(left)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = left, np.cross(d, left), d, o
    return m


TW = _lookat((1, 2, 3), (0, 0.3, 0), (0.1, 1, 0))
FILM = [(0.1, 0.2), (0.9, 0.3), (0.5, 0.5), (0.2, 0.95), (0.0, 0.0)]


@pytest.mark.mitsuba
@pytest.mark.parametrize("axis", ["x", "y", "diagonal", "smaller", "larger"])
@pytest.mark.parametrize("size", [(64, 32), (30, 50)])
def test_rays_match_mitsuba(axis, size):
    mi = pytest.importorskip("mitsuba")
    mi.set_variant("scalar_rgb")
    w, h = size
    sensor = mi.load_dict({"type": "perspective", "fov": 40.0, "fov_axis": axis,
                           "to_world": mi.ScalarTransform4f(TW.tolist()),
                           "film": {"type": "hdrfilm", "width": w, "height": h}})
    cam = camera_row(TW, 40.0, axis, w, h)
    for fx, fy in FILM:
        ray, _ = sensor.sample_ray(0.0, 0.5, mi.Point2f(fx, fy), mi.Point2f(0.5, 0.5))
        o, d, tmax = camera_ray(cam, fx * w, fy * h)
        assert np.allclose(np.array(ray.d), d, atol=1e-5) and np.allclose(np.array(ray.o), o, atol=1e-5)


def test_film_orientation_left_is_plus_x_of_the_lookat_frame():
    # Mitsuba: the image's left edge looks towards the camera's +x ("left") axis, its top towards +y
    cam = camera_row(np.eye(4), 60.0, "x", 40, 20)
    _, d_left, _ = camera_ray(cam, 0.0, 10.0)
    _, d_top, _ = camera_ray(cam, 20.0, 0.0)
    assert d_left[0] > 0 and abs(d_left[1]) < 1e-12
    assert d_top[1] > 0 and abs(d_top[0]) < 1e-12
    assert d_left[0] / d_left[2] == pytest.approx(math.tan(math.radians(30)))


def test_raster_inverts_ray():
    cam = camera_row(TW, 35.0, "smaller", 48, 27)
    rng = np.random.default_rng(0)
    for _ in range(200):
        fx, fy = rng.uniform(0, 48), rng.uniform(0, 27)
        o, d, _ = camera_ray(cam, fx, fy)
        p = tuple(np.array(o) + rng.uniform(0.1, 50) * np.array(d))
        ok, x, y = camera_raster(cam, p)
        assert ok and x == pytest.approx(fx, abs=1e-9) and y == pytest.approx(fy, abs=1e-9)
    ok, _, _ = camera_raster(cam, tuple(np.array(o) - 3 * np.array(d)))     # behind the camera
    assert not ok
