"""Ray queries on the compiled scene ``sa`` (:class:`gdlearn.kernels.arrays.SceneArrays`).

* :func:`intersect` -- closest hit with its surface interaction (the shift mappings re-evaluate
  vertices with it),
* :func:`shadow_ray` / :func:`occluded` -- visibility between two points.

``stack`` is a per-thread int32 scratch array of ``accel.bvh.STACK_SIZE``.
"""
import math


from gdlearn.kernels.accel.bvh import any_hit_inline, closest_hit_inline
from gdlearn.kernels.geometry import offset_origin, surface
from gdlearn.kernels.vec import dot
from gdlearn.kernels.jit import inlined, leaf, noalloc

#: Relative shortening of shadow rays so they stop just before the point they connect to (Mitsuba's
#: ``ShadowEpsilon`` idea); the origin is already pushed off its surface by ``offset_origin``.
SHADOW_EPS = 1e-7


@leaf
def intersect(sa, o, d, tmin, tmax, stack):
    """Closest hit of the ray o + t d, t in (tmin, tmax).

    Returns (hit, t, prim, p, ng, ns, front): ``ng`` the geometric normal, ``ns`` the shading
    normal (build the shading frame with ``vec.coordinate_system(ns)``), ``front`` True when the
    ray arrives on the side ``ng`` points to. On a miss hit is False and t = inf.
    """
    return _intersect(sa.nodes, sa.node_info, sa.prims, sa.prim_info, o, d, tmin, tmax, stack)


# Not inlined (the shifts call intersect from many places), but with the traversal inlined into it,
# no reference counts, and only the four arrays it reads as arguments: a call passes each array as
# about seven scalars, the whole scene as over a hundred (benchmarks/README.md, "Calls that pass the
# scene").
@noalloc
def _intersect(nodes, node_info, prims, prim_info, o, d, tmin, tmax, stack):
    t, prim, u, v = closest_hit_inline(nodes, node_info, prims, prim_info, o, d, tmin, tmax, stack)
    if prim < 0:
        z = (0.0, 0.0, 0.0)
        return False, math.inf, -1, z, z, z, False
    p, ng, ns = surface(prims, prim_info, prim, o, d, t, u, v)
    return True, t, prim, p, ng, ns, dot(d, ng) < 0.0


# forceinline: LLVM inlines this into its callers, the path kernels' per-bounce code (a call would pass
# its arrays as dozens of scalars; measured in benchmarks/README.md, "pt speed")
@inlined
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
@inlined
def occluded(sa, p, ng, q, stack):
    """True if anything blocks the segment from surface point p (geometric normal ng; pass zeros
    for a point in a medium) to q. Null-BSDF surfaces block too (in media they are crossed instead,
    see :mod:`gdlearn.integrators.path.volume`)."""
    o, d, tmax = shadow_ray(p, ng, q)
    if tmax <= 0.0:
        return False
    return any_hit_inline(sa.nodes, sa.node_info, sa.prims, sa.prim_info, o, d, 0.0, tmax, stack,
                   False, sa.materials) >= 0



