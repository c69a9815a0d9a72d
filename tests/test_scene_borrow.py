"""kernels.arrays.borrowed / borrow: the same arrays without reference counts.

The path tracer's row drivers run on borrowed scene arrays; they must be the very same memory
(shape, strides, values) as the owned ones, and the radiance must not change."""
import numpy as np
from numba import njit

from gdlearn.integrators.path.pt import render_rows_path
from gdlearn.integrators.path.surface import radiance_path
from gdlearn.kernels.accel.bvh import STACK_SIZE
from gdlearn.kernels.camera import camera_ray
from gdlearn.kernels.rng import rand
from gdlearn.kernels.pathclass import ALL_MASK
from gdlearn.kernels.arrays import borrow
from gdlearn.kernels.arrays import borrowed
from gdlearn.scene.compile import compile_scene
from gdlearn.scene.load import load


@njit(cache=True)
def _write_through(a):
    b = borrow(a)
    b[1, 2] = 7.0
    return b.shape[0], b.shape[1], b.strides[0], b[0, 0]


def test_borrow_is_the_same_memory():
    a = np.arange(12.0).reshape(3, 4)
    n0, n1, s0, v = _write_through(a)
    assert (n0, n1, s0, v) == (3, 4, 32, 0.0)
    assert a[1, 2] == 7.0          # written through the borrowed view: same data pointer


@njit(cache=True)
def _fields_equal(sa):
    sb = borrowed(sa)
    return (sb.prims.ctypes.data == sa.prims.ctypes.data and sb.nodes.shape == sa.nodes.shape
            and sb.em_cdf.ctypes.data == sa.em_cdf.ctypes.data and sb.env == sa.env
            and sb.camera_medium == sa.camera_medium)


@njit(cache=True)
def _image_owned(sa, seed, spp, out):
    """pt's image on the *owned* arrays, one thread, pixel by pixel in pt's sample order."""
    stack = np.empty(STACK_SIZE, dtype=np.int32)
    h, w = out.shape[0], out.shape[1]
    for y in range(h):
        for x in range(w):
            key = y * w + x
            a = np.zeros(3)
            for s in range(spp):
                o, d, tmax = camera_ray(sa.camera, x + rand(seed, key, s, 0), y + rand(seed, key, s, 1))
                c = radiance_path(sa, o, d, tmax, seed, key, s, 4, 5, ALL_MASK, 0.05, stack)
                for k in range(3):
                    a[k] += c[k]
            for k in range(3):
                out[y, x, k] = a[k] * (1.0 / spp)


def test_borrowed_scene_renders_the_same_image():
    from pathlib import Path
    root = Path(__file__).resolve().parents[1]
    sa = compile_scene(load(root / "scenes" / "cornell-box.xml", res=12, max_depth=4))
    assert _fields_equal(sa)
    # the row driver borrows the arrays itself and runs on two threads; the owned arrays, one thread
    img_a, img_b = np.zeros((12, 12, 3)), np.zeros((12, 12, 3))
    bad = np.zeros(12, dtype=np.int64)
    _image_owned(sa, 3, 2, img_a)
    render_rows_path(sa, 3, 0, 2, 4, 5, ALL_MASK, 0.05, img_b, bad)
    assert np.array_equal(img_a, img_b) and img_a.sum() > 0.0 and bad.sum() == 0
