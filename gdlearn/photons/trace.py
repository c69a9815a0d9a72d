"""Light-path tracing (importance transport) into flat vertex records.

A light path starts on an emitter chosen by power (:mod:`gdlearn.photons.emit`) and walks the
scene by BSDF sampling (Veach 1997, Sec. 10.2; pbrt-v3 ``SPPMIntegrator`` photon pass), with the
two corrections importance transport needs:

* the adjoint BSDF of a refraction carries no radiance scaling: Mitsuba's and gdlearn's dielectrics
  scale radiance by eta_ti^2 on refraction (Veach 1997, Sec. 5.2), so a light path multiplies the
  sampled weight back by ``bsdf_eta(wi, wo)^2``;
* shading normals make the adjoint BSDF non-symmetric: the weight is multiplied by
  ``|wi.ns| |wo.ng| / (|wi.ng| |wo.ns|)`` (Veach 1997, Sec. 5.3.2; pbrt-v3
  ``CorrectShadingNormal``), exactly 1 on flat geometry.

Participating media (homogeneous; PHOTONS.md Sec. 1.1; the random walk of Jarosz et al. 2008,
Eq. 11, whose photon weights alpha_i are the flux of Eq. 4): the path knows the medium it is in --
at the start the one the emitter sits in (:func:`!gdlearn.kernels.media.boundary.locate_medium`:
no emitter declares a medium, so it is read from the geometry by Mitsuba's interior/exterior rule;
a point in the unbounded region takes ``TraceParams.outer_medium``, which :class:`LightTracer`
derives from the scene; one extra ray walk per path in a scene with media, none without), then
the volpath rules of :mod:`!gdlearn.integrators.path.volume`
(:func:`!gdlearn.kernels.media.boundary.next_medium` after every surface, the function volpath
calls). On every segment inside a medium a
free-flight distance is sampled with the path tracer's spectral-MIS routine
(:func:`!gdlearn.kernels.media.medium.sample_distance`, Jarosz et al. 2008, Eq. 1-2 and Table 1):

* a collision before the next surface is a K_MEDIUM vertex (a volume photon when
  ``want_volume``); the path takes the weight sigma_s T(t) / pdf(t) (the albedo in a grey medium)
  and leaves by Henyey-Greenstein sampling (weight 1);
* otherwise the path reaches the surface with weight T(t_max) / P(pass).

A ``null`` surface is an index-matched interface: the medium changes, the direction does not, it is
not a bounce (no scattering, no roulette, no ``max_vertices`` count) -- but it is recorded, as a
K_SURFACE vertex with lobe -1 and F_DELTA_OUT, so every recorded edge lies in one medium (a photon
beam) and the shifts can cross the same interfaces (records module). At most ``max_null`` of them
per path (LightTracer: 2 (max_vertices + 1) when the scene has a null BSDF, two crossings of one
convex boundary per edge, else 0); a path that would need more ends there.

The pdfs stored (records module): forward, the parent's solid-angle pdf times the edge's free-flight
factor -- the collision density (1/3) sum_c sigma_c e^(-sigma_c t) at a medium vertex, the pass
probability at a surface -- times ``|cos|`` at a surface (1 at a medium vertex) over dist^2 (PHOTONS.md
Sec. 0.1 and E2: volume measure in media, area measure on surfaces; Veach 1997, Sec. 8.2.2 for
the change of measure); backwards the same with the child's sampling pdf and the parent's cosine.

Russian roulette from light depth ``rr_depth`` survives with ``min(max(w), 0.95)`` per bounce, w the
vertex's scattering weight times the free-flight weights of the edge that arrived (the albedo at a
medium vertex): the power of a path then stays about constant (pbrt-v3's photon pass, Mitsuba's cap).

Random numbers: light path j of pass i uses ``rand(seed, LIGHT_KEY0 + j, i, dim)`` with dims
0 emitter choice, 1-2 position, 3-4 direction, and for the scattering vertex k >= 1 the block
``5 + 6 (k - 1) + {0 lobe, 1-2 direction (BSDF or phase), 3 roulette, 4-5 the free flight (channel,
distance) of the edge arriving at k}``; a segment after the c-th null crossing of the path
(c >= 1) takes its free flight from ``NULL_DIMS0 + 2 (c - 1) + {0, 1}`` instead. The records are a
pure function of (seed, i, j): tracing is a ``prange`` over chunks of paths, each path writing
fixed slots of a batch, then compacted in path order -- the same records for any thread count.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numba
import numpy as np
from numba import prange

from gdlearn.kernels import layout as L
from gdlearn.kernels.bsdf.dispatch import (bsdf_eta, bsdf_is_null, bsdf_pdf, bsdf_sample, sampled_lobe_class,
                                           vertex_class)
from gdlearn.kernels.accel.bvh import STACK_SIZE, closest_hit_inline
from gdlearn.kernels.camera import CAM_O
from gdlearn.kernels.geometry import INFO_MAT, INFO_MED_TRANS, offset_origin, surface
from gdlearn.kernels.media.boundary import UNBOUNDED_REGION, locate_medium, next_medium
from gdlearn.kernels.media.medium import distance_pdf, medium_params, pass_probability, sample_distance
from gdlearn.kernels.media.phase import hg_sample
from gdlearn.kernels.rng import LIGHT_KEY0, path_state, rand_at
from gdlearn.kernels.arrays import borrow
from gdlearn.kernels.vec import coordinate_system, dot, max3, to_local, to_world
from gdlearn.kernels.arrays import borrowed
from gdlearn.photons.emit import emitter_cdf, sample_emission
from gdlearn.photons.records import (F_DELTA_DIR, F_DELTA_OUT, F_DELTA_POS, F_PHOTON, K_EMITTER, K_MEDIUM, K_SURFACE,
                                     LightPaths, allocate)
from gdlearn.kernels.jit import block, inlined, noalloc, rows

DIMS_START, DIMS_PER_BOUNCE = 5, 6
D_LOBE, D_U1, D_U2, D_RR, D_MED_CH, D_MED_T = 0, 1, 2, 3, 4, 5
#: first dimension of the free flights after null crossings (far above any bounce block)
NULL_DIMS0 = 1 << 24
#: the fixed, generic direction of the locating walks of :func:`outer_medium`
_LOCATE_DIR = (0.3320053, 0.5544812, 0.7631006)


class TraceParams(NamedTuple):
    """Constants of a light-path walk (numba passes a NamedTuple as a struct).

    ``max_vertices``: scattering vertices after the emitter (Mitsuba's max_depth - 1, or fewer if
    the effects plan bounds the interior vertices); ``want_caustic`` / ``want_other``: does the plan
    ask for paths whose first scattering vertex is specular (L S+ D ..., caustics) / is not (surface
    photons)? ``want_volume``: are medium vertices photons (a volumetric estimator's request; a
    path is then never cut at its first vertex, volume photons may follow any of them)?
    ``max_null``: null vertices a path may record (-1: :class:`LightTracer` chooses from the scene);
    ``outer_medium``: the medium of the region reaching infinity (set by :class:`LightTracer`);
    ``keep_escaped``: record paths that leave the scene from their emitter too (no edge, no photon:
    estimators never need them; tests of the emitter sampling do)."""
    max_vertices: int
    rr_depth: int
    threshold: float
    want_caustic: bool
    want_other: bool
    want_volume: bool = False
    max_null: int = -1
    outer_medium: int = -1
    keep_escaped: bool = False


ZERO3 = (0.0, 0.0, 0.0)


@inlined
def _put(rec, k, p, ng, ns, d):
    for c in range(3):
        rec.pos[k, c] = p[c]
        rec.nrm[k, c] = ng[c]
        rec.nsh[k, c] = ns[c]
        rec.d_in[k, c] = d[c]


@inlined
def _put_meta(rec, k, beta, pdf_fwd, kind, obj, prim, flags):
    for c in range(3):
        rec.beta[k, c] = beta[c]
    rec.pdf_fwd[k] = pdf_fwd
    rec.pdf_rev[k] = 0.0
    rec.kind[k] = kind
    rec.obj[k] = obj
    rec.prim[k] = prim
    rec.lobe[k] = -1
    rec.flags[k] = flags


@inlined
def _put_link(rec, k, parent, j, depth, medium):
    rec.parent[k] = parent
    rec.path[k] = j
    rec.depth[k] = depth
    rec.medium[k] = medium


@inlined
def _adjoint_weight(mat, w, wi, wo, wi_w, wo_w, ng, ns):
    """The importance-transport weight from bsdf_sample's radiance weight ``w`` (module docstring)."""
    e = bsdf_eta(mat, wi, wo)
    den = abs(dot(wi_w, ng)) * abs(dot(wo_w, ns))
    if not den > 0.0:
        return (0.0, 0.0, 0.0)
    s = e * e * abs(dot(wi_w, ns)) * abs(dot(wo_w, ng)) / den
    return (w[0] * s, w[1] * s, w[2] * s)


@inlined
def _mul(a, b):
    return (a[0] * b[0], a[1] * b[1], a[2] * b[2])


# -- emission ------------------------------------------------------------------------------------
@inlined
def _start_medium(sa, prm, prim, n, o, d, stack):
    """The medium the emitted ray (o, d) starts in: -1 in a scene without media; an area emitter on a
    medium transition leaves it on its normal's side (next_medium); anything else is located."""
    if sa.media.shape[0] == 0:
        return -1
    if prim >= 0 and sa.prim_info[prim, INFO_MED_TRANS] != 0:
        return next_medium(sa.prim_info, prim, -1, d, n)
    return locate_medium(sa, o, d, prm.outer_medium, stack)


@inlined
def _emit(sa, cdf, prm, h, j, rec, k, stack):
    """Vertex 0 of light path j (Veach 1997, Sec. 10.2) into row k: returns (ok, o, d, beta,
    pdf_dir, medium), the first ray, its weight Le / pdf, its solid-angle pdf and its medium."""
    u = (rand_at(h, 0), rand_at(h, 1), rand_at(h, 2), rand_at(h, 3), rand_at(h, 4))
    em, prim, p, n, d, beta, pdf_pos, pdf_dir, dpos, ddir = sample_emission(sa, cdf, u)
    if em < 0:
        return False, p, d, beta, 0.0, -1
    o = offset_origin(p, n, d) if prim >= 0 else p
    medium = _start_medium(sa, prm, prim, n, o, d, stack)
    _put(rec, k, p, n, n, d)
    _put_meta(rec, k, beta, pdf_pos, K_EMITTER, em, prim, (F_DELTA_POS if dpos else 0) | (F_DELTA_DIR if ddir else 0))
    _put_link(rec, k, -1, j, 0, medium)
    return True, o, d, beta, pdf_dir, medium


# -- media ---------------------------------------------------------------------------------------
@inlined
def _free_flight(med, t_max, u_ch, u_t):
    """Free-flight sampling on a segment of length t_max (inf: unbounded) inside medium row ``med``:
    (t, scattered, weight, factor) with the weight of ``sample_distance`` and the factor the pdfs
    take: the spectral-MIS collision density at t, or the probability of passing t_max."""
    sig, alb, g = medium_params(med)
    t, scattered, w = sample_distance(sig, alb, t_max, u_ch, u_t)
    if scattered:
        return t, True, w, distance_pdf(sig, t)
    return t, False, w, pass_probability(sig, t_max)


@inlined
def _reverse_factor(sa, medium, parent_kind, t):
    """The free-flight factor of the edge sampled backwards, from the child to its parent at
    distance t: a collision at a medium parent, a pass elsewhere (1 in vacuum)."""
    if medium < 0:
        return 1.0
    sig, alb, g = medium_params(sa.media[medium])
    if parent_kind == K_MEDIUM:
        return distance_pdf(sig, t)
    return pass_probability(sig, t)


@inlined
def _parent_cos(rec, kp, d):
    """|cos| at the parent row kp towards the edge d; 1 where it has no normal (medium, point)."""
    pn = (rec.nrm[kp, 0], rec.nrm[kp, 1], rec.nrm[kp, 2])
    return abs(dot(pn, d)) if (pn[0] != 0.0 or pn[1] != 0.0 or pn[2] != 0.0) else 1.0


@inlined
def _scatter_medium(sa, medium, h, b, d):
    """Henyey-Greenstein sampling at a medium vertex (weight 1): (wo, pdf)."""
    sig, alb, g = medium_params(sa.media[medium])
    return hg_sample(g, (-d[0], -d[1], -d[2]), rand_at(h, b + D_U1), rand_at(h, b + D_U2))


# -- surfaces ------------------------------------------------------------------------------------
@inlined
def _scatter_surface(mat, prm, h, b, d, ng, ns):
    """BSDF sampling at a surface vertex: (ok, wo_w, adjoint weight, pdf, delta, lobe, reverse pdf
    of the sampled pair in solid angle)."""
    s, tt = coordinate_system(ns)
    wi_w = (-d[0], -d[1], -d[2])
    wi = to_local(wi_w, s, tt, ns)
    u_lobe = rand_at(h, b + D_LOBE)
    wo, w, pdf, delta = bsdf_sample(mat, wi, u_lobe, rand_at(h, b + D_U1), rand_at(h, b + D_U2))
    if not pdf > 0.0:
        return False, d, w, pdf, delta, -1, 0.0
    wo_w = to_world(wo, s, tt, ns)
    w = _adjoint_weight(mat, w, wi, wo, wi_w, wo_w, ng, ns)
    lobe = sampled_lobe_class(mat, wi, u_lobe, delta, prm.threshold)
    rev = 0.0 if delta else bsdf_pdf(mat, wo, wi)
    return True, wo_w, w, pdf, delta, lobe, rev


@inlined
def _wanted_surface(prm, mat, k, caustic):
    """Is surface vertex k (k-th scattering vertex) a photon the plan asks for?"""
    return vertex_class(mat, prm.threshold) != L.V_SPECULAR and (
        (k == 1 and prm.want_other) or (k > 1 and (prm.want_caustic if caustic else prm.want_other)))


# -- roulette ------------------------------------------------------------------------------------
@inlined
def _roulette(w, w_edge, k, rr_depth, u):
    """From scattering vertex rr_depth on, survive with q = min(max(w w_edge), 0.95) and divide w by q.
    Returns (alive, w)."""
    if k < rr_depth:
        return True, w
    q = min(max3(_mul(w, w_edge)), 0.95)
    if u >= q:
        return False, w
    return True, (w[0] / q, w[1] / q, w[2] / q)


@inlined
def _medium_vertex(sa, prm, h, rec, j, k, o, d, t, beta, pdf_dir, fac, medium, nsc, w_edge):
    """Record the collision at distance t along (o, d) as scattering vertex nsc (row k, its parent
    row k - 1; sigma_s T / pdf is in beta already), then leave it by phase sampling and roulette.
    Returns (go_on, o, d, beta, pdf_dir) for the next edge."""
    p = (o[0] + t * d[0], o[1] + t * d[1], o[2] + t * d[2])
    kp = k - 1
    _put(rec, k, p, ZERO3, ZERO3, d)
    _put_meta(rec, k, beta, pdf_dir * fac / (t * t), K_MEDIUM, medium, -1, F_PHOTON if prm.want_volume else 0)
    _put_link(rec, k, kp, j, nsc, medium)
    if nsc >= prm.max_vertices:
        return False, p, d, beta, 0.0
    b = DIMS_START + DIMS_PER_BOUNCE * (nsc - 1)
    wo, pdf = _scatter_medium(sa, medium, h, b, d)
    if not pdf > 0.0:
        return False, p, d, beta, 0.0
    rec.lobe[k] = L.V_MEDIUM
    # phase functions are symmetric: the reverse direction has the same pdf
    rec.pdf_rev[kp] = pdf * _reverse_factor(sa, medium, rec.kind[kp], t) * _parent_cos(rec, kp, d) / (t * t)
    if nsc == 1 and not (prm.want_other or prm.want_volume):      # a medium first vertex is no caustic
        return False, p, d, beta, 0.0
    alive, w = _roulette((1.0, 1.0, 1.0), w_edge, nsc, prm.rr_depth, rand_at(h, b + D_RR))
    if not alive:
        return False, p, d, beta, 0.0
    beta = _mul(beta, w)
    return max3(beta) > 0.0, p, wo, beta, pdf


@inlined
def _surface_vertex(sa, prm, h, rec, j, k, prim, p, ng, ns, d, t, beta, pdf_fwd, medium, nsc, caustic, w_edge):
    """Record the hit (p, ng, ns) of primitive ``prim`` as scattering vertex nsc (row k), then leave
    it by BSDF sampling (adjoint weight) and roulette. Returns (go_on, o, d, beta, pdf_dir, medium,
    caustic) for the next edge; ``medium`` is the arriving edge's and becomes the leaving one's."""
    mid = sa.prim_info[prim, INFO_MAT]
    mat = sa.materials[mid]
    kp = k - 1
    store = _wanted_surface(prm, mat, nsc, caustic)
    _put(rec, k, p, ng, ns, d)
    _put_meta(rec, k, beta, pdf_fwd, K_SURFACE, mid, prim, F_PHOTON if store else 0)
    _put_link(rec, k, kp, j, nsc, medium)
    if nsc >= prm.max_vertices:
        return False, p, d, beta, 0.0, medium, caustic
    b = DIMS_START + DIMS_PER_BOUNCE * (nsc - 1)
    ok, wo_w, w, pdf, delta, lobe, rev = _scatter_surface(mat, prm, h, b, d, ng, ns)
    if not ok:
        return False, p, d, beta, 0.0, medium, caustic
    rec.lobe[k] = lobe
    if delta:
        rec.flags[k] |= F_DELTA_OUT
    else:       # reverse pdf of the parent: sampled from here towards it, to area at the parent
        rec.pdf_rev[kp] = rev * _reverse_factor(sa, medium, rec.kind[kp], t) * _parent_cos(rec, kp, d) / (t * t)
    if nsc == 1:     # the first scattering vertex decides caustic (L S ...) or not
        caustic = lobe == L.V_SPECULAR
        if not prm.want_volume and ((caustic and not prm.want_caustic) or (not caustic and not prm.want_other)):
            return False, p, d, beta, 0.0, medium, caustic
    alive, w = _roulette(w, w_edge, nsc, prm.rr_depth, rand_at(h, b + D_RR))
    if not alive:
        return False, p, d, beta, 0.0, medium, caustic
    beta = _mul(beta, w)
    return (max3(beta) > 0.0, offset_origin(p, ng, wo_w), wo_w, beta, pdf,
            next_medium(sa.prim_info, prim, medium, wo_w, ng), caustic)


@noalloc
def trace_one(sa, cdf, prm, seed, pass_index, j, rec, base, stack):
    """Trace light path j of pass ``pass_index`` into rows base, base+1, ... (at most
    max_vertices + 1 + max_null); returns its vertex count."""
    h = path_state(seed, LIGHT_KEY0 + j, pass_index)
    ok, o, d, beta, pdf_dir, medium = _emit(sa, cdf, prm, h, j, rec, base, stack)
    if not ok:
        return 0
    nv, nsc, nnull = 1, 0, 0    # rows written; scattering and null vertices among them
    caustic = False
    after_null = False          # is the current segment's origin a null vertex?
    w_edge = (1.0, 1.0, 1.0)    # free-flight weights since the last scattering vertex
    go_on = True
    while go_on and nsc < prm.max_vertices:
        t, prim, uu, vv = closest_hit_inline(sa.nodes, sa.node_info, sa.prims, sa.prim_info, o, d, 0.0, math.inf,
                                             stack)
        k = base + nv
        scattered = False
        fac = 1.0
        if medium >= 0:
            bd = NULL_DIMS0 + 2 * (nnull - 1) if after_null else DIMS_START + DIMS_PER_BOUNCE * nsc + D_MED_CH
            t, scattered, wf, fac = _free_flight(sa.media[medium], t if prim >= 0 else math.inf, rand_at(h, bd),
                                                 rand_at(h, bd + 1))
            beta = _mul(beta, wf)
            w_edge = _mul(w_edge, wf)
            if not max3(beta) > 0.0:
                break
        if not scattered and prim < 0:
            break
        nv += 1
        if scattered:
            nsc += 1
            go_on, o, d, beta, pdf_dir = _medium_vertex(sa, prm, h, rec, j, k, o, d, t, beta, pdf_dir, fac, medium,
                                                        nsc, w_edge)
            w_edge, after_null = (1.0, 1.0, 1.0), False
            continue
        p, ng, ns = surface(sa.prims, sa.prim_info, prim, o, d, t, uu, vv)
        # area-measure pdf of this vertex: the parent's solid-angle pdf times |cos| / dist^2 (times
        # the pass probability in a medium)
        pdf_fwd = pdf_dir * fac * abs(dot(d, ng)) / (t * t)
        if bsdf_is_null(sa.materials[sa.prim_info[prim, INFO_MAT]]):    # an interface, not a bounce
            if nnull >= prm.max_null:
                nv -= 1
                break
            nnull += 1
            _put(rec, k, p, ng, ns, d)
            _put_meta(rec, k, beta, pdf_fwd, K_SURFACE, sa.prim_info[prim, INFO_MAT], prim, F_DELTA_OUT)
            _put_link(rec, k, k - 1, j, nsc + 1, medium)
            medium = next_medium(sa.prim_info, prim, medium, d, ng)
            o = offset_origin(p, ng, d)
            pdf_dir, after_null = 1.0, True
            continue
        nsc += 1
        go_on, o, d, beta, pdf_dir, medium, caustic = _surface_vertex(sa, prm, h, rec, j, k, prim, p, ng, ns, d, t,
                                                                      beta, pdf_fwd, medium, nsc, caustic, w_edge)
        w_edge, after_null = (1.0, 1.0, 1.0), False
    return nv


@block
def _outer_medium_walk(sa, o, d):
    stack = np.empty(STACK_SIZE, dtype=np.int32)
    return locate_medium(sa, o, d, UNBOUNDED_REGION, stack)


def outer_medium(sa) -> int:
    """The medium of the region that reaches infinity: -1 without media; the camera's where no shape
    is a medium transition (a global medium) or where the camera's own locating walk meets none
    (the camera is in that region); else what a walk from outside the bounding sphere towards its
    centre meets first (its exterior, usually vacuum), vacuum if it meets no transition."""
    if sa.media.shape[0] == 0:
        return -1
    if not (sa.prim_info[:, INFO_MED_TRANS] != 0).any():
        return int(sa.camera_medium)
    d = np.array(_LOCATE_DIR) / np.linalg.norm(_LOCATE_DIR)
    cam = tuple(float(x) for x in sa.camera[CAM_O:CAM_O + 3])
    if int(_outer_medium_walk(sa, cam, tuple(d))) == UNBOUNDED_REGION:
        return int(sa.camera_medium)
    c, r = np.asarray(sa.bsphere[:3], dtype=float), float(sa.bsphere[3])
    o = c + (2.0 * r + 1.0) * d
    m = int(_outer_medium_walk(sa, tuple(o), tuple(-d)))
    return -1 if m == UNBOUNDED_REGION else m


@block
def _borrow_rec(r):
    return LightPaths(borrow(r.pos), borrow(r.nrm), borrow(r.nsh), borrow(r.d_in), borrow(r.beta),
                      borrow(r.pdf_fwd), borrow(r.pdf_rev), borrow(r.kind), borrow(r.obj), borrow(r.prim),
                      borrow(r.lobe), borrow(r.flags), borrow(r.parent), borrow(r.path), borrow(r.depth),
                      borrow(r.medium))


@block
def trace_batch(sa, cdf, prm, seed, pass_index, j0, slots, nv):
    """Light paths j0 .. j0 + len(nv) - 1 into fixed slots (max_vertices + 1 + max_null rows each); ``nv[i]``
    receives path i's vertex count."""
    # borrowed arrays: no atomic reference counts shared by the threads (scene.compile.borrowed)
    _trace_rows(borrowed(sa), cdf, prm, seed, pass_index, j0, _borrow_rec(slots), nv)


#: light paths one prange iteration traces with one BVH stack (a heap allocation per path cost as
#: much as tracing a path that escapes after one segment)
CHUNK = 64


@rows
def _trace_rows(sa, cdf, prm, seed, pass_index, j0, slots, nv):
    per = prm.max_vertices + 1 + prm.max_null
    n = nv.shape[0]
    for c in prange((n + CHUNK - 1) // CHUNK):
        stack = np.empty(STACK_SIZE, dtype=np.int32)
        for i in range(c * CHUNK, min(n, (c + 1) * CHUNK)):
            k = trace_one(sa, cdf, prm, seed, pass_index, j0 + i, slots, i * per, stack)
            # a path that left the scene from its emitter has no edge and no photon: keep nothing
            # (in an open scene most paths do; they still count in the normalisation by n)
            nv[i] = k if k > 1 or prm.keep_escaped else 0


@block
def compact(slots, per, nv, off, out):
    """Copy path i's ``nv[i]`` slot rows to rows off[i] ... of ``out``, parents re-indexed."""
    # borrowed views, as trace_batch: no reference counts shared by the threads
    _compact_rows(_borrow_rec(slots), per, nv, off, _borrow_rec(out))


@rows
def _compact_rows(slots, per, nv, off, out):
    for i in prange(nv.shape[0]):
        _copy_path(slots, i * per, nv[i], off[i], out)


# a function of its own on purpose: written directly in the prange body, stores into the fields of
# a NamedTuple of arrays were lost (numba 0.68's parfor lowering; tests/test_photons_trace.py
# compares the compacted records with the slots)
@block
def _copy_path(slots, s0, n, t0, out):
    for v in range(n):
        s = s0 + v
        t = t0 + v
        for c in range(3):
            out.pos[t, c] = slots.pos[s, c]
            out.nrm[t, c] = slots.nrm[s, c]
            out.nsh[t, c] = slots.nsh[s, c]
            out.d_in[t, c] = slots.d_in[s, c]
            out.beta[t, c] = slots.beta[s, c]
        out.pdf_fwd[t] = slots.pdf_fwd[s]
        out.pdf_rev[t] = slots.pdf_rev[s]
        out.kind[t] = slots.kind[s]
        out.obj[t] = slots.obj[s]
        out.prim[t] = slots.prim[s]
        out.lobe[t] = slots.lobe[s]
        out.flags[t] = slots.flags[s]
        out.parent[t] = t - 1 if v > 0 else -1
        out.path[t] = slots.path[s]
        out.depth[t] = slots.depth[s]
        out.medium[t] = slots.medium[s]


class LightTracer:
    """Traces batches of light paths with preallocated slots (reused across passes).

    ``LightTracer(sa, params, batch=16384).trace(seed, pass_index, j0, n) -> LightPaths`` for
    light paths j0 .. j0 + n - 1; ``threads`` sets numba's thread count while tracing.
    ``self.params`` are the params given with ``max_null`` (if -1) and ``outer_medium`` filled in
    from the scene."""

    def __init__(self, sa, params: TraceParams, batch: int = 16384, threads=None):
        if params.max_null < 0:
            has_null = any(int(r[L.MAT_TYPE]) == L.NULL for r in sa.materials)
            params = params._replace(max_null=2 * (params.max_vertices + 1) if has_null else 0)
        params = params._replace(outer_medium=outer_medium(sa))
        self.sa, self.params, self.threads = sa, params, threads
        self.cdf = emitter_cdf(sa)
        self.per = params.max_vertices + 1 + params.max_null
        self.batch = max(1024, min(int(batch), (1 << 17) // self.per))   # slots ~<= 20 MB
        self.slots = allocate(self.batch * self.per)
        self._per_path = 4.0        # vertices per light path, measured by every call to trace
        self._lent = self._spare = None     # the last output handed out / handed back (recycle)

    def trace(self, seed: int, pass_index: int, j0: int, n: int) -> LightPaths:
        """The records of light paths j0 .. j0 + n - 1 of pass ``pass_index`` (paths that leave from
        their emitter left out unless ``keep_escaped``), in path order."""
        old = numba.get_num_threads()
        if self.threads is not None:
            numba.set_num_threads(int(self.threads))
        try:
            return self._trace(int(seed), int(pass_index), int(j0), int(n))
        finally:
            numba.set_num_threads(old)

    def _trace(self, seed, pass_index, j0, n) -> LightPaths:
        # every batch is compacted straight into one output (no per-batch records to concatenate);
        # its first capacity is the previous call's vertices per path, grown by doubling if short
        want = int(self._per_path * n * 1.05) + 64
        out, total = self._spare, 0
        if out is None or len(out) < want:
            out = allocate(want + want // 4, empty=True)     # slack: the next pass may be longer
        self._spare = None
        for a in range(j0, j0 + n, self.batch):
            m = min(self.batch, j0 + n - a)
            nv = np.zeros(m, dtype=np.int64)
            trace_batch(self.sa, self.cdf, self.params, seed, pass_index, a, self.slots, nv)
            off = total + np.cumsum(nv) - nv          # first output row of each path
            need = total + int(nv.sum())
            if need > len(out):
                out = _grown(out, total, max(need, 2 * len(out)))
            compact(self.slots, self.per, nv, off, out)
            total = need
        self._per_path = total / max(n, 1)
        self._lent = out
        return LightPaths(*(f[:total] for f in out))

    def recycle(self, records: LightPaths) -> None:
        """Hand the records of the last :meth:`LightTracer.trace` back once they are no longer used: the next
        call then writes into the same memory. A pass's records take ~165 B x vertices (150 MB
        for 200k Cornell-box paths), and fresh memory costs a page fault per 4 kB on first touch
        -- measured: compaction into fresh output 4-6x slower than into reused. Records never
        handed back are never overwritten."""
        lent = self._lent
        if lent is not None and len(records) and records.pos.base is lent.pos:
            self._spare, self._lent = lent, None


def _grown(rec: LightPaths, used: int, capacity: int) -> LightPaths:
    """``rec`` with room for ``capacity`` vertices, its first ``used`` rows kept."""
    new = allocate(capacity, empty=True)
    for a, b in zip(new, rec):
        a[:used] = b[:used]
    return new
