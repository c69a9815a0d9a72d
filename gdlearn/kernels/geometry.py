"""Ray-primitive intersection and surface interactions: triangles, spheres, disks.

Every shape of a scene is flattened (by :mod:`gdlearn.scene.compile`) into *primitives*, one row of
``PRIM_WIDTH`` float64 per primitive in ``sa.prims`` and one row of ``INFO_WIDTH`` int32 in
``sa.prim_info`` (type, material, emitter, interior and exterior medium). Rectangles, cubes and
meshes become triangles (Mitsuba 3's ``rectangle`` is a planar quad: two triangles are the same
surface); spheres and disks stay analytic, so their areas -- and hence emitted power -- are exact.

Intersection is split as in Mitsuba 3 (``PreliminaryIntersection`` -> ``SurfaceInteraction``):
the hot traversal only returns ``(t, prim, u, v)``; :func:`surface` then computes the position,
the geometric normal, the shading normal and the side, for the one hit that matters.

Normals follow Mitsuba 3: a triangle's geometric normal is ``normalize(cross(p1 - p0, p2 - p0))``
(``src/render/mesh.cpp``), a rectangle's is ``to_world`` applied to +z as a normal
(``src/shapes/rectangle.cpp``), a sphere's points outwards, a disk's is +z; ``flip_normals`` negates
them. The compile step stores the final geometric normal, so kernels never re-derive it.
"""
import math


from gdlearn.kernels.vec import dot, fmax, normalize, sub
from gdlearn.kernels.jit import inlined

# --- primitive types (column INFO_TYPE) ----------------------------------------------------------
P_TRIANGLE = 0
P_SPHERE = 1
P_DISK = 2

# --- int32 row of sa.prim_info ---------------------------------------------------------------------
INFO_TYPE = 0
INFO_MAT = 1        # row of sa.materials
INFO_EMITTER = 2    # row of sa.emitters, -1 if the primitive does not emit
INFO_MED_INT = 3    # interior medium row, -1 = vacuum
INFO_MED_EXT = 4    # exterior medium row, -1 = vacuum
INFO_MED_TRANS = 5  # 1 if the shape declares any medium (Mitsuba's is_medium_transition())
INFO_SHAPE = 6      # index of the scene shape the primitive came from
INFO_WIDTH = 7

# --- float64 row of sa.prims -----------------------------------------------------------------------
# triangle: p0, e1 = p1 - p0, e2 = p2 - p0, geometric normal, vertex normals n0 n1 n2, has-normals flag
# sphere:   centre, radius, normal sign (+1 outwards, -1 flipped)
# disk:     centre, axis a, axis b (world images of local x, y), normal, dual axes da, db
G_P0, G_E1, G_E2, G_NG = 0, 3, 6, 9
G_N0, G_N1, G_N2, G_HASN = 12, 15, 18, 21
G_C, G_R, G_SIGN = 0, 3, 4
G_A, G_B, G_DA, G_DB = 3, 6, 12, 15
PRIM_WIDTH = 22



@inlined
def _v3(P, i, k):
    return (P[i, k], P[i, k + 1], P[i, k + 2])


# The intersection routines take the whole primitive table and an index instead of a row: slicing a
# row creates an array view whose reference count two threads would update atomically on every
# primitive test (the same counter for all rows), which costs more than the test itself.

@inlined
def intersect_triangle(P, i, o, d, tmax):
    """Moeller-Trumbore: (t, u, v) with t = inf on a miss. u, v are barycentrics of p1 and p2."""
    e1x, e1y, e1z = P[i, 3], P[i, 4], P[i, 5]
    e2x, e2y, e2z = P[i, 6], P[i, 7], P[i, 8]
    pvx = d[1] * e2z - d[2] * e2y
    pvy = d[2] * e2x - d[0] * e2z
    pvz = d[0] * e2y - d[1] * e2x
    det = e1x * pvx + e1y * pvy + e1z * pvz
    if det == 0.0:
        return math.inf, 0.0, 0.0
    inv = 1.0 / det
    tx, ty, tz = o[0] - P[i, 0], o[1] - P[i, 1], o[2] - P[i, 2]
    u = (tx * pvx + ty * pvy + tz * pvz) * inv
    if u < 0.0 or u > 1.0:
        return math.inf, 0.0, 0.0
    qx = ty * e1z - tz * e1y
    qy = tz * e1x - tx * e1z
    qz = tx * e1y - ty * e1x
    v = (d[0] * qx + d[1] * qy + d[2] * qz) * inv
    if v < 0.0 or u + v > 1.0:
        return math.inf, 0.0, 0.0
    t = (e2x * qx + e2y * qy + e2z * qz) * inv
    if t <= 0.0 or t >= tmax:
        return math.inf, 0.0, 0.0
    return t, u, v


@inlined
def intersect_sphere(P, i, o, d, tmin, tmax):
    """Nearest root in (tmin, tmax) of |o + t d - c| = r, for a unit d.

    Uses the cancellation-free discriminant r^2 - |f - (f.d) d|^2 (Haines et al., Ray Tracing Gems
    ch. 7) so grazing rays and far-away spheres keep their precision.
    """
    fx, fy, fz = o[0] - P[i, 0], o[1] - P[i, 1], o[2] - P[i, 2]
    r = P[i, G_R]
    b = -(fx * d[0] + fy * d[1] + fz * d[2])
    lx, ly, lz = fx + b * d[0], fy + b * d[1], fz + b * d[2]
    disc = r * r - (lx * lx + ly * ly + lz * lz)
    if disc < 0.0:
        return math.inf
    c = fx * fx + fy * fy + fz * fz - r * r
    q = b + math.copysign(math.sqrt(disc), b)
    if q == 0.0:
        return math.inf
    t0 = c / q
    t1 = q
    if t0 > t1:
        t0, t1 = t1, t0
    if t0 > tmin and t0 < tmax:
        return t0
    if t1 > tmin and t1 < tmax:
        return t1
    return math.inf


@inlined
def intersect_disk(P, i, o, d, tmax):
    """Plane of the disk, then local coordinates through the dual axes: inside if u^2 + v^2 <= 1."""
    nx, ny, nz = P[i, G_NG], P[i, G_NG + 1], P[i, G_NG + 2]
    dn = d[0] * nx + d[1] * ny + d[2] * nz
    if dn == 0.0:
        return math.inf, 0.0, 0.0
    t = ((P[i, 0] - o[0]) * nx + (P[i, 1] - o[1]) * ny + (P[i, 2] - o[2]) * nz) / dn
    if t <= 0.0 or t >= tmax:
        return math.inf, 0.0, 0.0
    rx = o[0] + t * d[0] - P[i, 0]
    ry = o[1] + t * d[1] - P[i, 1]
    rz = o[2] + t * d[2] - P[i, 2]
    u = rx * P[i, G_DA] + ry * P[i, G_DA + 1] + rz * P[i, G_DA + 2]
    v = rx * P[i, G_DB] + ry * P[i, G_DB + 1] + rz * P[i, G_DB + 2]
    if u * u + v * v > 1.0:
        return math.inf, 0.0, 0.0
    return t, u, v


@inlined
def intersect_prim(prims, ptype, i, o, d, tmin, tmax):
    """(t, u, v) of primitive ``i`` (t = inf: miss, or outside (tmin, tmax))."""
    if ptype == P_TRIANGLE:
        t, u, v = intersect_triangle(prims, i, o, d, tmax)
    elif ptype == P_SPHERE:
        t = intersect_sphere(prims, i, o, d, tmin, tmax)
        u = 0.0
        v = 0.0
    else:
        t, u, v = intersect_disk(prims, i, o, d, tmax)
    if t <= tmin:
        return math.inf, 0.0, 0.0
    return t, u, v


# forceinline: LLVM inlines this into its callers, the path kernels' per-bounce code (a call would pass
# its arrays as dozens of scalars; measured in benchmarks/README.md, "pt speed")
@inlined
def surface(prims, prim_info, prim, o, d, t, u, v):
    """The surface interaction of a hit: (p, ng, ns).

    ``ng`` is the geometric normal (Mitsuba's ``si.n``), ``ns`` the shading normal (``si.sh_frame.n``;
    interpolated vertex normals on smooth meshes, else ng). The hit point is recomputed on the
    primitive (not o + t d) for triangles and disks, which keeps it on the surface to rounding.
    """
    ptype = prim_info[prim, INFO_TYPE]
    if ptype == P_TRIANGLE:
        w = 1.0 - u - v
        p = (prims[prim, 0] + u * prims[prim, 3] + v * prims[prim, 6], prims[prim, 1] + u * prims[prim, 4] + v * prims[prim, 7],
             prims[prim, 2] + u * prims[prim, 5] + v * prims[prim, 8])
        ng = _v3(prims, prim, G_NG)
        if prims[prim, G_HASN] != 0.0:
            ns = normalize((w * prims[prim, 12] + u * prims[prim, 15] + v * prims[prim, 18], w * prims[prim, 13] + u * prims[prim, 16] + v * prims[prim, 19],
                            w * prims[prim, 14] + u * prims[prim, 17] + v * prims[prim, 20]))
        else:
            ns = ng
    elif ptype == P_SPHERE:
        p0 = (o[0] + t * d[0], o[1] + t * d[1], o[2] + t * d[2])
        ng = normalize(sub(p0, _v3(prims, prim, G_C)))
        r = prims[prim, G_R]
        # project back onto the sphere: o + t d drifts by ~t * eps
        p = (prims[prim, 0] + r * ng[0], prims[prim, 1] + r * ng[1], prims[prim, 2] + r * ng[2])
        s = prims[prim, G_SIGN]
        ng = (s * ng[0], s * ng[1], s * ng[2])
        ns = ng
    else:
        p = (prims[prim, 0] + u * prims[prim, 3] + v * prims[prim, 6], prims[prim, 1] + u * prims[prim, 4] + v * prims[prim, 7],
             prims[prim, 2] + u * prims[prim, 5] + v * prims[prim, 8])
        ng = _v3(prims, prim, G_NG)
        ns = ng
    return p, ng, ns


@inlined
def offset_origin(p, ng, d):
    """Spawn point for a ray leaving ``p`` along ``d``: pushed off the surface to d's side of ng.

    The push scales with the coordinates' magnitude (float64 rounding is relative), like pbrt's
    error-bound offset but with a fixed conservative bound (1e-9 relative, >= 1e-7 absolute).
    """
    eps = 1e-9 * fmax(abs(p[0]), fmax(abs(p[1]), abs(p[2]))) + 1e-7     # selects: vectorisable
    if dot(d, ng) < 0.0:
        eps = -eps
    return (p[0] + eps * ng[0], p[1] + eps * ng[1], p[2] + eps * ng[2])
