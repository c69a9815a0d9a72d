"""kernels.arrays.borrowed / borrow: the same arrays without reference counts.

The path tracer's parallel loop runs on borrowed scene arrays; they must be the very same memory
(shape, strides, values) as the owned ones, and the rendered image must not change."""
import numpy as np
from numba import njit

from gdlearn.integrators.path.pt import _rows_path, render_rows_path
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


def test_borrowed_scene_renders_the_same_image():
    from pathlib import Path
    root = Path(__file__).resolve().parents[1]
    sa = compile_scene(load(root / "scenes" / "cornell-box.xml", res=12, max_depth=4))
    assert _fields_equal(sa)
    img_a, img_b = np.zeros((12, 12, 3)), np.zeros((12, 12, 3))
    bad = np.zeros(12, dtype=np.int64)
    # the same kernel on owned arrays vs through the borrowing wrapper: bit-identical by construction
    _rows_path(sa, 3, 0, 2, 4, 5, ALL_MASK, 0.05, img_a, bad)
    render_rows_path(sa, 3, 0, 2, 4, 5, ALL_MASK, 0.05, img_b, bad)
    assert np.array_equal(img_a, img_b) and img_a.sum() > 0.0
