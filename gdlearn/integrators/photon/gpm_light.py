"""Completing the light subpath in GPM's hybrid shift (Hua et al. 2017, Sec. 4.2 Step 2; PHOTONS.md
Sec. 2.5): :func:`parent_factor` re-evaluates a light vertex towards a new direction (the
reconnection to a diffuse or glossy parent, or to the emitter); :func:`manifold_photon` is the
manifold branch (Eq. 7-8) for a photon whose parent lies on a specular chain.

The light subpath is y_b -> y_{b+1} .. y_{s-1} -> y_s, with y_b the last non-specular vertex (a
diffuse or glossy surface, or the emitter) and y_{b+1} .. y_{s-1} k = 1..MAX_CHAIN vertices on delta
BSDFs of analytic shapes (spheres, rectangles: ``gdlearn.integrators.path.gpt_surface.manifold.manifold_table``).
The offset photon y'_s is y* (Eq. 5) projected from the base parent y_{s-1}; the Newton walk of
``gdlearn.shifts.manifold.manifold_walk`` (at most 5 iterations, the paper's) then moves the chain
so that it joins the fixed y_b to y'_s with every half vector kept. Jacobian (Eq. 7):

    ``|dy'_{b+1}/dy_{b+1}|`` = ``|dy'_{b+1}/dy'_s|`` ``|dy'_s/dy_s|`` ``|dy_s/dy_{b+1}|``,

the outer factors the generalised geometry ratios of Eq. 8 (``gdlearn.shifts.manifold.chain_endpoint_det``,
the implicit function theorem on the half-vector constraints with y_b fixed), the middle one Eq. 6.
In the solid angle of the direction leaving y_b (what the light tracer sampled) it is multiplied by
(``|cos'_{b+1}|`` / d'^2) / (``|cos_{b+1}|`` / d^2). The offset photon's power, in ratio form:
beta'_s = beta_s [f_b(w') / f_b(w)] J_w prod_j F'_j / F_j (F the delta lobe values of the same
kind, reflection or refraction, at the offset's own angles), and the light side of the MIS ratio
p_w(w') / p_w(w) J_w prod_j P'_j / P_j (P the discrete lobe probabilities).

Refused (the shift fails, weight 1): chains longer than MAX_CHAIN, through a non-analytic shape,
a null interface, an emitter or a non-delta specular lobe (mirrors and smooth glass are walked,
each vertex keeping its lobe: a refraction stays a refraction); a walk that does not converge or walks
back to another chain (near caustics several chains join the same endpoints); an offset chain
that is occluded or leaves its shapes; an offset photon its own parent does not see back to y_s
(the paper's reversibility check), or one the projection moved off y* (its inverse shift, from the
offset's own parent, would not return y_s).
"""
from __future__ import annotations

import math

import numpy as np

from gdlearn.kernels import layout as L
from gdlearn.kernels.accel.bvh import closest_hit_inline
from gdlearn.kernels.bsdf.dispatch import bsdf_eval, bsdf_is_delta_only, bsdf_pdf, vertex_class
from gdlearn.kernels.geometry import INFO_EMITTER, INFO_MAT, offset_origin, surface
from gdlearn.kernels.jit import block, inlined
from gdlearn.kernels.vec import coordinate_system, dot, to_local
from gdlearn.photons.records import F_DELTA_OUT, K_EMITTER, K_SURFACE
from gdlearn.photons.trace import _adjoint_weight
from gdlearn.integrators.photon.gather import specular_vertex
from gdlearn.integrators.path.gpt_surface.manifold import POS_TOL, _same_row
from gdlearn.kernels.scene_query import intersect
from gdlearn.integrators.path.gpt_surface.vertex import same_delta_lobe
from gdlearn.shifts.photon import emission_profile
from gdlearn.shifts import manifold as M
from gdlearn.shifts.photon import projection_jacobian
from gdlearn.shifts.policy import MAX_CHAIN



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


@block
def chain_rows(sa, lp, mtab, q, rows):
    """The specular chain above photon parent ``q``: rows[0] = y_{s-1}, rows[1] = y_{s-2}, ...
    Returns (k, b): the chain length and the row of y_b, or k = 0 if the chain does not qualify."""
    k = 0
    u = q
    while u >= 0 and lp.kind[u] == K_SURFACE and (lp.flags[u] & F_DELTA_OUT) != 0:
        prim = lp.prim[u]
        if k == MAX_CHAIN or prim < 0 or lp.lobe[u] < 0 or mtab[prim, M.SH_TYPE] < 0.0 \
                or sa.prim_info[prim, INFO_EMITTER] >= 0 or not bsdf_is_delta_only(sa.materials[lp.obj[u]]):
            return 0, -1
        rows[k] = u
        k += 1
        u = lp.parent[u]
    if k == 0 or u < 0:
        return 0, -1
    return k, u


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


@block
def _delta_value(mat, ns, w_in, w_out_world, refl):
    """(F per channel, P, ok): the delta lobe of kind ``refl`` at a vertex of shading normal ns, the
    light arriving along w_in (direction of travel), leaving along w_out_world (checked)."""
    s, t = coordinate_system(ns)
    wi = to_local((-w_in[0], -w_in[1], -w_in[2]), s, t, ns)
    wo, wt, pdf, ok = same_delta_lobe(mat, wi, refl)
    if not ok:
        return (0.0, 0.0, 0.0), 0.0, False
    wl = to_local(w_out_world, s, t, ns)
    if not abs(wo[0] - wl[0]) + abs(wo[1] - wl[1]) + abs(wo[2] - wl[2]) <= 1e3 * POS_TOL:   # as gpt's manifold
        return (0.0, 0.0, 0.0), 0.0, False
    return (wt[0] * pdf, wt[1] * pdf, wt[2] * pdf), pdf, True


@block
def manifold_photon(sa, lp, mtab, prm, v, q, ystar, nstar, r, p2, stack):
    """Shift photon row v (parent q on a specular chain) to the offset photon near ``ystar``
    (normal ``nstar``), the offset gather point at p2 with kernel radius r. Returns (ok, photon
    power ratio beta'_s / beta_s per channel, MIS density ratio, arrival direction at y'_s).
    """
    zero = (0.0, 0.0, 0.0)
    rows = np.empty(MAX_CHAIN, dtype=np.int64)
    k, b = chain_rows(sa, lp, mtab, q, rows)
    if k == 0:
        return False, zero, 0.0, zero
    yq = (lp.pos[q, 0], lp.pos[q, 1], lp.pos[q, 2])
    ys = (lp.pos[v, 0], lp.pos[v, 1], lp.pos[v, 2])
    ns_v = (lp.nrm[v, 0], lp.nrm[v, 1], lp.nrm[v, 2])
    # the projection of y* from the base parent (Eq. 6)
    ok, _, yh, ngh = project(sa, prm, yq, (lp.nrm[q, 0], lp.nrm[q, 1], lp.nrm[q, 2]), ystar, p2, r, stack)
    # the photon's own inverse shift must give y_s back: with the projection from the *offset's*
    # parent that holds only when the projection did not move y* (y'_s = y*: Eq. 5 inverts exactly)
    if not (ok and same_point(yh, ystar, yq, r)):
        return False, zero, 0.0, zero
    j6 = projection_jacobian(yq, ystar, nstar, yh, ngh)
    # the chain from y_b's side: X[0] = y_{b+1} .. X[k-1] = y_{s-1}
    X = np.empty((k, 3))
    shapes = np.empty((k, M.SH_WIDTH))
    etas = np.empty(k)
    refr = np.empty(k, dtype=np.bool_)
    for j in range(k):
        row = rows[k - 1 - j]
        child = v if j == k - 1 else rows[k - 2 - j]
        for c in range(3):
            X[j, c] = lp.pos[row, c]
        shapes[j] = mtab[lp.prim[row]]
        etas[j] = sa.materials[lp.obj[row]][L.MAT_ETA]
        n_row = (lp.nrm[row, 0], lp.nrm[row, 1], lp.nrm[row, 2])
        din = (lp.d_in[row, 0], lp.d_in[row, 1], lp.d_in[row, 2])
        dout = (lp.d_in[child, 0], lp.d_in[child, 1], lp.d_in[child, 2])
        refr[j] = dot(din, n_row) * dot(dout, n_row) > 0.0      # travel keeps its side: it crossed
    yb = (lp.pos[b, 0], lp.pos[b, 1], lp.pos[b, 2])
    targets = np.empty((k, 2))
    if not M.half_vector_targets(yb, X, ys, shapes, etas, refr, k, targets):
        return False, zero, 0.0, zero
    Xo = X.copy()
    ok, _, _ = M.manifold_walk(yb, yh, ngh, Xo, shapes, etas, refr, targets, k, M.MAX_ITER, M.MAX_HALVINGS, M.TOL)
    if not ok:
        return False, zero, 0.0, zero
    Xb = Xo.copy()                                  # the walk back must find the base chain again
    ok, _, _ = M.manifold_walk(yb, ys, ns_v, Xb, shapes, etas, refr, targets, k, M.MAX_ITER, M.MAX_HALVINGS, M.TOL)
    if not ok:
        return False, zero, 0.0, zero
    tol = 1e-7 * M.chain_length_scale(yb, X, ys, k)
    for j in range(k):
        for c in range(3):
            if not abs(Xb[j, c] - X[j, c]) <= tol:
                return False, zero, 0.0, zero
    det_b, ok_b = M.chain_endpoint_det(yb, X, ys, ns_v, shapes, etas, refr, targets, k)
    det_o, ok_o = M.chain_endpoint_det(yb, Xo, yh, ngh, shapes, etas, refr, targets, k)
    if not (ok_b and ok_o and j6 > 0.0):
        return False, zero, 0.0, zero
    j_area = det_o * j6 / det_b                     # Eq. 7: |dy'_{b+1} / dy_{b+1}|
    # the offset chain must be what a light path would trace: every segment reaches its vertex
    nb = (lp.nrm[b, 0], lp.nrm[b, 1], lp.nrm[b, 2])
    a, n_a = yb, nb
    nrm_o = np.empty((k, 6))                        # the offset chain's geometric and shading normals
    for j in range(k + 1):
        bj = (Xo[j, 0], Xo[j, 1], Xo[j, 2]) if j < k else yh
        good, pj, ngj, nsj = reaches(sa, a, n_a, bj, r, stack)
        if not good:
            return False, zero, 0.0, zero
        if j < k:
            if not _same_row(mtab, pj, lp.prim[rows[k - 1 - j]]):
                return False, zero, 0.0, zero
            for c in range(3):
                nrm_o[j, c], nrm_o[j, 3 + c] = ngj[c], nsj[c]
        a, n_a = bj, ngj
    # reversibility (Hua et al. 2017 Sec. 4.3): the offset's own parent must see the base photon
    last = (Xo[k - 1, 0], Xo[k - 1, 1], Xo[k - 1, 2])
    if not reaches(sa, last, (nrm_o[k - 1, 0], nrm_o[k - 1, 1], nrm_o[k - 1, 2]), ys, r, stack)[0]:
        return False, zero, 0.0, zero
    # J in the solid angle at y_b
    x1 = (X[0, 0], X[0, 1], X[0, 2])
    x1o = (Xo[0, 0], Xo[0, 1], Xo[0, 2])
    n1 = (lp.nrm[rows[k - 1], 0], lp.nrm[rows[k - 1], 1], lp.nrm[rows[k - 1], 2])
    d1, l1 = _dir(yb, x1)
    d1o, l1o = _dir(yb, x1o)
    c1 = abs(dot(d1, n1))
    c1o = abs(dot(d1o, (nrm_o[0, 0], nrm_o[0, 1], nrm_o[0, 2])))
    if not (c1 > 0.0 and c1o > 0.0):
        return False, zero, 0.0, zero
    j_w = j_area * (c1o / (l1o * l1o)) / (c1 / (l1 * l1))
    status, fr, pr = parent_factor(sa, lp, b, rows[k - 1], d1o)
    if status != 0:
        return False, zero, 0.0, zero
    # the chain's delta lobes at the offset's angles against the base's
    f0, f1, f2, pp = fr[0] * j_w, fr[1] * j_w, fr[2] * j_w, pr * j_w
    w_in_b, w_in_o = d1, d1o
    for j in range(k):
        row = rows[k - 1 - j]
        mat = sa.materials[lp.obj[row]]
        ns_b = (lp.nsh[row, 0], lp.nsh[row, 1], lp.nsh[row, 2])
        nxt_b = ys if j == k - 1 else (X[j + 1, 0], X[j + 1, 1], X[j + 1, 2])
        nxt_o = yh if j == k - 1 else (Xo[j + 1, 0], Xo[j + 1, 1], Xo[j + 1, 2])
        xo_j = (Xo[j, 0], Xo[j, 1], Xo[j, 2])
        xb_j = (X[j, 0], X[j, 1], X[j, 2])
        ns_o = (nrm_o[j, 3], nrm_o[j, 4], nrm_o[j, 5])
        out_b, _ = _dir(xb_j, nxt_b)
        out_o, _ = _dir(xo_j, nxt_o)
        fb, pb, okb = _delta_value(mat, ns_b, w_in_b, out_b, not refr[j])
        fo, po, oko = _delta_value(mat, ns_o, w_in_o, out_o, not refr[j])
        if not (okb and oko and pb > 0.0):
            return False, zero, 0.0, zero
        if (fb[0] > 0.0) != (fo[0] > 0.0) or (fb[1] > 0.0) != (fo[1] > 0.0) or (fb[2] > 0.0) != (fo[2] > 0.0):
            return False, zero, 0.0, zero
        f0 *= fo[0] / fb[0] if fb[0] > 0.0 else 0.0
        f1 *= fo[1] / fb[1] if fb[1] > 0.0 else 0.0
        f2 *= fo[2] / fb[2] if fb[2] > 0.0 else 0.0
        pp *= po / pb
        w_in_b, w_in_o = out_b, out_o
    return True, (f0, f1, f2), pp, w_in_o
