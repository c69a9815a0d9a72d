"""Scene queries on the compiled scene ``sa`` (:class:`gdlearn.scene.compile.SceneArrays`).

The one-line entry points every estimator uses -- the path tracer, photon tracing from the lights,
and the shift mappings that re-evaluate vertices:

* :func:`intersect` -- closest hit with its surface interaction,
* :func:`occluded` -- visibility between two points (shadow rays),
* :func:`sample_light` / :func:`light_pdf` / :func:`light_eval` -- next-event estimation,
* ``camera_ray`` / ``camera_raster`` (re-exported from :mod:`gdlearn.kernels.camera`).

``stack`` is a per-thread int32 scratch array of ``bvh.STACK_SIZE`` (see :func:`new_stack`).
"""
import math

import numpy as np
from numba import njit, types
from numba.core import cgutils
from numba.extending import intrinsic

from .bvh import STACK_SIZE, any_hit_inline, closest_hit
from .camera import camera_raster, camera_ray  # noqa: F401  (re-exported)
from .geometry import INFO_EMITTER, INFO_MAT, offset_origin, surface
from .lights import emitter_pdf, eval_emitter, sample_emitter
from .vec import dot

#: Relative shortening of shadow rays so they stop just before the point they connect to (Mitsuba's
#: ``ShadowEpsilon`` idea); the origin is already pushed off its surface by ``offset_origin``.
SHADOW_EPS = 1e-7


@njit(cache=True, error_model="numpy")
def new_stack():
    """A traversal stack for one thread."""
    return np.empty(STACK_SIZE, dtype=np.int32)


@njit(cache=True, error_model="numpy")
def intersect(sa, o, d, tmin, tmax, stack):
    """Closest hit of the ray o + t d, t in (tmin, tmax).

    Returns (hit, t, prim, p, ng, ns, front): ``ng`` the geometric normal, ``ns`` the shading
    normal (build the shading frame with ``vec.coordinate_system(ns)``), ``front`` True when the
    ray arrives on the side ``ng`` points to. On a miss hit is False and t = inf.
    """
    t, prim, u, v = closest_hit(sa.nodes, sa.node_info, sa.prims, sa.prim_info, o, d, tmin, tmax, stack)
    if prim < 0:
        z = (0.0, 0.0, 0.0)
        return False, math.inf, -1, z, z, z, False
    p, ng, ns = surface(sa.prims, sa.prim_info, prim, o, d, t, u, v)
    return True, t, prim, p, ng, ns, dot(d, ng) < 0.0


# forceinline: LLVM inlines this into its callers, the path kernels' per-bounce code (a call would pass
# its arrays as dozens of scalars; measured in benchmarks/README.md, "pt speed")
@njit(cache=True, error_model="numpy", forceinline=True)
def shadow_ray(p, ng, q):
    """(origin, unit direction, tmax) of the segment from surface point p (geometric normal ng;
    zeros for a point in a medium) to q. The origin is pushed off p's surface and the direction and
    length are measured *from that origin* (measuring from p would let the ray reach q's surface
    at grazing angles), then shortened by SHADOW_EPS."""
    d = (q[0] - p[0], q[1] - p[1], q[2] - p[2])
    if ng[0] != 0.0 or ng[1] != 0.0 or ng[2] != 0.0:
        o = offset_origin(p, ng, d)
        d = (q[0] - o[0], q[1] - o[1], q[2] - o[2])
    else:
        o = p
    dist = math.sqrt(dot(d, d))
    if dist == 0.0:
        return o, (0.0, 0.0, 1.0), 0.0
    inv = 1.0 / dist
    return o, (d[0] * inv, d[1] * inv, d[2] * inv), dist * (1.0 - SHADOW_EPS)


# forceinline: as above
@njit(cache=True, error_model="numpy", forceinline=True)
def occluded(sa, p, ng, q, stack):
    """True if anything blocks the segment from surface point p (geometric normal ng; pass zeros
    for a point in a medium) to q. Null-BSDF surfaces block too (in media they are crossed instead,
    see :mod:`gdlearn.kernels.volume_path`)."""
    o, d, tmax = shadow_ray(p, ng, q)
    if tmax <= 0.0:
        return False
    return any_hit_inline(sa.nodes, sa.node_info, sa.prims, sa.prim_info, o, d, 0.0, tmax, stack,
                   False, sa.materials) >= 0


@njit(cache=True, error_model="numpy")
def sample_light(sa, p, u_sel, u1, u2):
    """Next-event sample from p (no visibility test): see :func:`lights.sample_emitter`."""
    return sample_emitter(sa.emitters, sa.em_prims, sa.em_cdf, sa.prims, sa.prim_info, p, u_sel, u1, u2)


@njit(cache=True, error_model="numpy")
def light_pdf(sa, em, p, q, nq):
    """Solid-angle pdf at p of sampling emitter point q (normal nq) with :func:`sample_light`."""
    return emitter_pdf(sa.emitters, em, p, q, nq)


@njit(cache=True, error_model="numpy")
def light_eval(sa, prim, ns, d):
    """(emitter row or -1, radiance) a ray of direction d sees at a hit of primitive ``prim``."""
    em = sa.prim_info[prim, INFO_EMITTER]
    if em < 0:
        return -1, (0.0, 0.0, 0.0)
    return em, eval_emitter(sa.emitters, em, ns, d)


@njit(cache=True, error_model="numpy")
def material_of(sa, prim):
    """The material row of a primitive."""
    return sa.materials[sa.prim_info[prim, INFO_MAT]]


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
