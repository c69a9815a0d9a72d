"""Emitters: sampling a point/direction for next-event estimation, the matching pdf, and emission.

Follows Mitsuba 3 (``src/render/scene.cpp`` and ``src/emitters/*.cpp``):

* the scene picks one emitter *uniformly* (``Scene::sample_emitter``: probability 1/N, weight N);
  every area-emitting shape is one emitter;
* ``area``: a point uniform in area on the shape (pdf 1/A), converted to solid angle
  ``dist^2 / |cos theta_q|``; it emits ``radiance`` only on the side its normal faces
  (``src/emitters/area.cpp``: zero when ``cos_theta(si.wi) <= 0``);
* ``point``: ``intensity / dist^2`` (delta position);
* ``spot``: ``intensity * falloff / dist^2``, falloff 1 inside ``beam_width``, linear in angle down
  to 0 at ``cutoff_angle`` (``src/emitters/spot.cpp::falloff_curve``); the spot shines along local +z;
* ``directional``: ``irradiance`` from direction ``-direction`` (delta direction), shadow ray of
  length 2 max(r, |p - c|) for the scene's bounding sphere (c, r) (:func:`infinite_distance`);
* ``constant``: ``radiance`` from every direction, sampled uniformly on the sphere (pdf 1 / 4 pi).

Emitter rows (``sa.emitters``, float64, ``EM_WIDTH``) hold the parameters; area emitters own the
primitive range ``sa.em_prims[first : first + count]`` with the normalised cumulative areas in
``sa.em_cdf`` (a primitive is chosen with probability area_i / A, then a uniform point on it).
"""
import math


from gdlearn.kernels.geometry import (G_A, G_B, G_C, G_E1, G_E2, G_HASN, G_NG, G_R, G_SIGN, INFO_TYPE, P_SPHERE,
                       P_TRIANGLE)
from gdlearn.kernels.vec import dot, normalize
from gdlearn.kernels.jit import block, inlined

E_AREA, E_POINT, E_SPOT, E_DIRECTIONAL, E_CONSTANT = 0, 1, 2, 3, 4

EM_TYPE = 0
EM_RGB = 1          # 3: radiance (area, constant) / intensity (point, spot) / irradiance (directional)
EM_FIRST = 4        # area: first index into em_prims / em_cdf
EM_COUNT = 5        # area: number of primitives
EM_AREA = 6         # area: total surface area A
EM_P = 7            # 3: point/spot position
EM_D = 10           # 3: directional: the direction light travels (unit)
EM_COS_CUTOFF = 13  # spot
EM_COS_BEAM = 14
EM_CUTOFF = 15      # radians
EM_INV_TRANS = 16   # 1 / (cutoff - beam_width)
EM_INV = 17         # 9: spot's inverse to_world 3x3, row-major (world -> local direction)
EM_BS_R = 26        # scene bounding-sphere radius (directional, constant)
EM_BS_C = 28        # 3: scene bounding-sphere centre (directional, constant)
EM_WIDTH = 31

INV_FOUR_PI = 0.25 / math.pi


# forceinline: LLVM inlines this into its callers, the path kernels' per-bounce code (a call would pass
# its arrays as dozens of scalars; measured in benchmarks/README.md, "pt speed")
@inlined
def prim_point(prims, prim_info, prim, u1, u2):
    """A uniform point on a primitive and its normal: (q, n). Triangles: Mitsuba's
    ``square_to_uniform_triangle``; spheres: uniform sphere; disks: concentric disk mapping."""
    pt = prim_info[prim, INFO_TYPE]
    if pt == P_TRIANGLE:
        su = math.sqrt(1.0 - u1)
        b1 = 1.0 - su
        b2 = u2 * su
        q = (prims[prim, 0] + b1 * prims[prim, G_E1] + b2 * prims[prim, G_E2], prims[prim, 1] + b1 * prims[prim, G_E1 + 1] + b2 * prims[prim, G_E2 + 1],
             prims[prim, 2] + b1 * prims[prim, G_E1 + 2] + b2 * prims[prim, G_E2 + 2])
        if prims[prim, G_HASN] != 0.0:
            b0 = 1.0 - b1 - b2
            n = normalize((b0 * prims[prim, 12] + b1 * prims[prim, 15] + b2 * prims[prim, 18], b0 * prims[prim, 13] + b1 * prims[prim, 16] + b2 * prims[prim, 19],
                           b0 * prims[prim, 14] + b1 * prims[prim, 17] + b2 * prims[prim, 20]))
        else:
            n = (prims[prim, G_NG], prims[prim, G_NG + 1], prims[prim, G_NG + 2])
        return q, n
    if pt == P_SPHERE:
        z = 1.0 - 2.0 * u1
        r = math.sqrt(max(0.0, 1.0 - z * z))
        phi = 2.0 * math.pi * u2
        w = (r * math.cos(phi), r * math.sin(phi), z)
        rad = prims[prim, G_R]
        s = prims[prim, G_SIGN]
        return (prims[prim, 0] + rad * w[0], prims[prim, 1] + rad * w[1], prims[prim, 2] + rad * w[2]), (s * w[0], s * w[1], s * w[2])
    # disk: Shirley-Chiu concentric map of [0,1)^2 onto the unit disk, then the disk's affine axes
    a = 2.0 * u1 - 1.0
    b = 2.0 * u2 - 1.0
    if a == 0.0 and b == 0.0:
        x = 0.0
        y = 0.0
    elif abs(a) > abs(b):
        x = a * math.cos(0.25 * math.pi * b / a)
        y = a * math.sin(0.25 * math.pi * b / a)
    else:
        x = b * math.sin(0.25 * math.pi * a / b)
        y = b * math.cos(0.25 * math.pi * a / b)
    q = (prims[prim, G_C] + x * prims[prim, G_A] + y * prims[prim, G_B], prims[prim, G_C + 1] + x * prims[prim, G_A + 1] + y * prims[prim, G_B + 1],
         prims[prim, G_C + 2] + x * prims[prim, G_A + 2] + y * prims[prim, G_B + 2])
    return q, (prims[prim, G_NG], prims[prim, G_NG + 1], prims[prim, G_NG + 2])


@inlined
def pick_prim(em_cdf, first, count, u):
    """The first cdf entry > u in em_cdf[first:first+count] (the last if none): for up to 8 entries
    the number of entries <= u before the last, counted without a branch (the cdf does not decrease,
    and a binary search's branches on a random u are mispredicted half the time: a rectangle light
    is 2 entries); beyond that a binary search. Both give the same index."""
    if count <= 8:
        k = 0
        for i in range(first, first + count - 1):
            k += em_cdf[i] <= u
        return first + k
    lo = first
    hi = first + count - 1
    while lo < hi:
        mid = (lo + hi) // 2
        if em_cdf[mid] > u:
            hi = mid
        else:
            lo = mid + 1
    return lo


@block
def spot_falloff(emitters, em, d_world):
    """Mitsuba's ``falloff_curve`` for the world direction ``d_world`` leaving the spot."""
    lx = emitters[em, EM_INV] * d_world[0] + emitters[em, EM_INV + 1] * d_world[1] + emitters[em, EM_INV + 2] * d_world[2]
    ly = emitters[em, EM_INV + 3] * d_world[0] + emitters[em, EM_INV + 4] * d_world[1] + emitters[em, EM_INV + 5] * d_world[2]
    lz = emitters[em, EM_INV + 6] * d_world[0] + emitters[em, EM_INV + 7] * d_world[1] + emitters[em, EM_INV + 8] * d_world[2]
    ln = math.sqrt(lx * lx + ly * ly + lz * lz)
    if ln == 0.0:
        return 0.0
    c = lz / ln
    if c <= emitters[em, EM_COS_CUTOFF]:
        return 0.0
    if c >= emitters[em, EM_COS_BEAM]:
        return 1.0
    return (emitters[em, EM_CUTOFF] - math.acos(min(1.0, c))) * emitters[em, EM_INV_TRANS]


# forceinline: as above
@inlined
def infinite_distance(emitters, em, p):
    """Length of the shadow ray from ``p`` to a directional or constant emitter ``em``:
    2 max(r, |p - c|) for the scene's bounding sphere (c, r), as Mitsuba 3's ``directional.cpp`` and
    ``constant.cpp`` (``sample_direction``). The ray thus always leaves the bounding sphere, also from
    a point outside it: a camera on the sensor, or a medium vertex far out in a global medium, where a
    fixed 2 r would end the ray early and, in a medium, keep too much transmittance."""
    dx = p[0] - emitters[em, EM_BS_C]
    dy = p[1] - emitters[em, EM_BS_C + 1]
    dz = p[2] - emitters[em, EM_BS_C + 2]
    return 2.0 * max(emitters[em, EM_BS_R], math.sqrt(dx * dx + dy * dy + dz * dz))


# forceinline: as above
@inlined
def same_direction_point(emitters, em, p_base, q_base, p):
    """The light point of a directional or constant emitter seen from ``p`` in the direction of the
    base's sample ``p_base -> q_base`` (a shift that copies the direction), at the distance
    :func:`infinite_distance` of ``p`` itself, so an offset's shadow ray is the one its own
    next-event sample would trace."""
    dx, dy, dz = q_base[0] - p_base[0], q_base[1] - p_base[1], q_base[2] - p_base[2]
    f = infinite_distance(emitters, em, p) / math.sqrt(dx * dx + dy * dy + dz * dz)
    return (p[0] + f * dx, p[1] + f * dy, p[2] + f * dz)


@inlined
def pick_emitter(emitters, u_sel):
    """The emitter ``u_sel`` picks uniformly (``Scene::sample_emitter``) and the leftover of u_sel,
    uniform in [0, 1), which picks its primitive."""
    n_em = emitters.shape[0]
    x = u_sel * n_em
    em = min(int(x), n_em - 1)
    return em, min(x - em, 0.9999999999999999)


# forceinline: as above
@inlined
def sample_emitter(emitters, em_prims, em_cdf, prims, prim_info, p, u_sel, u1, u2):
    """Next-event estimation from point ``p``: pick an emitter uniformly, then a point/direction.

    Returns (em, q, nq, d, dist, weight, pdf, pdf_area, is_delta):
    ``q`` the emitter point (for directional/constant a point :func:`infinite_distance` away along d), ``nq`` its normal
    (zeros for point/spot/directional/constant), ``d`` the unit direction p -> q, ``dist`` |q - p|,
    ``weight`` = Le(q -> p) / pdf (rgb, selection included; Mitsuba's ``em_weight``), ``pdf`` the
    solid-angle pdf at p (selection included; for delta emitters the selection probability),
    ``pdf_area`` the area pdf at q (selection included; 0 for delta and constant), ``is_delta``.
    ``em = -1`` (and zero weight) when the sample carries no light (back side, outside the spot).
    """
    n_em = emitters.shape[0]
    zero = (0.0, 0.0, 0.0)
    if n_em == 0:
        return -1, p, zero, zero, 0.0, zero, 0.0, 0.0, False
    em, u_rest = pick_emitter(emitters, u_sel)
    et = int(emitters[em, EM_TYPE])
    sel = 1.0 / n_em
    rgb = (emitters[em, EM_RGB], emitters[em, EM_RGB + 1], emitters[em, EM_RGB + 2])
    if et == E_AREA:
        prim = pick_prim(em_cdf, int(emitters[em, EM_FIRST]), int(emitters[em, EM_COUNT]), u_rest)
        q, nq = prim_point(prims, prim_info, em_prims[prim], u1, u2)
        dv = (q[0] - p[0], q[1] - p[1], q[2] - p[2])
        dist2 = dot(dv, dv)
        if dist2 == 0.0:
            return -1, q, nq, zero, 0.0, zero, 0.0, 0.0, False
        dist = math.sqrt(dist2)
        inv_dist = 1.0 / dist          # reciprocals: a division costs several multiplications
        d = (dv[0] * inv_dist, dv[1] * inv_dist, dv[2] * inv_dist)
        cos_q = -dot(d, nq)
        if cos_q <= 0.0:        # one-sided: the back of an area emitter is black
            return -1, q, nq, d, dist, zero, 0.0, 0.0, False
        pdf_area = sel / emitters[em, EM_AREA]
        pdf = pdf_area * dist2 / cos_q
        inv_pdf = cos_q / (pdf_area * dist2)
        return em, q, nq, d, dist, (rgb[0] * inv_pdf, rgb[1] * inv_pdf, rgb[2] * inv_pdf), pdf, pdf_area, False
    if et == E_POINT or et == E_SPOT:
        q = (emitters[em, EM_P], emitters[em, EM_P + 1], emitters[em, EM_P + 2])
        dv = (q[0] - p[0], q[1] - p[1], q[2] - p[2])
        dist2 = dot(dv, dv)
        if dist2 == 0.0:
            return -1, q, zero, zero, 0.0, zero, 0.0, 0.0, True
        dist = math.sqrt(dist2)
        d = (dv[0] / dist, dv[1] / dist, dv[2] / dist)
        f = 1.0 / (dist2 * sel)
        if et == E_SPOT:
            f *= spot_falloff(emitters, em, (-d[0], -d[1], -d[2]))
            if f <= 0.0:
                return -1, q, zero, d, dist, zero, 0.0, 0.0, True
        return em, q, zero, d, dist, (rgb[0] * f, rgb[1] * f, rgb[2] * f), sel, 0.0, True
    r2 = infinite_distance(emitters, em, p)
    if et == E_DIRECTIONAL:
        d = (-emitters[em, EM_D], -emitters[em, EM_D + 1], -emitters[em, EM_D + 2])
        q = (p[0] + r2 * d[0], p[1] + r2 * d[1], p[2] + r2 * d[2])
        return em, q, zero, d, r2, (rgb[0] / sel, rgb[1] / sel, rgb[2] / sel), sel, 0.0, True
    # constant: uniform direction on the sphere
    z = 1.0 - 2.0 * u1
    r = math.sqrt(max(0.0, 1.0 - z * z))
    phi = 2.0 * math.pi * u2
    d = (r * math.cos(phi), r * math.sin(phi), z)
    q = (p[0] + r2 * d[0], p[1] + r2 * d[1], p[2] + r2 * d[2])
    pdf = sel * INV_FOUR_PI
    return em, q, zero, d, r2, (rgb[0] / pdf, rgb[1] / pdf, rgb[2] / pdf), pdf, 0.0, False


# forceinline: as above
@inlined
def emitter_pdf(emitters, em, p, q, nq):
    """Solid-angle pdf at ``p`` with which :func:`sample_emitter` would produce the emitter point
    ``q`` (normal ``nq``) of emitter ``em`` (area or constant; delta emitters: 0). For constant
    emitters q may be any point along the direction."""
    n_em = emitters.shape[0]
    et = int(emitters[em, EM_TYPE])
    if et == E_CONSTANT:
        return INV_FOUR_PI / n_em
    if et != E_AREA:
        return 0.0
    dv = (q[0] - p[0], q[1] - p[1], q[2] - p[2])
    dist2 = dot(dv, dv)
    if dist2 == 0.0:
        return 0.0
    cos_q = abs(dot(dv, nq)) / math.sqrt(dist2)
    if cos_q == 0.0:
        return 0.0
    return dist2 / (cos_q * emitters[em, EM_AREA] * n_em)


# forceinline: as above
@inlined
def eval_emitter(emitters, em, nq, d):
    """Radiance an area emitter sends back along a ray of direction ``d`` that hit it at a point of
    shading normal ``nq`` (zero from behind); constant emitters ignore nq."""
    et = int(emitters[em, EM_TYPE])
    if et == E_AREA and dot(d, nq) >= 0.0:
        return (0.0, 0.0, 0.0)
    if et != E_AREA and et != E_CONSTANT:
        return (0.0, 0.0, 0.0)
    return (emitters[em, EM_RGB], emitters[em, EM_RGB + 1], emitters[em, EM_RGB + 2])
