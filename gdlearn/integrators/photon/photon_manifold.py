"""The manifold branch of a photon shift: a photon whose parent lies on a specular chain (Hua et al.
2017, Sec. 4.2 Step 2, Eq. 7-8; PHOTONS.md Sec. 2.5) -- a surface photon, :func:`manifold_photon`,
or a volume photon (Gruson et al. 2018, Sec. 4.3), :func:`manifold_volume_photon`.

The light subpath is y_b -> y_{b+1} .. y_{s-1} -> y_s, with y_b the last non-specular vertex (a
diffuse or glossy surface, or the emitter) and y_{b+1} .. y_{s-1} k = 1..MAX_CHAIN vertices on delta
BSDFs of analytic shapes (spheres, rectangles: ``gdlearn.integrators.path.gpt_surface.manifold.manifold_table``).
The offset photon y'_s is given (a surface photon: y* of Eq. 5 projected from the base parent y_{s-1},
Eq. 6; a volume photon: b' of the photon shift, Eq. 16); the Newton walk of
``gdlearn.shifts.manifold.manifold_walk`` (at most 5 iterations, the paper's) then moves the chain
so that it joins the fixed y_b to y'_s with every half vector kept. Jacobian (Eq. 7):

    ``|dy'_{b+1}/dy_{b+1}|`` = ``|dy'_{b+1}/dy'_s|`` ``|dy'_s/dy_s|`` ``|dy_s/dy_{b+1}|``,

the outer factors the generalised geometry ratios of Eq. 8 (``gdlearn.shifts.manifold.chain_endpoint_det``,
the implicit function theorem on the half-vector constraints with y_b fixed), the middle one Eq. 6
for a surface photon and 1 for a volume photon (Gruson et al. 2018 Eq. 16 moves b in volume measure
with unit Jacobian). At a volume photon the endpoint's chart is the plane across the last segment
(``ne`` = its direction): moving b along the segment leaves the chain unchanged, so the volume
element dV = dA_perp dt and the distance t sampled from y_{s-1} is shared by the map's two sides.
In the solid angle of the direction leaving y_b (what the light tracer sampled) the Jacobian is
multiplied by (``|cos'_{b+1}|`` / d'^2) / (``|cos_{b+1}|`` / d^2). The offset photon's power, in ratio
form: beta'_s = beta_s [f_b(w') / f_b(w)] J_w prod_j F'_j / F_j (F the delta lobe values of the same
kind, reflection or refraction, at the offset's own angles) -- times T(l') / T(l) of the last edge for
a volume photon --, and the light side of the MIS ratio p_w(w') / p_w(w) J_w prod_j P'_j / P_j (P the
discrete lobe probabilities) -- times the tracer's collision densities p_l(l') / p_l(l) for a volume
photon.

Refused (the shift fails, weight 1): chains longer than MAX_CHAIN, through a non-analytic shape,
a null interface, an emitter or a non-delta specular lobe (mirrors and smooth glass are walked,
each vertex keeping its lobe: a refraction stays a refraction); a walk that does not converge or walks
back to another chain (near caustics several chains join the same endpoints); an offset chain
that is occluded or leaves its shapes; for a surface photon, an offset photon its own parent does not
see back to y_s (the paper's reversibility check), or one the projection moved off y* (its inverse
shift, from the offset's own parent, would not return y_s); for a volume photon, a chain not in vacuum
(the walk carries no transmittance) or a last edge that crosses another number of null interfaces or
meets a surface before b' (:func:`gdlearn.integrators.photon.gvpm_light.edge_walk`, the whole segment).
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from gdlearn.kernels import layout as L
from gdlearn.kernels.bsdf.dispatch import bsdf_is_delta_only
from gdlearn.kernels.geometry import INFO_EMITTER, offset_origin
from gdlearn.kernels.jit import block, ir_inline
from gdlearn.kernels.vec import coordinate_system, dot, to_local
from gdlearn.photons.records import F_DELTA_OUT, K_SURFACE
from gdlearn.integrators.path.gpt_surface.manifold import POS_TOL, _same_row
from gdlearn.integrators.path.gpt_surface.vertex import same_delta_lobe
from gdlearn.integrators.photon.gpm_light import _dir, parent_factor, project, reaches, same_point
from gdlearn.integrators.photon.gvpm_light import FAIL, FAIL_SPECULAR, OK, edge_walk, reconnect_edge
from gdlearn.shifts import manifold as M
from gdlearn.shifts.photon import projection_jacobian
from gdlearn.shifts.policy import MAX_CHAIN

_ZERO = (0.0, 0.0, 0.0)


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


@block
def _delta_value(mat, ns, w_in, w_out_world, refl, loose):
    """(F per channel, P, ok): the delta lobe of kind ``refl`` at a vertex of shading normal ns, the
    light arriving along w_in (direction of travel), leaving along w_out_world (checked, unless
    ``loose``: a relaxed walk's last event)."""
    s, t = coordinate_system(ns)
    wi = to_local((-w_in[0], -w_in[1], -w_in[2]), s, t, ns)
    wo, wt, pdf, ok = same_delta_lobe(mat, wi, refl)
    if not ok:
        return (0.0, 0.0, 0.0), 0.0, False
    wl = to_local(w_out_world, s, t, ns)
    if not (loose or abs(wo[0] - wl[0]) + abs(wo[1] - wl[1]) + abs(wo[2] - wl[2]) <= 1e3 * POS_TOL):  # as gpt's
        return (0.0, 0.0, 0.0), 0.0, False
    return (wt[0] * pdf, wt[1] * pdf, wt[2] * pdf), pdf, True


@block
def load_chain_into(sa, lp, mtab, v, rows, k, X, shapes, etas, refr):
    """The chain from y_b's side, X[0] = y_{b+1} .. X[k-1] = y_{s-1}, with each vertex's shape row,
    relative index and event (True: a refraction) as the base path took it, into the first k rows."""
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


@block
def load_chain(sa, lp, mtab, v, rows, k):
    """:func:`load_chain_into` new arrays of k rows: (X, shapes, etas, refr)."""
    X = np.empty((k, 3))
    shapes = np.empty((k, M.SH_WIDTH))
    etas = np.empty(k)
    refr = np.empty(k, dtype=np.bool_)
    load_chain_into(sa, lp, mtab, v, rows, k, X, shapes, etas, refr)
    return X, shapes, etas, refr


@block
def base_sensitivity(yb, X, ys, ns, shapes, etas, refr, k, targets, A, S):
    """The base chain's half-vector targets (into ``targets``), S = A^-1 B (``S``; A scratch) and
    Eq. 8's ``|dy_{b+1}/dy_s|``, y_s moving in the chart of normal ns: (ok, det_b). The sensitivity
    that predicts a walk's start (``gdlearn.shifts.manifold.predicted_walk``) is the one Eq. 8 takes."""
    if not M.half_vector_targets(yb, X, ys, shapes, etas, refr, k, targets):
        return False, 0.0
    det_b, ok = M.endpoint_sensitivity(yb, X, ys, ns, shapes, etas, refr, targets, k, A, S)
    return ok, det_b


@block
def walk_forward(yb, X, ys, ns, ye, shapes, etas, refr, k):
    """Walk the base chain X (y_b .. y_s, y_s moving in the chart of normal ns) to the offset
    endpoint ye, from the first-order predicted chain (``gdlearn.shifts.manifold.predicted_walk``).
    Returns (ok, offset chain X', the base's half-vector targets, Eq. 8's ``|dy_{b+1}/dy_s|`` of
    the base chain)."""
    m = 2 * k
    targets = np.empty((k, 2))
    S = np.empty((m, 2))
    Xo = X.copy()
    ok, det_b = base_sensitivity(yb, X, ys, ns, shapes, etas, refr, k, targets, np.empty((m, m)), S)
    if not ok:
        return False, Xo, targets, 0.0
    ok, _, _ = M.predicted_walk(yb, X, ys, ns, ye, S, shapes, etas, refr, targets, k, Xo, None)
    return ok, Xo, targets, det_b


@block
def walks_back(yb, X, ys, Xo, ye, ne, shapes, etas, refr, targets, k):
    """The offset chain Xo (endpoint ye in the chart of normal ne) walked back to y_s as the reverse
    shift would walk it -- from its own predicted start -- must find the base chain X again (near a
    caustic several chains join the same endpoints: the shift would not be invertible). Returns
    (ok, Eq. 8's ``|dy'_{b+1}/dy'_s|`` of the offset chain)."""
    m = 2 * k
    S = np.empty((m, 2))
    det_o, ok = M.endpoint_sensitivity(yb, Xo, ye, ne, shapes, etas, refr, targets, k, np.empty((m, m)), S)
    if not ok:
        return False, 0.0
    Xb = np.empty((k, 3))
    ok, _, _ = M.predicted_walk(yb, Xo, ye, ne, ys, S, shapes, etas, refr, targets, k, Xb, None)
    if not (ok and M.same_chain(yb, X, ys, Xb, k)):
        return False, 0.0
    return True, det_o


@block
def offset_chain_normals(sa, lp, mtab, rows, k, yb, nb, Xo, r, stack):
    """The offset chain must be what a light path would trace: y_b -> y'_{b+1} .. -> y'_{s-1}, each
    segment reaching its vertex on the base vertex's shape. Returns (ok, normals): per vertex the
    geometric (0:3) and shading (3:6) normal of the hit."""
    a, n_a = yb, nb
    nrm_o = np.empty((k, 6))
    for j in range(k):
        bj = (Xo[j, 0], Xo[j, 1], Xo[j, 2])
        good, pj, ngj, nsj = reaches(sa, a, n_a, bj, r, stack)
        if not (good and _same_row(mtab, pj, lp.prim[rows[k - 1 - j]])):
            return False, nrm_o
        for c in range(3):
            nrm_o[j, c], nrm_o[j, 3 + c] = ngj[c], nsj[c]
        a, n_a = bj, ngj
    return True, nrm_o


@block
def yb_of(lp, b):
    return (lp.pos[b, 0], lp.pos[b, 1], lp.pos[b, 2])


@block
def chain_ratios(sa, lp, rows, k, b, yb, X, Xo, ys, ye, nrm_o, refr, j_area, relaxed):
    """The offset light subpath over the base's, given the area Jacobian ``j_area`` at y_{b+1}: J in
    the solid angle at y_b, y_b's value and density towards the offset chain, every delta lobe at
    the offset's angles. Returns (ok, (f'/f per channel) J_w, (p'/p) J_w, the arrival direction at y'_s).
    ``relaxed``: the last event may leave towards y'_s off its delta direction (a relaxed walk,
    :func:`shift_volume_chain`); its lobe is valued at its incoming angle."""
    x1 = (X[0, 0], X[0, 1], X[0, 2])
    x1o = (Xo[0, 0], Xo[0, 1], Xo[0, 2])
    n1 = (lp.nrm[rows[k - 1], 0], lp.nrm[rows[k - 1], 1], lp.nrm[rows[k - 1], 2])
    d1, l1 = _dir(yb, x1)
    d1o, l1o = _dir(yb, x1o)
    c1 = abs(dot(d1, n1))
    c1o = abs(dot(d1o, (nrm_o[0, 0], nrm_o[0, 1], nrm_o[0, 2])))
    if not (c1 > 0.0 and c1o > 0.0):
        return False, _ZERO, 0.0, _ZERO
    j_w = j_area * (c1o / (l1o * l1o)) / (c1 / (l1 * l1))
    status, fr, pr = parent_factor(sa, lp, b, rows[k - 1], d1o)
    if status != 0:
        return False, _ZERO, 0.0, _ZERO
    f0, f1, f2, pp = fr[0] * j_w, fr[1] * j_w, fr[2] * j_w, pr * j_w
    w_in_b, w_in_o = d1, d1o
    for j in range(k):
        row = rows[k - 1 - j]
        mat = sa.materials[lp.obj[row]]
        ns_b = (lp.nsh[row, 0], lp.nsh[row, 1], lp.nsh[row, 2])
        nxt_b = ys if j == k - 1 else (X[j + 1, 0], X[j + 1, 1], X[j + 1, 2])
        nxt_o = ye if j == k - 1 else (Xo[j + 1, 0], Xo[j + 1, 1], Xo[j + 1, 2])
        ns_o = (nrm_o[j, 3], nrm_o[j, 4], nrm_o[j, 5])
        out_b, _ = _dir((X[j, 0], X[j, 1], X[j, 2]), nxt_b)
        out_o, _ = _dir((Xo[j, 0], Xo[j, 1], Xo[j, 2]), nxt_o)
        fb, pb, okb = _delta_value(mat, ns_b, w_in_b, out_b, not refr[j], False)
        fo, po, oko = _delta_value(mat, ns_o, w_in_o, out_o, not refr[j], relaxed and j == k - 1)
        if not (okb and oko and pb > 0.0):
            return False, _ZERO, 0.0, _ZERO
        if (fb[0] > 0.0) != (fo[0] > 0.0) or (fb[1] > 0.0) != (fo[1] > 0.0) or (fb[2] > 0.0) != (fo[2] > 0.0):
            return False, _ZERO, 0.0, _ZERO
        f0 *= fo[0] / fb[0] if fb[0] > 0.0 else 0.0
        f1 *= fo[1] / fb[1] if fb[1] > 0.0 else 0.0
        f2 *= fo[2] / fb[2] if fb[2] > 0.0 else 0.0
        pp *= po / pb
        w_in_b, w_in_o = out_b, out_o
    return True, (f0, f1, f2), pp, w_in_o


@block
def manifold_photon(sa, lp, mtab, prm, v, q, ystar, nstar, r, p2, stack):
    """Shift the surface photon row v (parent q on a specular chain) to the offset photon near
    ``ystar`` (normal ``nstar``), the offset gather point at p2 with kernel radius r. Returns (ok,
    photon power ratio beta'_s / beta_s per channel, MIS density ratio, arrival direction at y'_s)."""
    rows = np.empty(MAX_CHAIN, dtype=np.int64)
    k, b = chain_rows(sa, lp, mtab, q, rows)
    if k == 0:
        return False, _ZERO, 0.0, _ZERO
    yq = (lp.pos[q, 0], lp.pos[q, 1], lp.pos[q, 2])
    ys = (lp.pos[v, 0], lp.pos[v, 1], lp.pos[v, 2])
    ns_v = (lp.nrm[v, 0], lp.nrm[v, 1], lp.nrm[v, 2])
    # the projection of y* from the base parent (Eq. 6)
    ok, _, yh, ngh = project(sa, prm, yq, (lp.nrm[q, 0], lp.nrm[q, 1], lp.nrm[q, 2]), ystar, p2, r, stack)
    # the photon's own inverse shift must give y_s back: with the projection from the *offset's*
    # parent that holds only when the projection did not move y* (y'_s = y*: Eq. 5 inverts exactly)
    if not (ok and same_point(yh, ystar, yq, r)):
        return False, _ZERO, 0.0, _ZERO
    j6 = projection_jacobian(yq, ystar, nstar, yh, ngh)
    X, shapes, etas, refr = load_chain(sa, lp, mtab, v, rows, k)
    yb = yb_of(lp, b)
    ok, Xo, targets, det_b = walk_forward(yb, X, ys, ns_v, yh, shapes, etas, refr, k)
    if not ok:
        return False, _ZERO, 0.0, _ZERO
    ok, det_o = walks_back(yb, X, ys, Xo, yh, ngh, shapes, etas, refr, targets, k)
    if not (ok and j6 > 0.0):
        return False, _ZERO, 0.0, _ZERO
    j_area = det_o * j6 / det_b                     # Eq. 7: |dy'_{b+1} / dy_{b+1}|
    ok, nrm_o = offset_chain_normals(sa, lp, mtab, rows, k, yb, (lp.nrm[b, 0], lp.nrm[b, 1], lp.nrm[b, 2]), Xo, r,
                                     stack)
    last = (Xo[k - 1, 0], Xo[k - 1, 1], Xo[k - 1, 2])
    n_last = (nrm_o[k - 1, 0], nrm_o[k - 1, 1], nrm_o[k - 1, 2])
    # the last segment reaches y'_s, and (reversibility, Hua et al. 2017 Sec. 4.3) the offset's own
    # parent sees the base photon
    if not (ok and reaches(sa, last, n_last, yh, r, stack)[0] and reaches(sa, last, n_last, ys, r, stack)[0]):
        return False, _ZERO, 0.0, _ZERO
    return chain_ratios(sa, lp, rows, k, b, yb, X, Xo, ys, yh, nrm_o, refr, j_area, False)


@block
def _in_vacuum(lp, rows, k):
    """Does every segment of the chain y_b -> .. -> y_{s-1} run in vacuum? (The walk carries no
    transmittance; the last edge y_{s-1} -> b is walked with its media by edge_walk.)"""
    for j in range(k):
        if lp.medium[rows[j]] >= 0:
            return False
    return True


#: ``walk`` of gvpm and gbre: how a volume photon's specular chain is walked (:func:`shift_volume_chain`)
WALKS = ("relaxed", "exact")


def relaxed_walk(name: str, walk: str) -> bool:
    """Whether ``name`` (gvpm, gbre) walks volume photons' chains relaxed (``walk`` "relaxed") or
    exactly ("exact", the default). The relaxed walk is Gruson et al. 2018's default (Sec. 6.1),
    consistent as the radius shrinks; measured at equal time on the volume caustic, its bias cost
    more than its extra shifts bought (benchmarks/README.md, "The relaxed walk")."""
    if walk not in WALKS:
        raise ValueError(f"{name}: walk={walk!r}; choose exact (converged and reversible: unbiased at a fixed "
                         "radius) or relaxed (Gruson et al. 2018 Sec. 6.1: accepted inside the offset kernel, "
                         "biased, consistent as the radius shrinks)")
    return walk == "relaxed"


class VolumeChain(NamedTuple):
    """A volume photon's specular chain and what its shifts share (:func:`volume_chain`): built once
    per photon, walked for each neighbour (:func:`shift_volume_chain`). Arrays of MAX_CHAIN rows,
    the first k used; allocated once per camera-pass row (:func:`new_volume_chain`)."""
    state: np.ndarray     # (3,) int64: CHAIN_UNKNOWN / CHAIN_OK / CHAIN_FAIL, k, the row of y_b
    rows: np.ndarray      # (MAX_CHAIN,) int64: chain_rows' rows, y_{s-1} first
    X: np.ndarray         # (MAX_CHAIN, 3): the chain from y_b's side
    shapes: np.ndarray    # (MAX_CHAIN, SH_WIDTH)
    etas: np.ndarray      # (MAX_CHAIN,)
    refr: np.ndarray      # (MAX_CHAIN,) bool
    targets: np.ndarray   # (MAX_CHAIN, 2): the base's half-vector components
    S: np.ndarray         # (2 MAX_CHAIN, 2): A^-1 B at the base chain (shifts.manifold.endpoint_sensitivity)
    A: np.ndarray         # (2 MAX_CHAIN, 2 MAX_CHAIN): scratch
    det: np.ndarray       # (1,): Eq. 8's |dy_{b+1}/dy_s| of the base chain


#: VolumeChain.state[0]
CHAIN_UNKNOWN, CHAIN_OK, CHAIN_FAIL = 0, 1, 2


@block
def new_volume_chain():
    """An empty :class:`VolumeChain` (state CHAIN_UNKNOWN), its arrays sized for MAX_CHAIN vertices."""
    m = 2 * MAX_CHAIN
    return VolumeChain(np.zeros(3, dtype=np.int64), np.empty(MAX_CHAIN, dtype=np.int64), np.empty((MAX_CHAIN, 3)),
                       np.empty((MAX_CHAIN, M.SH_WIDTH)), np.empty(MAX_CHAIN), np.empty(MAX_CHAIN, dtype=np.bool_),
                       np.empty((MAX_CHAIN, 2)), np.empty((m, 2)), np.empty((m, m)), np.empty(1))


@block
def volume_chain(sa, lp, mtab, v, edge, ch):
    """Fill ``ch`` for volume photon row v whose recorded edge a -> b is ``edge``
    (:func:`gdlearn.integrators.photon.gvpm_light.base_edge`): its chain (:func:`chain_rows`; in
    vacuum), targets, sensitivity and determinant, the endpoint's chart across its last segment
    (module docstring). ch.state[0] says whether it can be walked."""
    ch.state[0] = CHAIN_FAIL
    st, q = edge[0], edge[1]
    if st != OK:                 # the recorded edge itself could not be walked: no densities to compare
        return
    k, b = chain_rows(sa, lp, mtab, q, ch.rows)
    if k == 0 or not _in_vacuum(lp, ch.rows, k):
        return
    load_chain_into(sa, lp, mtab, v, ch.rows, k, ch.X, ch.shapes, ch.etas, ch.refr)
    ys = (lp.pos[v, 0], lp.pos[v, 1], lp.pos[v, 2])
    w_b, _ = _dir((lp.pos[q, 0], lp.pos[q, 1], lp.pos[q, 2]), ys)
    ok, det_b = base_sensitivity(yb_of(lp, b), ch.X, ys, w_b, ch.shapes, ch.etas, ch.refr, k, ch.targets, ch.A, ch.S)
    if ok:
        ch.state[0], ch.state[1], ch.state[2] = CHAIN_OK, k, b
        ch.det[0] = det_b


@ir_inline
def shift_volume_chain(sa, lp, mtab, v, b_off, edge, r, ch, stack, relax):
    """Shift the volume photon row v, whose parent a = y_{s-1} lies on the specular chain ``ch``
    (:func:`volume_chain`, state CHAIN_OK), to ``b_off`` (module docstring). Returns what
    gvpm_light.reconnect_edge does: (status, beta_b' / beta_b per channel, light-side density ratio
    p(b') / p(b), the direction b' is reached along).

    ``relax`` = (d', r_relax): with r_relax > 0, Gruson et al. 2018's relaxed walk (Sec. 6.1;
    :mod:`gdlearn.shifts.specular_trace`): accepted once its traced chain ends within r_relax of b'
    and of the offset gather point d', evaluated with that chain (the last event off by at most the
    kernel's angle), and without the reversibility walk (the reference code drops it when r > 0):
    biased, consistent as the radius shrinks. r_relax = 0: the exact, reversible walk."""
    _, q, child, n_null, tau_b, logp_b = edge
    k, b = ch.state[1], ch.state[2]
    X, shapes, etas, refr, targets = ch.X, ch.shapes, ch.etas, ch.refr, ch.targets
    ys = (lp.pos[v, 0], lp.pos[v, 1], lp.pos[v, 2])
    w_b, _ = _dir((lp.pos[q, 0], lp.pos[q, 1], lp.pos[q, 2]), ys)
    yb = yb_of(lp, b)
    Xo = np.empty((k, 3))
    relaxed = relax[1] > 0.0
    ok, _, _ = M.predicted_walk(yb, X, ys, w_b, b_off, ch.S, shapes, etas, refr, targets, k, Xo, relax)
    if not ok:
        return FAIL, _ZERO, 0.0, _ZERO
    # each endpoint's chart lies across its own last segment (module docstring)
    a_o = (Xo[k - 1, 0], Xo[k - 1, 1], Xo[k - 1, 2])
    w_o, l_o = _dir(a_o, b_off)
    if not l_o > 0.0:
        return FAIL, _ZERO, 0.0, _ZERO
    if relaxed:
        det_o, ok = M.chain_endpoint_det(yb, Xo, b_off, w_o, shapes, etas, refr, targets, k)
    else:
        ok, det_o = walks_back(yb, X, ys, Xo, b_off, w_o, shapes, etas, refr, targets, k)
    if not ok:
        return FAIL, _ZERO, 0.0, _ZERO
    ok, nrm_o = offset_chain_normals(sa, lp, mtab, ch.rows, k, yb, (lp.nrm[b, 0], lp.nrm[b, 1], lp.nrm[b, 2]), Xo, r,
                                     stack)
    if not ok:
        return FAIL, _ZERO, 0.0, _ZERO
    # the last edge a' -> b' through the same null interfaces into the same medium, visible throughout
    n_a = (nrm_o[k - 1, 0], nrm_o[k - 1, 1], nrm_o[k - 1, 2])
    ok, n_o, tau_o, logp_o, med_o = edge_walk(sa, a_o, offset_origin(a_o, n_a, w_o), w_o, b_off, lp.medium[child],
                                              stack)
    if not (ok and n_o == n_null and med_o == lp.medium[v]):
        return FAIL, _ZERO, 0.0, _ZERO
    ok, f3, pp, w_in = chain_ratios(sa, lp, ch.rows, k, b, yb, X, Xo, ys, b_off, nrm_o, refr, det_o / ch.det[0],
                                    relaxed)
    if not ok:
        return FAIL, _ZERO, 0.0, _ZERO
    # T(a', b') / T(a, b) per channel and the tracer's collision densities, as gvpm_light.reconnect_edge
    f3 = (f3[0] * math.exp(tau_b[0] - tau_o[0]), f3[1] * math.exp(tau_b[1] - tau_o[1]),
          f3[2] * math.exp(tau_b[2] - tau_o[2]))
    return OK, f3, pp * math.exp(logp_o - logp_b), w_in


@block
def manifold_volume_photon(sa, lp, mtab, v, b_off, edge, r, stack, relax):
    """Shift the volume photon row v, whose parent a = y_{s-1} (``edge``: its recorded edge a -> b,
    :func:`gdlearn.integrators.photon.gvpm_light.base_edge`) lies on a specular chain, to ``b_off``:
    :func:`volume_chain` then :func:`shift_volume_chain` (a camera pass with several neighbours per
    photon builds the chain once; ``relax`` as there)."""
    ch = new_volume_chain()
    volume_chain(sa, lp, mtab, v, edge, ch)
    if ch.state[0] != CHAIN_OK:
        return FAIL, _ZERO, 0.0, _ZERO
    return shift_volume_chain(sa, lp, mtab, v, b_off, edge, r, ch, stack, relax)


@ir_inline
def complete_volume_photon(sa, lp, mtab, v, b_off, edge, r, ch, stack, relax):
    """The light subpath of volume photon row v moved to ``b_off`` (Gruson et al. 2018, Sec. 4.3):
    reconnected from its parent (:func:`gdlearn.integrators.photon.gvpm_light.reconnect_edge`), or,
    when the parent is specular, by the manifold walk (:func:`shift_volume_chain`) of the chain
    ``ch``, built at the first neighbour that needs it (the caller sets ch.state[0] to
    CHAIN_UNKNOWN for each new photon). Returns reconnect_edge's tuple and whether the walk
    completed it; ``relax`` = (the offset gather point d', the relaxed walk's radius, 0 for the exact
    walk): :func:`shift_volume_chain`. IR-inlined, as :func:`shift_volume_chain`: G-VPM's and
    G-BRE's camera passes call it once, per photon and neighbour, and each level numba compiles on its
    own is compiled again inside every caller (``kernels/jit.py``)."""
    status, f3, rl, w_in = reconnect_edge(sa, lp, v, b_off, stack, edge)
    if status != FAIL_SPECULAR:
        return status, f3, rl, w_in, False
    if ch.state[0] == CHAIN_UNKNOWN:
        volume_chain(sa, lp, mtab, v, edge, ch)
    if ch.state[0] != CHAIN_OK:
        return FAIL, _ZERO, 0.0, _ZERO, True
    status, f3, rl, w_in = shift_volume_chain(sa, lp, mtab, v, b_off, edge, r, ch, stack, relax)
    return status, f3, rl, w_in, True
