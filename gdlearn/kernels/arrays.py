"""The compiled scene every kernel reads: :class:`SceneArrays`, and :func:`borrowed` for threads.

``SceneArrays`` is a NamedTuple of contiguous arrays (numba passes it as a struct of array views:
no per-call cost inside compiled code); :func:`gdlearn.scene.compile.compile_scene` fills it, and
the row layouts live beside the kernels that read them (``geometry`` for primitives, ``accel.bvh``
for nodes, ``layout`` for materials, media and vertex classes, ``lights`` for emitters, ``camera``
for the camera). The field table is in :mod:`gdlearn.scene.compile`.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic

from gdlearn.kernels.camera import CAM_H, CAM_W
from gdlearn.kernels.jit import block


class SceneArrays(NamedTuple):
    prims: np.ndarray
    prim_info: np.ndarray
    prim_area: np.ndarray
    nodes: np.ndarray
    node_info: np.ndarray
    materials: np.ndarray
    media: np.ndarray
    emitters: np.ndarray
    em_prims: np.ndarray
    em_cdf: np.ndarray
    camera: np.ndarray
    bsphere: np.ndarray
    env: int
    camera_medium: int

    @property
    def width(self) -> int:
        return int(self.camera[CAM_W])

    @property
    def height(self) -> int:
        return int(self.camera[CAM_H])

    def __reduce__(self):
        # numpy unpickles every array writable, and the write flags name what the kernels compile
        # (the BVH's form, accel.forms; the material table's tier, bsdf.tiers): without them a
        # copy sent to another process would compile the tree traversal and every BSDF family
        flags = tuple(isinstance(v, np.ndarray) and v.flags.writeable for v in self)
        return _unpickled, (tuple(self), flags)


def _unpickled(values: tuple, writeable: tuple) -> SceneArrays:
    """A pickled :class:`SceneArrays` with its arrays' write flags as they were."""
    for v, w in zip(values, writeable):
        if isinstance(v, np.ndarray) and not w:
            v.flags.writeable = False
    return SceneArrays(*values)


# ------------------------------------------------------------------------------ borrowed arrays
# Every numba array carries a reference count (its "meminfo") that compiled code increments and
# decrements atomically whenever an array is passed to or returned from a non-inlined function. The
# path kernels pass the scene's arrays through dozens of such calls per bounce; with two threads
# both cores then hammer the *same* counters (one per scene array), and the cache line ping-pong
# cost more than the arithmetic: 2 threads rendered barely faster than 1. A *borrowed* array is the
# same data pointer, shape and strides with no meminfo, so every count becomes a null check. It is
# valid only while the owner is alive, i.e. inside one kernel call that holds the original ``sa``.

@intrinsic
def borrow(typingctx, arr):
    """``arr`` without a reference count (same type, data, shape, strides); see the note above."""
    if not isinstance(arr, types.Array):
        return None

    def codegen(context, builder, signature, args):
        src = context.make_array(arr)(context, builder, value=args[0])
        dst = context.make_array(arr)(context, builder)
        dst.meminfo = cgutils.get_null_value(dst.meminfo.type)
        dst.parent = cgutils.get_null_value(dst.parent.type)
        dst.nitems = src.nitems
        dst.itemsize = src.itemsize
        dst.data = src.data
        dst.shape = src.shape
        dst.strides = src.strides
        return dst._getvalue()

    return arr(arr), codegen


@block
def borrowed(sa):
    """``sa`` with every array borrowed (no reference counting; :func:`borrow`).

    Call it once at the top of a parallel kernel and pass the result down: the arrays are shared by
    all threads, and their atomic reference counts were the path tracer's scaling bottleneck. Only
    valid while ``sa`` itself is alive (for the duration of that kernel call); call it from compiled
    code only, never from Python (the returned arrays would not keep their memory alive)."""
    return SceneArrays(borrow(sa.prims), borrow(sa.prim_info), borrow(sa.prim_area), borrow(sa.nodes),
                       borrow(sa.node_info), borrow(sa.materials), borrow(sa.media), borrow(sa.emitters),
                       borrow(sa.em_prims), borrow(sa.em_cdf), borrow(sa.camera), borrow(sa.bsphere),
                       sa.env, sa.camera_medium)
