"""Manifold exploration inside gradient-domain path tracing (policy ``halfvector+reconnection+manifold``;
STAR, Hua et al. 2019, Sec. 3.4; GPM 2017 Eq. 7-8; Jakob & Marschner 2012). The lockstep loop that
calls it is :mod:`gdlearn.integrators.path.gpt_surface.lockstep`; the Newton walk and its Jacobian are
:func:`gdlearn.shifts.manifold.manifold_shift`.

When the base path leaves a connectable vertex x_b (a non-delta lobe) towards a specular vertex, the
chain x_{b+1} .. x_{c-1} up to the next connectable vertex x_c is *looked ahead*: the base's own later
decisions are drawn from counter-based random numbers, so :func:`lookahead_chain` traces exactly the
vertices the base will visit. The chain qualifies (Q) when it has 1..MAX_CHAIN vertices, each on an
analytic shape of the manifold table (sphere, rectangle), with a delta-only material and no emitter,
and x_c is a connectable surface vertex. Then every free offset at x'_b is moved at once: the walk
joins x'_b to x_c through the chain's shapes; the offset waits (``I_PENDING`` segments) until the base
reaches x_c and continues there as a reconnected (JOINED) path. Q is a property of the path's structure
(shapes, lobe kinds, length), which the manifold offset shares; a chain that does not qualify is
half-vector copied, and the copy must then stay on the base's shapes (:func:`same_shape`), so the
offset's chain does not qualify either: forward and backward shifts choose the same action.

Measure and Jacobian. The base's free variable at x_b is the solid angle of the direction to x_1;
manifold_shift gives |dx'_1/dx_1| in area, converted to solid angle by cos theta_1 / d^2 at each path
(Veach Eq. 8.10). At the chain's delta vertices the offset evaluates its own delta lobe of the same
kind (reflection or refraction); those densities are the discrete lobe probabilities (J = 1). An
offset chain that is occluded, off its finite shape, or walks back to another base chain
(irreversible, near caustics) fails (weight 1, STAR Sec. 3.5), counted as ``manifold failed``.
"""
import math

import numpy as np


from gdlearn.kernels import geometry as G
from gdlearn.kernels import layout as L
from gdlearn.kernels.bsdf.dispatch import bsdf_eval, bsdf_is_delta_only, bsdf_pdf, bsdf_sample, lobe_class, vertex_class
from gdlearn.kernels.geometry import offset_origin
from gdlearn.integrators.path.gpt_surface.vertex import (F_NG, F_NS, F_POS, F_PREV_P, F_PREV_PDF, F_WI,
                                                         I_MAT, I_PENDING, I_PREV_DELTA, I_PRIM, I_RECONN, I_STATE,
                                                         JOINED, get3, same_delta_lobe, set3, _update)
from gdlearn.shifts.policy import conn
from gdlearn.kernels.pathclass import pc_push
from gdlearn.kernels.rng import rand
from gdlearn.kernels.scene_query import intersect
from gdlearn.integrators.path.surface import D_BSDF_U1, D_BSDF_U2, D_LOBE, dim
from gdlearn.kernels.vec import coordinate_system, dot, norm, sub, to_local, to_world
from gdlearn.shifts import manifold as M
from gdlearn.shifts.policy import MAX_CHAIN
from gdlearn.kernels.jit import block, leaf, noalloc

#: chain buffer columns (rows 0..m-1: chain vertices, row m: x_c): position, geometric normal,
#: shading normal, base lobe probability, eta of the refraction (1 for a reflection)
C_POS, C_NG, C_NS, C_PDF, C_ETA = 0, 3, 6, 9, 10
NCF = 11
#: int columns: primitive, refraction flag
CI_PRIM, CI_REFR = 0, 1
NCI = 2
#: relative tolerance on positions / directions of the offset chain checked by ray tracing: the walk
#: converges to |c| < 1e-12, ray-surface intersections are exact to ~1e-12 relative; 1e-7 leaves room
POS_TOL = 1e-7


def manifold_table(scene, sa) -> np.ndarray:
    """(n_prims, SH_WIDTH) manifold shape rows (:mod:`gdlearn.shifts.manifold`) of every primitive of
    a *specular analytic* shape -- a sphere (outward normals) or a rectangle with orthogonal axes,
    with a conductor or dielectric BSDF; SH_TYPE = -1 elsewhere (chains over them do not qualify)."""
    n = sa.prim_info.shape[0]
    tab = np.zeros((n, M.SH_WIDTH))
    tab[:, M.SH_TYPE] = -1.0
    for i in range(n):
        shape = scene.shapes[int(sa.prim_info[i, G.INFO_SHAPE])]
        if shape.bsdf is None or shape.bsdf.type not in ("conductor", "dielectric") or shape.flip_normals:
            continue
        m = np.asarray(shape.to_world, dtype=np.float64)
        if shape.type == "sphere":
            tab[i] = M.sphere_row(sa.prims[i, G.G_C:G.G_C + 3], sa.prims[i, G.G_R])
        elif shape.type == "rectangle":
            a, b = m[:3, 0], m[:3, 1]
            if abs(a @ b) > 1e-12 * np.linalg.norm(a) * np.linalg.norm(b):
                continue                       # a sheared quad: not a plane_row
            nrm = np.linalg.inv(m[:3, :3]).T @ np.array([0.0, 0.0, 1.0])
            tab[i] = M.plane_row(m[:3, 3], nrm, a, (np.linalg.norm(a), np.linalg.norm(b)))
    return tab


@noalloc
def lookahead_chain(sa, mtab, nx, rng, depth, cfg, cf, ci, stack):
    """Trace the base's specular chain from its next vertex ``nx`` (hit, prim, p ... reached along d, at
    loop depth ``depth``) with the base's own random numbers (``rng``: :class:`~gdlearn.integrators.path.params.PathRng`). Returns m, the chain length, with the chain
    in cf / ci (rows 0..m-1) and x_c in row m, or 0 if the chain does not qualify (module docstring)."""
    hit, prim, p, ng, ns, d = nx.hit, nx.prim, nx.p, nx.ng, nx.ns, nx.d
    seed, key, s = rng.seed, rng.key, rng.s
    for j in range(MAX_CHAIN + 1):
        if not hit:
            return 0
        mat = sa.materials[sa.prim_info[prim, 1]]
        if conn(vertex_class(mat, cfg.threshold)):
            if j == 0:
                return 0
            set3(cf, j, C_POS, p)
            set3(cf, j, C_NG, ng)
            set3(cf, j, C_NS, ns)
            ci[j, CI_PRIM] = prim
            return j
        if j == MAX_CHAIN or mtab[prim, M.SH_TYPE] < 0.0 or not bsdf_is_delta_only(mat) \
                or sa.prim_info[prim, 2] >= 0 or vertex_class(mat, cfg.threshold) != L.V_SPECULAR:
            return 0
        sf, tf = coordinate_system(ns)
        wi = to_local((-d[0], -d[1], -d[2]), sf, tf, ns)
        dj = depth + j
        wo, _, pdf, _ = bsdf_sample(mat, wi, rand(seed, key, s, dim(dj, D_LOBE)),
                                    rand(seed, key, s, dim(dj, D_BSDF_U1)), rand(seed, key, s, dim(dj, D_BSDF_U2)))
        if not pdf > 0.0:
            return 0
        refr = wi[2] * wo[2] < 0.0
        set3(cf, j, C_POS, p)
        set3(cf, j, C_NG, ng)
        set3(cf, j, C_NS, ns)
        cf[j, C_PDF] = pdf
        cf[j, C_ETA] = mat[L.MAT_ETA] if refr else 1.0
        ci[j, CI_PRIM] = prim
        ci[j, CI_REFR] = 1 if refr else 0
        d = to_world(wo, sf, tf, ns)
        hit, _, prim, p, ng, ns, _ = intersect(sa, offset_origin(p, ng, d), d, 0.0, math.inf, stack)
    return 0


@noalloc
def _segment_reaches(sa, a, ng_a, b, stack):
    """The first hit of the ray from a (normal ng_a) towards b is b itself: ``(ok, prim, ng, ns, dir)``."""
    dv = sub(b, a)
    ln = norm(dv)
    if not ln > 0.0:
        return False, -1, a, a, a
    dr = (dv[0] / ln, dv[1] / ln, dv[2] / ln)
    hit, _, prim, q, ng, ns, _ = intersect(sa, offset_origin(a, ng_a, dr), dr, 0.0, math.inf, stack)
    if not hit or not norm(sub(q, b)) <= POS_TOL * (1.0 + ln):
        return False, -1, a, a, a
    return True, prim, ng, ns, dr


@noalloc
def _solid_angle_factor(x, x1, n1):
    """|cos theta_1| / d^2 of the segment x -> x1 (area -> solid angle at x, Veach Eq. 8.10)."""
    dv = sub(x1, x)
    d2 = dot(dv, dv)
    return abs(dot(dv, n1)) / (math.sqrt(d2) * d2)


@block(_nrt=True)       # explicit: its callers run without reference counting, it allocates
def manifold_offset(sa, mtab, k, of, oi, m, cf, ci, x_b, mat_b_o, pdf_b, cfg, broken_jacobian, stack):
    """Move offset k (at its connectable vertex x'_b, material row mat_b_o) through the looked-ahead
    chain of length m to the base's x_c. On success updates beta' and lr (Eq. 16-17), places the
    offset at x_c as JOINED with I_PENDING = m and returns True; False means the shift failed."""
    xo = get3(of, k, F_POS)
    X = np.empty((m, 3))
    shapes = np.empty((m, M.SH_WIDTH))
    etas = np.empty(m)
    refr = np.empty(m, dtype=np.bool_)
    for j in range(m):
        for c in range(3):
            X[j, c] = cf[j, C_POS + c]
        shapes[j] = mtab[ci[j, CI_PRIM]]
        etas[j] = sa.materials[sa.prim_info[ci[j, CI_PRIM], 1]][L.MAT_ETA]     # used only where refr[j]
        refr[j] = ci[j, CI_REFR] == 1
    x_c, n_c = get3(cf, m, C_POS), get3(cf, m, C_NG)
    Xo = np.empty((m, 3))
    j_area, ok, _ = M.manifold_shift(x_b, xo, X, x_c, n_c, shapes, etas, refr, m, Xo, M.MAX_ITER, True)
    if not ok:
        return False
    if broken_jacobian:
        j_area = 1.0
    # the offset chain must be what the neighbour's tracer would trace: each segment unoccluded
    a, ng_a = xo, get3(of, k, F_NG)
    prims = np.empty(m + 1, dtype=np.int64)
    nrm = np.empty((m + 1, 6))
    dirs = np.empty((m + 1, 3))
    for j in range(m + 1):
        b = (Xo[j, 0], Xo[j, 1], Xo[j, 2]) if j < m else x_c
        good, prim, ng, ns, dr = _segment_reaches(sa, a, ng_a, b, stack)
        if not good or (j < m and mtab[prim, M.SH_TYPE] < 0.0) or (j < m and not _same_row(mtab, prim, ci[j, CI_PRIM])):
            return False
        prims[j] = prim
        for c in range(3):
            nrm[j, c], nrm[j, 3 + c], dirs[j, c] = ng[c], ns[c], dr[c]
        a, ng_a = b, ng
    # x_b: the offset's BSDF towards x'_1, Jacobian in solid angle (area Jacobian x cos/d^2 ratio)
    x1, x1o = get3(cf, 0, C_POS), (Xo[0, 0], Xo[0, 1], Xo[0, 2])
    j_sa = j_area * _solid_angle_factor(xo, x1o, (nrm[0, 0], nrm[0, 1], nrm[0, 2])) / \
        _solid_angle_factor(x_b, x1, get3(cf, 0, C_NG))
    ns_o = get3(of, k, F_NS)
    s, t = coordinate_system(ns_o)
    wi_o = to_local(get3(of, k, F_WI), s, t, ns_o)
    wo = to_local((dirs[0, 0], dirs[0, 1], dirs[0, 2]), s, t, ns_o)
    pdf_o = bsdf_pdf(mat_b_o, wi_o, wo)
    _update(of, k, bsdf_eval(mat_b_o, wi_o, wo), j_sa, pdf_o, pdf_b)
    state = pc_push(oi[k, I_STATE], lobe_class(mat_b_o, False, cfg.threshold))
    # the chain's delta vertices: the offset's own lobe of the base's kind, which must point along the chain
    prev_pdf = pdf_o
    for j in range(m):
        mat = sa.materials[sa.prim_info[prims[j], 1]]
        nsj = (nrm[j, 3], nrm[j, 4], nrm[j, 5])
        sj, tj = coordinate_system(nsj)
        wi = to_local((-dirs[j, 0], -dirs[j, 1], -dirs[j, 2]), sj, tj, nsj)
        wo_j, wt, pdf, good = same_delta_lobe(mat, wi, ci[j, CI_REFR] == 0)
        if not good:
            return False
        w_world = to_world(wo_j, sj, tj, nsj)
        if not norm(sub(w_world, (dirs[j + 1, 0], dirs[j + 1, 1], dirs[j + 1, 2]))) <= 1e3 * POS_TOL:
            return False
        _update(of, k, (wt[0] * pdf, wt[1] * pdf, wt[2] * pdf), 1.0, pdf, cf[j, C_PDF])
        state = pc_push(state, L.V_SPECULAR)
        prev_pdf = pdf
    # the offset now sits on x_c, arriving from its own last chain vertex; the base gets there in m steps
    set3(of, k, F_POS, x_c)
    # the base's own normals at x_c (the same point): the offset's shadow rays from x_c are then the base's
    set3(of, k, F_NG, get3(cf, m, C_NG))
    set3(of, k, F_NS, get3(cf, m, C_NS))
    set3(of, k, F_WI, (-dirs[m, 0], -dirs[m, 1], -dirs[m, 2]))
    set3(of, k, F_PREV_P, (Xo[m - 1, 0], Xo[m - 1, 1], Xo[m - 1, 2]))
    of[k, F_PREV_PDF] = prev_pdf
    oi[k, I_PREV_DELTA] = 1
    oi[k, I_PRIM] = prims[m]
    oi[k, I_MAT] = sa.prim_info[prims[m], 1]
    oi[k, I_STATE] = state
    oi[k, I_RECONN] = JOINED
    oi[k, I_PENDING] = m
    return True


@leaf
def _same_row(mtab, a, b):
    """Two primitives of one analytic shape (their manifold rows are equal)."""
    for c in range(M.SH_WIDTH):
        if mtab[a, c] != mtab[b, c]:
            return False
    return True


@leaf
def same_shape(sa, prim_a, prim_b):
    """Both primitives come from the same scene shape (``INFO_SHAPE``)."""
    return sa.prim_info[prim_a, G.INFO_SHAPE] == sa.prim_info[prim_b, G.INFO_SHAPE]


__all__ = ["manifold_table", "lookahead_chain", "manifold_offset", "same_shape", "NCF", "NCI"]
