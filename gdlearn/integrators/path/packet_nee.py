"""Next-event estimation in the packet path tracer (:mod:`gdlearn.integrators.path.packet`).

A lane's vertex gets ``radiance_path``'s next-event estimate up to its shadow ray: the term times
beta waits in R_C, the ray in R_SO, Q_NEE says a term is pending. The common case -- a diffuse
vertex and an area emitter's triangle, every vertex of the Cornell box -- is *deferred*: the lane's
shading gathers what the estimate reads into rows of its own (:func:`defer_diffuse_area`), and
after every lane is shaded one loop computes all the deferred estimates at once
(:func:`nee_diffuse_area`), which the compiler turns into SIMD over the lanes (8 float64 with
AVX-512): the square roots and divisions of 8 lanes in one instruction each. Written branch-free
(each branch a select) with the scalar functions' operations in their order, it gives the bits of
``sample_emitter``, ``bsdf_eval``, ``bsdf_pdf``, ``power_heuristic`` and ``shadow_ray``
(tests/test_pt_packet.py: the image equals the one-path kernel's bit for bit). Other lanes take the
scalar :func:`nee_lane`. Why a loop of its own: LLVM vectorises a loop over the lanes only when
it reads and writes the rows of ``S`` and ``Q`` alone (constant row offsets, no aliasing to prove);
reading the scene's arrays in it (gathers) left it scalar. benchmarks/README.md, "The diffuse
lanes in SIMD".
"""
import math

from gdlearn.integrators.path.packet_rows import (Q_EMP, Q_NEE, R_BETA, R_C, R_ENG, R_EP0, R_EPA, R_ERGB, R_M2S,
                                                  R_MREF, R_NG, R_NS, R_P, R_SO, R_UEM, R_WI, get3, set3,
                                                  set3_if, set_if)
from gdlearn.kernels.accel.packet import PK
from gdlearn.kernels.bsdf.dispatch import bsdf_eval_pdf
from gdlearn.kernels.geometry import G_HASN, G_NG, INFO_TYPE, P_TRIANGLE, offset_origin
from gdlearn.kernels.jit import ir_inline, leaf
from gdlearn.kernels.layout import DIFFUSE, MAT_TYPE
from gdlearn.kernels.lights import (E_AREA, EM_AREA, EM_COUNT, EM_FIRST, EM_RGB, EM_TYPE, pick_emitter, pick_prim,
                                    sample_emitter)
from gdlearn.kernels.sampling import INV_PI, power_heuristic
from gdlearn.kernels.scene_query import SHADOW_EPS, shadow_ray
from gdlearn.kernels.vec import to_local


@ir_inline
def nee_lane(sa, S, Q, j, p, ng, frame, wi, mat, beta):
    """``surface_path.nee_surface`` for lane j up to its visibility test: the term times beta waits
    in R_C, its shadow ray in R_SO (tmax -1: no ray to test, the term counts as visible)."""
    s, t, n = frame
    em, q, nq, dl, dist, w_em, pdf_em, pdf_a, delta = sample_emitter(
        sa.emitters, sa.em_prims, sa.em_cdf, sa.prims, sa.prim_info, p,
        S[R_UEM * PK + j], S[(R_UEM + 1) * PK + j], S[(R_UEM + 2) * PK + j])
    if em < 0:
        return
    wo = to_local(dl, s, t, n)
    f, pdf_b = bsdf_eval_pdf(mat, wi, wo)
    if f[0] == 0.0 and f[1] == 0.0 and f[2] == 0.0:
        return
    o, d, tmax = shadow_ray(p, ng, q)
    w = 1.0 if delta else power_heuristic(pdf_em, pdf_b)   # nee_class_share: 1
    c = (f[0] * w_em[0] * w, f[1] * w_em[1] * w, f[2] * w_em[2] * w)
    set3(S, R_C, j, (beta[0] * c[0], beta[1] * c[1], beta[2] * c[2]))
    set3(S, R_SO, j, o)
    set3(S, R_SO + 3, j, d)
    S[(R_SO + 6) * PK + j] = tmax if tmax > 0.0 else -1.0
    Q[Q_NEE * PK + j] = 1


@leaf
def defer_diffuse_area(sa, S, Q, j, mat):
    """Defer lane j's next-event estimate to :func:`nee_diffuse_area` when its vertex is diffuse and
    its emitter sample falls on an area emitter's triangle (flat: no vertex normals): gather the
    triangle, the emitter's rgb and area pdf (``sample_emitter``'s ``sel / A``) into the lane's rows
    (the material's, R_MREF and R_M2S, are the vertex's: ``packet._shade_hit``). Returns whether it
    did."""
    if mat[MAT_TYPE] != DIFFUSE:
        return False
    em, u_rest = pick_emitter(sa.emitters, S[R_UEM * PK + j])
    if int(sa.emitters[em, EM_TYPE]) != E_AREA:
        return False
    prim = sa.em_prims[pick_prim(sa.em_cdf, int(sa.emitters[em, EM_FIRST]), int(sa.emitters[em, EM_COUNT]), u_rest)]
    if sa.prim_info[prim, INFO_TYPE] != P_TRIANGLE or sa.prims[prim, G_HASN] != 0.0:
        return False
    Q[Q_EMP * PK + j] = prim
    for k in range(9):                          # p0, e1, e2 (geometry.G_P0, G_E1, G_E2)
        S[(R_EP0 + k) * PK + j] = sa.prims[prim, k]
    set3(S, R_ENG, j, (sa.prims[prim, G_NG], sa.prims[prim, G_NG + 1], sa.prims[prim, G_NG + 2]))
    set3(S, R_ERGB, j, (sa.emitters[em, EM_RGB], sa.emitters[em, EM_RGB + 1], sa.emitters[em, EM_RGB + 2]))
    S[R_EPA * PK + j] = (1.0 / sa.emitters.shape[0]) / sa.emitters[em, EM_AREA]
    return True


@leaf
def nee_diffuse_area(S, Q):
    """:func:`nee_lane` for the lanes :func:`defer_diffuse_area` deferred (a diffuse vertex, an area
    emitter's triangle, gathered into rows R_EP0 ...), all lanes in one branch-free loop the compiler
    vectorises: ``sample_emitter``'s area branch, ``diffuse_eval``, ``diffuse_pdf``,
    ``power_heuristic`` and ``shadow_ray``, the same operations in the same order (so the same
    bits), each branch a select."""
    for j in range(PK):
        fast = Q[Q_EMP * PK + j] >= 0
        u1, u2 = S[(R_UEM + 1) * PK + j], S[(R_UEM + 2) * PK + j]
        su = math.sqrt(1.0 - u1)
        b1 = 1.0 - su
        b2 = u2 * su
        qx = S[R_EP0 * PK + j] + b1 * S[(R_EP0 + 3) * PK + j] + b2 * S[(R_EP0 + 6) * PK + j]
        qy = S[(R_EP0 + 1) * PK + j] + b1 * S[(R_EP0 + 4) * PK + j] + b2 * S[(R_EP0 + 7) * PK + j]
        qz = S[(R_EP0 + 2) * PK + j] + b1 * S[(R_EP0 + 5) * PK + j] + b2 * S[(R_EP0 + 8) * PK + j]
        px, py, pz = S[R_P * PK + j], S[(R_P + 1) * PK + j], S[(R_P + 2) * PK + j]
        vx, vy, vz = qx - px, qy - py, qz - pz
        dist2 = vx * vx + vy * vy + vz * vz
        inv_dist = 1.0 / math.sqrt(dist2)
        dx, dy, dz = vx * inv_dist, vy * inv_dist, vz * inv_dist
        cos_q = -(dx * S[R_ENG * PK + j] + dy * S[(R_ENG + 1) * PK + j] + dz * S[(R_ENG + 2) * PK + j])
        pdf_area = S[R_EPA * PK + j]
        pdf = pdf_area * dist2 / cos_q
        inv_pdf = cos_q / (pdf_area * dist2)
        # the shading frame's z of wi and wo, mirrored by a twosided material
        wiz = S[(R_WI + 2) * PK + j]
        woz = dx * S[R_NS * PK + j] + dy * S[(R_NS + 1) * PK + j] + dz * S[(R_NS + 2) * PK + j]
        flip = (S[R_M2S * PK + j] != 0.0) & (wiz < 0.0)
        wiz = -wiz if flip else wiz
        woz = -woz if flip else woz
        front = (wiz > 0.0) & (woz > 0.0)
        cs = woz * INV_PI
        fx = S[R_MREF * PK + j] * cs if front else 0.0
        fy = S[(R_MREF + 1) * PK + j] * cs if front else 0.0
        fz = S[(R_MREF + 2) * PK + j] * cs if front else 0.0
        pdf_b = cs if front else 0.0
        r = pdf_b / pdf
        w = 1.0 / (1.0 + r * r)
        w = 0.0 if r > 1e150 else w
        w = 1.0 if not pdf_b > 0.0 else w
        w = 0.0 if not pdf > 0.0 else w
        ok = fast & (dist2 != 0.0) & (cos_q > 0.0) & ((fx != 0.0) | (fy != 0.0) | (fz != 0.0))
        # shadow_ray from the vertex pushed off its surface (offset_origin) to q
        ng = get3(S, R_NG, j)
        o = offset_origin((px, py, pz), ng, (vx, vy, vz))
        has_n = (ng[0] != 0.0) | (ng[1] != 0.0) | (ng[2] != 0.0)
        ox = o[0] if has_n else px
        oy = o[1] if has_n else py
        oz = o[2] if has_n else pz
        sx, sy, sz = qx - ox, qy - oy, qz - oz
        sdist = math.sqrt(sx * sx + sy * sy + sz * sz)
        sinv = 1.0 / sdist
        tmax = sdist * (1.0 - SHADOW_EPS)
        c0 = fx * (S[R_ERGB * PK + j] * inv_pdf) * w
        c1 = fy * (S[(R_ERGB + 1) * PK + j] * inv_pdf) * w
        c2 = fz * (S[(R_ERGB + 2) * PK + j] * inv_pdf) * w
        beta = get3(S, R_BETA, j)
        set3_if(S, R_C, j, ok, (beta[0] * c0, beta[1] * c1, beta[2] * c2))
        set3_if(S, R_SO, j, ok, (ox, oy, oz))
        set3_if(S, R_SO + 3, j, ok, (sx * sinv, sy * sinv, sz * sinv) if sdist != 0.0 else (0.0, 0.0, 1.0))
        set_if(S, R_SO + 6, j, ok, tmax if (sdist != 0.0) & (tmax > 0.0) else -1.0)
        Q[Q_NEE * PK + j] = 1 if ok else Q[Q_NEE * PK + j]
