"""Gradient-domain path tracing in homogeneous media: one ``volpath`` base path and its four offset
paths in lockstep (Kettunen et al. 2015; Gruson et al. 2018, Sec. 6 "G-PT" with the distance copy of
Sec. 4.1; STAR, Hua et al. 2019, Sec. 3, 4.1 and 7.1, Eq. 16-17).

The base path is Mitsuba's ``volpath`` (:mod:`gdlearn.integrators.path.volume`) with the same random
numbers, so L equals ``pt``'s sample for sample as long as Russian roulette does not fire (roulette
uses max(base, offsets) throughput, as the surface G-PT). One loop iteration = one *flight* of the
base (the free-flight sampling across null interfaces up to a scattering vertex, a surface vertex
or the escape: :func:`base_flight`), then the shift of that segment for every offset:

* the direction leaving vertex x_i: reconnection to x_{i+1} when x_i, x'_i and x_{i+1} are
  connectable (medium vertices are; Jacobian |dw'/dw| with "cosine" 1 at a medium endpoint), else
  replay or -- at glossy / specular surface vertices under the half-vector policy -- the half-vector
  copy (:func:`gdlearn.integrators.path.gpt_surface.vertex.shift_direction`); phase sampling is replayed;
* the flight along the offset's own ray (:mod:`gdlearn.integrators.path.gpt_volume.flight`): the sampled
  distance is copied (Jacobian 1), a passing base flight passes; kinds must match or the shift
  fails; f' and the densities are the offset's own transmittances, distance pdfs and pass
  probabilities, so every MIS density of Eq. 17 is evaluated on each path's own segments.

Next-event samples are shifted by reconnecting to the same light point with each path's own shadow
transmittance. Emission seen *on* a null interface is not handled (volpath adds it; none of the
scenes has an emitting null shape): such light enters L but not the gradients.

Output per sample: L, and per shift k the gradient sample D_k = sum over techniques of w (C' - C)
(failed: -C) and S_k = sum of w C' (Eq. 16; w of Eq. 17 in log-ratio form). B_k = S_k - D_k is the
weighted base term, so B_k(p) + S_opposite(q) is the pair's MIS estimate of I_p.
"""
import math

import numpy as np

from gdlearn.kernels.bsdf.dispatch import (bsdf_eta, bsdf_eval, bsdf_is_delta_only, bsdf_pdf, bsdf_sample,
                                  lobe_class, sampled_lobe_class, vertex_class)
from gdlearn.kernels.accel.bvh import STACK_SIZE
from gdlearn.kernels.camera import camera_ray
from gdlearn.kernels.geometry import INFO_EMITTER, INFO_MAT, offset_origin
from gdlearn.integrators.path.gpt_surface.vertex import (BROKEN_LOBE_CLASS, BROKEN_UNPAIRED, F_BETA, F_LR, F_NG,
                                                         F_NS, F_POS, F_PREV_P, F_PREV_PDF, F_WI, I_ALIVE, I_ESCAPED,
                                                         I_MAT, I_PREV_DELTA, I_PRIM, I_RECONN, I_STATE, FREE, MERGED,
                                                         emitted, get3, mul3, sc3, set3, shift_direction, vclass_of)
from gdlearn.shifts.policy import conn, decide
from gdlearn.integrators.path.gpt_volume.flight import EV_ESCAPE, EV_FAIL, EV_SCATTER, EV_SURFACE, base_flight, offset_flight
from gdlearn.integrators.path.gpt_volume.vertex import (ALIVE, F_D, F_O, F_TMAX, FAILED, I_KIND,
                                               I_MED, K_ESCAPED, K_MEDIUM, K_SURFACE, NFV, NIV, TR_UNKNOWN,
                                               follow_joined, follow_merged, nee_pairs, pair, push_medium_vertex,
                                               reconnect_offset, replay_phase, scale_log, set_ray, set_vertex,
                                               start_offsets, wanted)
from gdlearn.kernels.layout import V_MEDIUM
from gdlearn.kernels.lights import emitter_pdf, eval_emitter, sample_emitter
from gdlearn.kernels.media.medium import medium_params
from gdlearn.kernels.pathclass import pc_init, pc_push
from gdlearn.kernels.media.phase import hg_eval, hg_sample
from gdlearn.kernels.rng import rand
from gdlearn.kernels.sampling import power_heuristic
from gdlearn.integrators.path.surface import D_BSDF_U1, D_BSDF_U2, D_EM_SEL, D_EM_U1, D_EM_U2, D_LOBE, D_RR, dim
from gdlearn.kernels.vec import coordinate_system, dot, max3, to_local, to_world
from gdlearn.integrators.path.volume import MAX_SEGMENTS, next_medium, shadow_transmittance
from gdlearn.kernels.arrays import borrowed
from gdlearn.shifts.policy import SHIFT_FAIL, SHIFT_RECONNECT, is_mixed, record
from gdlearn.integrators.path.gpt_surface.mixed import unpaired
from gdlearn.integrators.path.gpt_volume.mixed import shift_free_mixed
from gdlearn.integrators.path.accumulate import add_sample, finite_sample, store_means
from gdlearn.kernels.jit import block, ir_inline, leaf, noalloc
from gdlearn.kernels.threads import next_rows, run_rows
from gdlearn.integrators.path.params import VB_CAMERA, VB_MEDIUM, VB_SURFACE, BaseVertex, NextVertex, PathRng, Pixel

ZERO3 = (0.0, 0.0, 0.0)
ONE3 = (1.0, 1.0, 1.0)


@noalloc
def _flight(sa, of, oi, k, nx, tau, lp_b, cfg, stack):
    """Shift the base's flight to offset k's own ray (distance copy / pass) and check that the
    offset's event is of the base's kind ``nx.ev`` (escape, scattering, surface of the same connectability
    ``nx.cls`` and delta-only-ness ``nx.delta``: symmetric rules, so the backward shift fails on the same
    pairs)."""
    ev_b, cls_next, delta_next = nx.ev, nx.cls, nx.delta
    d = get3(of, k, F_D)
    ev, prim, p, ng, ns, med, lf, lp = offset_flight(sa, get3(of, k, F_O), d, of[k, F_TMAX], oi[k, I_MED], tau,
                                                     ev_b == EV_SCATTER, stack)
    if ev != ev_b or not lp_b > -math.inf:
        return False
    if ev == EV_SURFACE:
        mo = sa.materials[sa.prim_info[prim, INFO_MAT]]
        if conn(vertex_class(mo, cfg.threshold)) != conn(cls_next) or bsdf_is_delta_only(mo) != delta_next:
            return False
    scale_log(of, k, lf, lp_b)
    of[k, F_LR] += lp - lp_b
    kind = K_SURFACE if ev == EV_SURFACE else (K_MEDIUM if ev == EV_SCATTER else K_ESCAPED)
    set_vertex(sa, of, oi, k, kind, prim, p, ng, ns, d, med)
    return True


@ir_inline
def _shift_free(sa, of, oi, k, cfg, bv, nx, tau, lp_b, stats, stack):
    """Shift the segment x_i -> x_{i+1} of a not yet reconnected offset: direction, then flight
    (``bv``, ``nx``: :class:`~gdlearn.integrators.path.params.BaseVertex` x_i, ``NextVertex`` x_{i+1}; the
    decisions use ``bv.cls_s``)."""
    cls_b, us, cls_next = bv.cls_s, bv.us, nx.cls
    if bv.kind == VB_CAMERA:              # the pixel shift already set the ray
        ok = _flight(sa, of, oi, k, nx, tau, lp_b, cfg, stack)
        if not ok:
            record(stats, SHIFT_FAIL, False)
        return ok
    medium_o = oi[k, I_KIND] == K_MEDIUM
    mat_o = sa.materials[max(oi[k, I_MAT], 0)]
    cls_o = V_MEDIUM if medium_o else vertex_class(mat_o, cfg.threshold)
    action = decide(cfg.policy, cls_b, cls_o, cls_next)
    if action == SHIFT_FAIL:
        record(stats, SHIFT_FAIL, False)
        return False
    p_o = get3(of, k, F_POS)
    delta_o = False
    lcls = V_MEDIUM if medium_o else lobe_class(mat_o, False, cfg.threshold)
    if action == SHIFT_RECONNECT:
        ok, pdf_o = reconnect_offset(sa, of, oi, k, bv, nx, lp_b, cfg, stack)
    else:
        if medium_o:                      # phase sampling is replayed (no half-vector in a medium)
            pdf_o = replay_phase(sa, of, oi, k, us[1], us[2])
            ok = pdf_o > 0.0
        else:
            wo_w, ok, lcls, pdf_o, delta_o = shift_direction(sa, action, k, of, mat_o, bv, nx, cfg, stack)
            if ok:
                ng_o = get3(of, k, F_NG)
                set_ray(of, oi, k, offset_origin(p_o, ng_o, wo_w), wo_w,
                        next_medium(sa.prim_info, oi[k, I_PRIM], oi[k, I_MED], wo_w, ng_o))
        if ok:
            ok = _flight(sa, of, oi, k, nx, tau, lp_b, cfg, stack)
    record(stats, action, ok)
    if ok:
        set3(of, k, F_PREV_P, p_o)
        of[k, F_PREV_PDF] = pdf_o
        oi[k, I_PREV_DELTA] = 1 if delta_o else 0
        if not medium_o:
            oi[k, I_STATE] = pc_push(oi[k, I_STATE], lcls)
    return ok


@ir_inline
def _shift_all(sa, of, oi, cfg, bv, nx, tau, lp_b, W, bounce, rng, stats, stack):
    """Every live offset follows the base's segment x_i -> x_{i+1} (its event ``nx.ev`` at ``nx.p``).
    ``bv``: the base vertex x_i the segment leaves, ``nx`` the vertex x_{i+1} it reached
    (:class:`~gdlearn.integrators.path.params.BaseVertex`, ``NextVertex``; ``bv.cls_b`` its lobe's effect
    class, ``bv.cls_s`` its class for the shift decisions); the base flight (weight W, log density lp_b,
    length tau) read the random numbers (``rng``) of the flight leaving bounce ``bounce``."""
    ev = nx.ev
    kind = K_SURFACE if ev == EV_SURFACE else (K_MEDIUM if ev == EV_SCATTER else K_ESCAPED)
    for k in range(4):
        if oi[k, I_ALIVE] != ALIVE:
            continue
        if oi[k, I_RECONN] != FREE:
            if oi[k, I_RECONN] == MERGED:
                follow_merged(of, oi, k, bv)
            else:
                follow_joined(sa, of, oi, k, bv, cfg)
            if oi[k, I_ALIVE] == ALIVE:   # the same flight as the base: its weight
                set3(of, k, F_BETA, mul3(get3(of, k, F_BETA), W))
                set_vertex(sa, of, oi, k, kind, nx.prim, nx.p, nx.ng, nx.ns, nx.d, nx.med)
        elif is_mixed(cfg.policy):
            if not shift_free_mixed(sa, of, oi, k, cfg, bv, nx, bounce, rng, lp_b, stats, stack):
                oi[k, I_ALIVE] = FAILED
        elif not _shift_free(sa, of, oi, k, cfg, bv, nx, tau, lp_b, stats, stack):
            oi[k, I_ALIVE] = FAILED
    push_medium_vertex(oi)


@ir_inline
def _emission(sa, nx, beta, prev_p, prev_pdf, prev_delta, state, of, oi, diff, summ, cfg):
    """The emitter-hit technique at the base's surface hit / escape ``nx`` (volpath's arithmetic, so L is
    pt's bit for bit) and its pairs with every offset's own hit."""
    escaped, prim, p, ns, d = nx.ev == EV_ESCAPE, nx.prim, nx.p, nx.ns, nx.d
    cb = ZERO3
    if wanted(cfg, state):
        em = sa.env if escaped else sa.prim_info[prim, INFO_EMITTER]
        if em >= 0:
            if escaped:
                le = eval_emitter(sa.emitters, em, d, d)
                w = 1.0 if prev_delta else power_heuristic(prev_pdf, emitter_pdf(sa.emitters, em, prev_p, d, d))
                cb = (beta[0] * le[0] * w, beta[1] * le[1] * w, beta[2] * le[2] * w)
            else:
                le = eval_emitter(sa.emitters, em, ns, d)
                if le[0] + le[1] + le[2] > 0.0:
                    w = 1.0 if prev_delta else power_heuristic(prev_pdf, emitter_pdf(sa.emitters, em, prev_p, p, ns))
                    cb = (beta[0] * le[0] * w, beta[1] * le[1] * w, beta[2] * le[2] * w)
    for k in range(4):
        co = ZERO3
        if oi[k, I_ALIVE] == ALIVE and oi[k, I_KIND] == K_MEDIUM and cfg.broken != BROKEN_UNPAIRED:
            unpaired(diff, k, cb)    # (mixed policies) an offset at a medium vertex has no emitter hit here
            continue
        if oi[k, I_ALIVE] == ALIVE and wanted(cfg, oi[k, I_STATE]):
            wi = get3(of, k, F_WI)
            le = emitted(sa, oi[k, I_ESCAPED] == 1, oi[k, I_PRIM], get3(of, k, F_POS), get3(of, k, F_NS),
                         (-wi[0], -wi[1], -wi[2]), get3(of, k, F_PREV_P), of[k, F_PREV_PDF], oi[k, I_PREV_DELTA] == 1)
            co = mul3(get3(of, k, F_BETA), le)
        pair(diff, summ, of, oi, k, co, cb, cfg)
    return cb


# inlined (leaf), as flight.base_flight: one call per base vertex that passed the whole scene
@leaf
def _next_event(sa, nx, mat, g, beta, state, rng, bounce, of, oi, diff, summ, cfg, stack):
    """volpath's next-event sample at the base vertex ``nx`` -- the vertex the last flight reached, a
    medium vertex when ``nx.ev`` is EV_SCATTER (``nee_volume``'s random numbers and arithmetic) -- and its
    shifts to the offsets (:func:`gpt_volume_vertex.nee_pairs`); returns the base term."""
    p, ng, ns, prim, medium, medium_vertex = nx.p, nx.ng, nx.ns, nx.prim, nx.med, nx.ev == EV_SCATTER
    wi_w = (-nx.d[0], -nx.d[1], -nx.d[2])
    seed, key, s = rng.seed, rng.key, rng.s
    n_em = sa.emitters.shape[0]
    if n_em == 0:
        return ZERO3
    u_sel = rand(seed, key, s, dim(bounce, D_EM_SEL))
    em_b, q, nq, dl, _, w_em, pdf_em, _, delta = sample_emitter(
        sa.emitters, sa.em_prims, sa.em_cdf, sa.prims, sa.prim_info, p, u_sel,
        rand(seed, key, s, dim(bounce, D_EM_U1)), rand(seed, key, s, dim(bounce, D_EM_U2)))
    em = min(int(u_sel * n_em), n_em - 1)        # even if black for the base: an offset may see it
    nb = ZERO3
    cbv = ZERO3
    tr, m = TR_UNKNOWN, -1
    if em_b >= 0:
        m = medium if medium_vertex else next_medium(sa.prim_info, prim, medium, dl, ng)
        tr = shadow_transmittance(sa, p, ng, q, m, stack)
        if not (tr[0] == 0.0 and tr[1] == 0.0 and tr[2] == 0.0):
            wl = (w_em[0] * tr[0], w_em[1] * tr[1], w_em[2] * tr[2])
            if medium_vertex:
                ph = hg_eval(g, dot(wi_w, dl))
                kk = ph * (1.0 if delta else power_heuristic(pdf_em, ph))
                nb = (wl[0] * kk, wl[1] * kk, wl[2] * kk)
                cbv = (beta[0] * wl[0] * kk, beta[1] * wl[1] * kk, beta[2] * wl[2] * kk)
            else:
                sf, tf = coordinate_system(ns)
                wi = to_local(wi_w, sf, tf, ns)
                wo = to_local(dl, sf, tf, ns)
                f = bsdf_eval(mat, wi, wo)
                kk = 1.0 if delta else power_heuristic(pdf_em, bsdf_pdf(mat, wi, wo))
                nb = (f[0] * wl[0] * kk, f[1] * wl[1] * kk, f[2] * wl[2] * kk)
                cbv = (beta[0] * f[0] * wl[0] * kk, beta[1] * f[1] * wl[1] * kk, beta[2] * f[2] * wl[2] * kk)
    st = state if medium_vertex else pc_push(state, vertex_class(mat, cfg.threshold))
    cb = cbv if wanted(cfg, st) else ZERO3
    nee_pairs(sa, em, q, nq, p, nb, tr, m, cb, of, oi, diff, summ, cfg, medium_vertex, stack)
    return cb


@leaf
def _any_free(oi):
    """Does a live offset still shift on its own (FREE)? Only then is the base flight's log density
    needed (joined and merged offsets follow the base's flight with its weight)."""
    for k in range(4):
        if oi[k, I_ALIVE] == ALIVE and oi[k, I_RECONN] == FREE:
            return True
    return False


@leaf
def _roulette_all(of, oi, beta, eta, depth, cfg, u):
    """Mitsuba's roulette q = min(max throughput eta^2, 0.95) with the max over the base *and* the
    live offsets (a black base must not stop offsets that still carry light). Returns (alive, beta)."""
    m = max3(beta)
    for k in range(4):
        if oi[k, I_ALIVE] == ALIVE:
            b = max3(get3(of, k, F_BETA))
            if b > m:
                m = b
    if not m > 0.0:
        return False, beta
    if depth < cfg.rr_depth:
        return True, beta
    q = min(m * eta * eta, 0.95)
    if u >= q:
        return False, beta
    for k in range(4):
        if oi[k, I_ALIVE] == ALIVE:
            set3(of, k, F_BETA, sc3(get3(of, k, F_BETA), 1.0 / q))
    return True, (beta[0] / q, beta[1] / q, beta[2] / q)


@ir_inline
def gpt_volume_sample(sa, px, rng, cfg, of, oi, diff, summ, stats, stack):
    """One volpath base path through film point (fx, fy) of pixel (x, y) (``px``:
    :class:`~gdlearn.integrators.path.params.Pixel`; random numbers ``rng``: ``PathRng``) and its four shifts.
    Returns L; ``diff[k]`` / ``summ[k]`` receive D_k / S_k of shift k (right, left, down, up).
    IR-inlined into :func:`_gpt_volume_rows`, so that it is compiled once (as ``gpt_sample``)."""
    seed, key, s = rng.seed, rng.key, rng.s
    diff[:] = 0.0
    summ[:] = 0.0
    o, d, tmax = camera_ray(sa.camera, px.fx, px.fy)
    start_offsets(sa, px, of, oi)
    medium = sa.camera_medium
    beta, eta, state, L, depth, b = ONE3, 1.0, pc_init(), ZERO3, 0, 0     # b: bounce (random numbers)
    prev_p, prev_pdf, prev_delta = o, 1.0, True
    # the base vertex the next segment leaves, as the shifts need it (_shift_all)
    bv = BaseVertex(VB_CAMERA, o, ZERO3, ZERO3, -1, medium, sa.materials[0], ZERO3, ZERO3, ZERO3, ONE3, 1.0, False,
                    0, 0, (0.0, 0.0, 0.0))
    while b < MAX_SEGMENTS:
        ev, medium, beta, W, lp_b, tau, prim, p, ng, ns = base_flight(sa, o, d, tmax, medium, beta, rng, b, stack,
                                                                      _any_free(oi))
        tmax = math.inf
        if ev == EV_FAIL:
            break
        # the vertex x_{i+1} the flight reached (params.NextVertex): its class and delta-only-ness, as the
        # shifts of the segment x_i -> x_{i+1} need them
        cls_next = V_MEDIUM if ev == EV_SCATTER else vclass_of(sa, ev == EV_ESCAPE, prim, cfg)
        delta_next = ev == EV_SURFACE and bsdf_is_delta_only(sa.materials[sa.prim_info[prim, INFO_MAT]])
        nx = NextVertex(ev != EV_ESCAPE, ev, prim, p, ng, ns, d, medium, cls_next, delta_next)
        _shift_all(sa, of, oi, cfg, bv, nx, tau, lp_b, W, b, rng, stats, stack)
        wi_w = (-d[0], -d[1], -d[2])
        u_lobe = rand(seed, key, s, dim(b, D_LOBE))    # also at a medium vertex: a replayed offset may need it
        if ev == EV_SCATTER:
            depth += 1
            if depth >= cfg.max_depth:
                break
            state = pc_push(state, V_MEDIUM)
            _, _, g = medium_params(sa.media[medium])
            cb = _next_event(sa, nx, bv.mat, g, beta, state, rng, b, of, oi, diff, summ, cfg, stack)
            L = (L[0] + cb[0], L[1] + cb[1], L[2] + cb[2])
            u1, u2 = rand(seed, key, s, dim(b, D_BSDF_U1)), rand(seed, key, s, dim(b, D_BSDF_U2))
            d2, pdf = hg_sample(g, wi_w, u1, u2)
            if not pdf > 0.0:
                break
            bv = BaseVertex(VB_MEDIUM, p, ZERO3, ZERO3, -1, medium, sa.materials[0], ZERO3, ZERO3, d2, ONE3, pdf,
                            False, V_MEDIUM, V_MEDIUM, (u_lobe, u1, u2))
            o, d = p, d2
            prev_p, prev_pdf, prev_delta = p, pdf, False
        else:
            cb = _emission(sa, nx, beta, prev_p, prev_pdf, prev_delta, state, of, oi, diff, summ, cfg)
            L = (L[0] + cb[0], L[1] + cb[1], L[2] + cb[2])
            if ev == EV_ESCAPE or depth + 1 >= cfg.max_depth:
                break
            mat = sa.materials[sa.prim_info[prim, INFO_MAT]]
            sf, tf = coordinate_system(ns)
            wi = to_local(wi_w, sf, tf, ns)
            if not bsdf_is_delta_only(mat):
                cb = _next_event(sa, nx, mat, 0.0, beta, state, rng, b, of, oi, diff, summ, cfg, stack)
                L = (L[0] + cb[0], L[1] + cb[1], L[2] + cb[2])
            u1, u2 = rand(seed, key, s, dim(b, D_BSDF_U1)), rand(seed, key, s, dim(b, D_BSDF_U2))
            wo, weight, pdf, is_delta = bsdf_sample(mat, wi, u_lobe, u1, u2)
            if not pdf > 0.0:
                break
            beta = (beta[0] * weight[0], beta[1] * weight[1], beta[2] * weight[2])
            eta *= bsdf_eta(mat, wi, wo)
            d2 = to_world(wo, sf, tf, ns)
            o = offset_origin(p, ng, d2)
            med_b = medium                    # the medium the base arrived in at p
            medium = next_medium(sa.prim_info, prim, medium, d2, ng)
            cls_b = sampled_lobe_class(mat, wi, u_lobe, is_delta, cfg.threshold)
            cls_s = cls_b if cfg.broken == BROKEN_LOBE_CLASS else lobe_class(mat, is_delta, cfg.threshold)
            state = pc_push(state, cls_b)
            bv = BaseVertex(VB_SURFACE, p, ng, ns, prim, med_b, mat, wi, wo, d2, weight, pdf, is_delta, cls_b, cls_s,
                            (u_lobe, u1, u2))
            prev_p, prev_pdf, prev_delta = p, pdf, is_delta
            depth += 1
            d = d2
        alive, beta = _roulette_all(of, oi, beta, eta, depth, cfg, rand(seed, key, s, dim(b, D_RR)))
        if not alive:
            break
        b += 1
    return L


def gpt_volume_rows(sa, seed, sample0, spp, cfg, out, stats, bad):
    """``out`` (9, H, W, 3) per-pass means per base pixel: [0] L, [1 + k] D_k, [5 + k] S_k (shift k:
    right, left, down, up). ``stats`` (H, N_STATS) shift counters per row (``shifts.policy.record``),
    ``bad`` (H,) samples dropped because something in them was not finite. Rows run on threads
    (:func:`gdlearn.kernels.threads.run_rows`), not in a parallel kernel: a third less to compile."""
    run_rows(lambda counter, step: _gpt_volume_rows(sa, seed, sample0, spp, cfg, out, stats, bad, counter, step),
             out.shape[1])


@block(nogil=True)
def _gpt_volume_rows(sa, seed, sample0, spp, cfg, out, stats, bad, counter, step):
    """One thread's share of the pass: chunks of ``step`` rows taken from ``counter`` until the image
    is done."""
    # borrowed arrays: no atomic reference counts shared by the threads (kernels.arrays.borrowed)
    sa = borrowed(sa)
    h, w = out.shape[1], out.shape[2]
    inv = 1.0 / spp
    stack = np.empty(STACK_SIZE, dtype=np.int32)
    of = np.zeros((4, NFV))
    oi = np.zeros((4, NIV), dtype=np.int64)
    # the sample writes its gradient rows D_k and offset rows S_k straight into the rows of d8
    # (views, not copies: a copy's shape check put numba's error formatting in the compile)
    d8 = np.zeros((8, 3))
    diff, summ = d8[:4], d8[4:]
    acc = np.zeros((9, 3))
    while True:
        y0, y1 = next_rows(counter, step, h)
        if y0 == y1:
            return
        for y in range(y0, y1):
            st = stats[y]
            for x in range(w):
                key = y * w + x
                acc[:] = 0.0
                for s in range(sample0, sample0 + spp):
                    fx, fy = x + rand(seed, key, s, 0), y + rand(seed, key, s, 1)
                    c = gpt_volume_sample(sa, Pixel(fx, fy, x, y, w, h), PathRng(seed, key, s), cfg, of, oi,
                                          diff, summ, st, stack)
                    if not finite_sample(c, d8):
                        bad[y] += 1          # NaN / Inf never reach an image: drop the whole sample
                        continue
                    add_sample(acc, c, d8)
                store_means(out, y, x, acc, inv)
