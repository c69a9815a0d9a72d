"""Completing the light subpath in GPM's hybrid shift (Hua et al. 2017, Sec. 4.2 Step 2; PHOTONS.md
Sec. 2.5): :func:`parent_factor` re-evaluates a light vertex towards a new direction (the
reconnection to a diffuse or glossy parent, or to the emitter); :func:`project` is Eq. 6's
projection of y* from the parent; :func:`reaches` and :func:`same_point` judge visibility with one
tolerance for a shift and its inverse. A photon whose parent lies on a specular chain is shifted by
the manifold branch (Eq. 7-8), :mod:`gdlearn.integrators.photon.photon_manifold`.
"""
from __future__ import annotations

import math

from gdlearn.kernels import layout as L
from gdlearn.kernels.accel.bvh import closest_hit_inline
from gdlearn.kernels.bsdf.dispatch import bsdf_eval, bsdf_pdf, vertex_class
from gdlearn.kernels.geometry import INFO_MAT, offset_origin, surface
from gdlearn.kernels.jit import block, inlined
from gdlearn.kernels.scene_query import intersect
from gdlearn.kernels.vec import coordinate_system, dot, to_local
from gdlearn.photons.records import K_EMITTER, K_SURFACE
from gdlearn.photons.trace import _adjoint_weight
from gdlearn.integrators.photon.gather import specular_vertex
from gdlearn.shifts.photon import emission_profile



@inlined
def _dir(a, b):
    d = (b[0] - a[0], b[1] - a[1], b[2] - a[2])
    n = math.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
    if not n > 0.0:
        return (0.0, 0.0, 0.0), 0.0
    return (d[0] / n, d[1] / n, d[2] / n), n


#: parent_base's kinds: how the parent y_{s-1} is re-evaluated towards a new direction
P_FAIL, P_EMITTER, P_SURFACE, P_SPECULAR = 0, 1, 2, 3


@block
def parent_factor(sa, lp, q, v, d_new):
    """The parent y_{s-1} = row q re-evaluated towards ``d_new`` (reconnection): returns (status,
    (f'/f per channel), p_w(w') / p_w(w)). status 0: ok, 1: fails, 2: needs the manifold walk (a
    specular parent). The base half (:func:`parent_base`) does not depend on d_new: the camera pass
    computes it once per photon for its four neighbours and calls :func:`parent_offset` per shift."""
    return parent_offset(sa, lp, q, parent_base(sa, lp, q, v), d_new)


@inlined
def parent_base(sa, lp, q, v):
    """The base side of :func:`parent_factor` for photon row v and its parent row q (the reconnection
    of Hua et al. 2017 Sec. 4.2 Step 2): (kind P_*, the base direction y_{s-1} -> y_s, the parent's
    value towards it per channel (emission profile, the same in every channel, or adjoint BSDF
    weight), its sampling density p_w(w)). Independent of the neighbour: once per photon."""
    one = (1.0, 1.0, 1.0)
    yq = (lp.pos[q, 0], lp.pos[q, 1], lp.pos[q, 2])
    # the base direction from the positions, not the stored ray direction (which left from an origin
    # pushed off the surface): the reverse shift computes its direction the same way, so the two
    # density ratios are exact reciprocals and the MIS weights of a pair sum to one (1e-16, not 1e-8)
    d_b, _ = _dir(yq, (lp.pos[v, 0], lp.pos[v, 1], lp.pos[v, 2]))
    nq = (lp.nrm[q, 0], lp.nrm[q, 1], lp.nrm[q, 2])
    if lp.kind[q] == K_EMITTER:
        fb, pb = emission_profile(sa.emitters, lp.obj[q], nq, d_b)
        return P_EMITTER, d_b, (fb, fb, fb), pb
    if lp.kind[q] != K_SURFACE:
        return P_FAIL, d_b, one, 0.0
    if specular_vertex(lp, q):
        return P_SPECULAR, d_b, one, 0.0
    mat = sa.materials[lp.obj[q]]
    ns = (lp.nsh[q, 0], lp.nsh[q, 1], lp.nsh[q, 2])
    s, t = coordinate_system(ns)
    wi_w = (-lp.d_in[q, 0], -lp.d_in[q, 1], -lp.d_in[q, 2])
    wi = to_local(wi_w, s, t, ns)
    wb = to_local(d_b, s, t, ns)
    fb = _adjoint_weight(mat, bsdf_eval(mat, wi, wb), wi, wb, wi_w, d_b, nq, ns)
    return P_SURFACE, d_b, fb, bsdf_pdf(mat, wi, wb)


@inlined
def parent_offset(sa, lp, q, base, d_new):
    """:func:`parent_factor` towards ``d_new`` from its base side ``base`` (:func:`parent_base`):
    the same arithmetic as evaluating both directions together, so the ratios are the same bits."""
    one = (1.0, 1.0, 1.0)
    kind, d_b, fb, pb = base
    nq = (lp.nrm[q, 0], lp.nrm[q, 1], lp.nrm[q, 2])
    if kind == P_EMITTER:
        fo, po = emission_profile(sa.emitters, lp.obj[q], nq, d_new)
        if not (fb[0] > 0.0 and fo > 0.0 and pb > 0.0 and po > 0.0):
            return 1, one, 0.0
        r = fo / fb[0]
        return 0, (r, r, r), po / pb
    if kind == P_SPECULAR:
        return 2, one, 0.0
    if kind != P_SURFACE:
        return 1, one, 0.0
    if not dot(d_b, nq) * dot(d_new, nq) > 0.0:            # the offset must leave on the base's side
        return 1, one, 0.0
    mat = sa.materials[lp.obj[q]]
    ns = (lp.nsh[q, 0], lp.nsh[q, 1], lp.nsh[q, 2])
    s, t = coordinate_system(ns)
    wi_w = (-lp.d_in[q, 0], -lp.d_in[q, 1], -lp.d_in[q, 2])
    wi = to_local(wi_w, s, t, ns)
    wo = to_local(d_new, s, t, ns)
    fo = _adjoint_weight(mat, bsdf_eval(mat, wi, wo), wi, wo, wi_w, d_new, nq, ns)
    po = bsdf_pdf(mat, wi, wo)
    if not (pb > 0.0 and po > 0.0):
        return 1, one, 0.0
    for c in range(3):
        if (fb[c] > 0.0) != (fo[c] > 0.0):                 # a channel only one side carries: refuse both ways
            return 1, one, 0.0
    r = (_ratio(fo[0], fb[0]), _ratio(fo[1], fb[1]), _ratio(fo[2], fb[2]))
    return 0, r, po / pb


@inlined
def _ratio(a, b):
    return a / b if b > 0.0 else 0.0


#: y'_s counts as y*_s (no projection happened) within this fraction of the kernel radius (plus the
#: rounding of spawned rays, :func:`same_point`)
SAME_POINT = 1e-6


@inlined
def same_point(a, b, yq, r):
    """Do two hits of rays from the light vertex yq count as one point? Within a millionth of the
    kernel radius r plus 100 x the push of a spawned ray's origin (geometry.offset_origin: the ray
    starts that far off the surface, so its hit moves by about that over the cosine)."""
    push = 1e-9 * max(abs(yq[0]), max(abs(yq[1]), abs(yq[2]))) + 1e-7
    tol = SAME_POINT * r + 100.0 * push
    e = (a[0] - b[0], a[1] - b[1], a[2] - b[2])
    return e[0] * e[0] + e[1] * e[1] + e[2] * e[2] <= tol * tol


@block
def reaches(sa, a, ng_a, b, r, stack):
    """Does the ray from a (geometric normal ng_a) towards b first hit b, by :func:`same_point`'s
    tolerance? ``(ok, prim, ng, ns)`` of the hit. The shift and its inverse must judge visibility
    with one tolerance: the projection (:func:`project`) accepts a hit within same_point of y*,
    and gpt's ``_segment_reaches`` (POS_TOL of the segment length, ~1e-7) is tighter than the
    displacement the ray origin's push causes, so a pair built from exact points (the offset
    chain of an independent solver, tests/test_gpm_manifold.py) passed one way and failed the
    other on 13 of 400 pairs."""
    d, ln = _dir(a, b)
    if not ln > 0.0:
        return False, -1, a, a
    hit, _, prim, q, ng, ns, _ = intersect(sa, offset_origin(a, ng_a, d), d, 0.0, math.inf, stack)
    if not (hit and same_point(q, b, a, r)):
        return False, -1, a, a
    return True, prim, ng, ns


@inlined
def project(sa, prm, yq, nq, ystar, p2, r, stack):
    """Eq. 6's projection: the first surface the ray from the light vertex yq (normal nq) through y*
    hits, which must hold a photon (not specular) and lie in the offset gather point p2's kernel of
    radius r (PHOTONS.md Sec. 2.6). Returns (ok, direction, y'_s, its geometric normal)."""
    zero = (0.0, 0.0, 0.0)
    d, dl = _dir(yq, ystar)
    if not dl > 0.0:
        return False, d, zero, zero
    o = offset_origin(yq, nq, d)          # a point light's zero normal leaves the origin in place
    t, prim, u, w = closest_hit_inline(sa.nodes, sa.node_info, sa.prims, sa.prim_info, o, d, 0.0, math.inf, stack)
    if prim < 0:
        return False, d, zero, zero
    yh, ngh, _ = surface(sa.prims, sa.prim_info, prim, o, d, t, u, w)
    if vertex_class(sa.materials[sa.prim_info[prim, INFO_MAT]], prm.threshold) == L.V_SPECULAR:
        return False, d, zero, zero                                       # no photon is stored there
    e = (yh[0] - p2[0], yh[1] - p2[1], yh[2] - p2[2])
    if not e[0] * e[0] + e[1] * e[1] + e[2] * e[2] < r * r:
        return False, d, zero, zero
    return True, d, yh, ngh
