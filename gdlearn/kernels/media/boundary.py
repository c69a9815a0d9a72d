"""Medium boundaries: which medium a ray is in, after a surface and at its start.

Mitsuba 3's rule (``Shape::is_medium_transition``, ``SurfaceInteraction::target_medium``): at a
surface of a shape that declares an interior or exterior medium, a ray continuing to the back side
of the geometric normal is in ``interior``, else in ``exterior`` (None = vacuum, row -1); a shape
declaring neither leaves the medium unchanged. The path tracers start from the sensor's declared
medium (:mod:`gdlearn.integrators.path.volume`); a light path starts wherever its emitter is, and no
emitter declares a medium, so :func:`locate_medium` finds it from the geometry by the same rule,
read backwards: walking along a ray from the point, the first medium transition met from its
front side says the point is in that shape's ``exterior``, met from behind in its ``interior``.
"""
import math

from gdlearn.kernels.accel.bvh import closest_hit_inline
from gdlearn.kernels.geometry import INFO_MED_EXT, INFO_MED_INT, INFO_MED_TRANS, offset_origin, surface
from gdlearn.kernels.vec import dot
from gdlearn.kernels.jit import block, inlined

#: surfaces a locating walk may pass before giving up (the point is then taken to be outside)
MAX_LOCATE = 4096
#: the sentinel :func:`locate_medium` returns when its walk meets no medium transition
UNBOUNDED_REGION = -2


@block
def next_medium(prim_info, prim, medium, d, ng):
    """The medium a ray of direction d is in after crossing/leaving the surface of ``prim``."""
    if prim_info[prim, INFO_MED_TRANS] == 0:
        return medium
    if dot(d, ng) < 0.0:
        return prim_info[prim, INFO_MED_INT]
    return prim_info[prim, INFO_MED_EXT]


@inlined
def locate_medium(sa, o, d, outside, stack):
    """The medium at ``o``, read from the first medium transition along the ray (o, d): its exterior
    if the ray meets it from the front (dot(d, ng) < 0), its interior otherwise. Surfaces declaring
    no medium are walked through. ``outside`` is returned when the walk meets no transition: the
    point lies in the region that reaches infinity."""
    for _ in range(MAX_LOCATE):
        t, prim, u, v = closest_hit_inline(sa.nodes, sa.node_info, sa.prims, sa.prim_info, o, d, 0.0, math.inf,
                                           stack)
        if prim < 0:
            return outside
        p, ng, ns = surface(sa.prims, sa.prim_info, prim, o, d, t, u, v)
        if sa.prim_info[prim, INFO_MED_TRANS] != 0:
            if dot(d, ng) < 0.0:
                return sa.prim_info[prim, INFO_MED_EXT]
            return sa.prim_info[prim, INFO_MED_INT]
        o = offset_origin(p, ng, d)
    return outside
