"""Gradient-domain path tracing on surfaces: one base path and its four offset paths in lockstep
(Kettunen et al. 2015; STAR, Hua et al. 2019, Sec. 3-4.1, Eq. 15-17).

The base path is Mitsuba's ``path`` (:mod:`gdlearn.integrators.path.surface`: NEE + BSDF sampling with
the power heuristic, Russian roulette), with the same random numbers, so the primal image of one
seed equals ``pt``'s up to the roulette (see below). Each offset path starts through the neighbouring
pixel with the same sub-pixel jitter and is shifted one segment at a time as the base is extended
(:func:`gdlearn.integrators.path.gpt_surface.vertex.decide`): replay, half-vector copy, or -- once x_i, x'_i and x_{i+1}
are connectable -- reconnection to x_{i+1}, after which the offset shares the base's vertices (it keeps
its own incoming direction at x_{i+1} and is identical from x_{i+2} on). Every next-event sample of
the base is shifted by reconnecting the offset vertex to the *same* light point (area Jacobian 1).

Eq. 16-17. Each base contribution C = f(x)/p(x) of one technique (an emitter hit or a next-event
sample at some depth) and the offset's C' = f(T x)|J|/p(x) form the gradient sample

    w (C' - C),    w = p(x) / (p(x) + p'(T x) |J|)   (balance heuristic, ratio / log form)

added to the shift's buffer of the base pixel; a failed shift contributes -C (w = 1, STAR Sec. 3.5).
Since the backward shift from the neighbour carries the weight 1 - w of the same path pair, the
forward and backward buffers are *summed* (weights 1, 1) in :func:`gdlearn.integrators.gradients.combine_gradients`.
The MIS densities leave out Russian roulette (any density function used consistently on both sides
gives weights that sum to one); the estimator itself divides by the base's roulette probability.

Russian roulette uses max(base, offset) throughput, so a base path that turns black (a black
material) keeps going while an offset can still contribute: otherwise the forward shift of those
paths would never be sampled and their gradient would be lost.

Mixed policies (``replay+reconnection``, ``halfvector+replay+reconnection``): the free offsets take
:func:`gdlearn.integrators.path.gpt_surface.mixed.shift_segment_mixed` -- replay instead of failing where the vertex
classes disagree, reconnection where its criterion holds from both sides, a failure only where the
backward shift would reconnect -- and a base technique the offset lacks is paired with nothing
(weight 1), as that module explains.

Effects: every contribution is kept only if the class of *its own* path is wanted (the base's and
each offset's class are tracked separately); the early stop of ``radiance_path`` is not used, since
an offset can reach a wanted class the base cannot.
"""
import math


from gdlearn.kernels.bsdf.dispatch import (bsdf_eta, bsdf_is_delta_only, bsdf_sample, lobe_class, nee_class_share,
                                           nee_classes, sampled_lobe_class, vertex_class)
from gdlearn.kernels.camera import camera_ray
from gdlearn.kernels.geometry import offset_origin
from gdlearn.integrators.path.gpt_surface.vertex import (ALIVE, BROKEN_LOBE_CLASS, BROKEN_MANIFOLD_JACOBIAN,
                                                         BROKEN_MIS, BROKEN_PRIMAL, BROKEN_REVERSIBILITY,
                                                         BROKEN_UNPAIRED, F_W, FAILED, I_PENDING, OUTSIDE, VIS_UNKNOWN,
                                                         follow_base, follow_merged, nee_at_vis, set_hit, start_weights)
from gdlearn.integrators.path.gpt_surface.mixed import shift_segment_mixed, unpaired
from gdlearn.integrators.path.gpt_surface.vertex import (F_BETA, F_NG, F_NS, F_POS, F_PREV_P, F_PREV_PDF, F_WI,
                                                         I_ALIVE, I_ESCAPED, I_MAT, I_PREV_DELTA, I_PRIM, I_RECONN,
                                                         I_STATE, JOINED, MERGED, FREE, emitted, get3, mul3, relabel,
                                                         replayed_class, sc3, set3, shift_direction, vclass_of)
from gdlearn.shifts.policy import conn, decide
from gdlearn.kernels.lights import E_AREA, E_POINT, E_SPOT, EM_TYPE, same_direction_point, sample_emitter
from gdlearn.kernels.pathclass import pc_class, pc_init, pc_push
from gdlearn.kernels.rng import path_state, rand_at
from gdlearn.kernels.scene_query import intersect
from gdlearn.integrators.path.surface import D_BSDF_U1, D_BSDF_U2, D_EM_SEL, D_EM_U1, D_EM_U2, D_LOBE, D_RR, dim
from gdlearn.kernels.vec import coordinate_system, max3, to_local, to_world
from gdlearn.integrators.path.gpt_surface.manifold import lookahead_chain, manifold_offset, same_shape
from gdlearn.kernels.layout import V_SPECULAR
from gdlearn.shifts.policy import (POLICY_HALFVECTOR_RECONNECTION_MANIFOLD, SHIFT_FAIL, SHIFT_MANIFOLD,
                                   SHIFT_RECONNECT, SHIFT_REPLAY, is_mixed, record)
from gdlearn.shifts.replay import neighbour_inside, offset_film_position
from gdlearn.kernels.jit import inlined, ir_inline, leaf
from gdlearn.integrators.path.gpt_volume.flight import EV_ESCAPE, EV_SURFACE
from gdlearn.integrators.path.params import VB_SURFACE, BaseVertex, NextVertex

ONE3 = (1.0, 1.0, 1.0)


@leaf
def _wanted(cfg, state):
    return (cfg.mask >> pc_class(state)) & 1 == 1


@leaf
def _start_offsets(sa, px, of, oi, stack):
    """The pixel shift (Eq. 3): each neighbour's camera ray with the base's sub-pixel jitter (``px``:
    :class:`~gdlearn.integrators.path.params.Pixel`)."""
    fx, fy, x, y, w, h = px.fx, px.fy, px.x, px.y, px.w, px.h
    for k in range(4):
        if not neighbour_inside(x, y, k, w, h):
            oi[k, I_ALIVE] = OUTSIDE
            continue
        ox, oy = offset_film_position(fx, fy, k)
        o, d, tmax = camera_ray(sa.camera, ox, oy)
        hit, _, prim, p, ng, ns, _ = intersect(sa, o, d, 0.0, tmax, stack)
        set_hit(sa, of, oi, k, hit, prim, p, ng, ns, d)
        set3(of, k, F_BETA, ONE3)
        start_weights(of, k)
        of[k, F_PREV_PDF] = 1.0
        set3(of, k, F_PREV_P, o)
        oi[k, I_PREV_DELTA] = 1
        oi[k, I_RECONN] = FREE
        oi[k, I_STATE] = pc_init()
        oi[k, I_PENDING] = 0
        oi[k, I_ALIVE] = ALIVE


@leaf
def _pair(diff, of, oi, k, co, cb, cfg):
    """Eq. 16 with Eq. 17's weight for one technique: ``diff[k] += w (C' - C)`` (-C for a failed
    shift), and the weighted offset contribution ``diff[4 + k] += w C'`` (0 for a failed shift) that
    the MIS primal of Kettunen et al. 2015 gives to the neighbour (:func:`gdlearn.integrators.path.gpt.mis_primal`).
    A pair of zeros (most emission pairs: no emitter at either vertex) adds nothing and is skipped."""
    if co[0] == 0.0 and co[1] == 0.0 and co[2] == 0.0 and cb[0] == 0.0 and cb[1] == 0.0 and cb[2] == 0.0:
        return
    if oi[k, I_ALIVE] == ALIVE:
        wgt = 1.0 if cfg.broken == BROKEN_MIS else of[k, F_W]      # Eq. 17 of lr (vertex._update keeps it)
        for c in range(3):
            diff[k, c] += wgt * (co[c] - cb[c])
            diff[4 + k, c] += (1.0 if cfg.broken == BROKEN_PRIMAL else wgt) * co[c]
    elif oi[k, I_ALIVE] == FAILED:
        for c in range(3):
            diff[k, c] -= cb[c]


@leaf
def _emission_pairs(sa, of, oi, diff, cb, le_b, cfg):
    """The emission pairs of one vertex: ``cb`` the base's term, ``le_b`` the MIS-weighted Le it saw
    (:func:`emitted`), which a MERGED offset sees too: same vertex, same previous vertex and density."""
    for k in range(4):
        co = (0.0, 0.0, 0.0)
        # a pending manifold offset already sits at x_c; the base crosses the chain (no emitters) first
        if oi[k, I_ALIVE] == ALIVE and oi[k, I_PENDING] == 0 and _wanted(cfg, oi[k, I_STATE]):
            if oi[k, I_RECONN] == MERGED:
                _pair(diff, of, oi, k, mul3(get3(of, k, F_BETA), le_b), cb, cfg)
                continue
            wi = get3(of, k, F_WI)
            le = emitted(sa, oi[k, I_ESCAPED] == 1, oi[k, I_PRIM], get3(of, k, F_POS), get3(of, k, F_NS),
                         (-wi[0], -wi[1], -wi[2]), get3(of, k, F_PREV_P), of[k, F_PREV_PDF],
                         oi[k, I_PREV_DELTA] == 1)
            co = mul3(get3(of, k, F_BETA), le)
        _pair(diff, of, oi, k, co, cb, cfg)


@leaf
def _nee_share(mat, state, ns, wi_world, p, q, cfg):
    """The share of a next-event term at p (towards the light point q) that the effects mask keeps:
    ``surface_path``'s rule (:func:`gdlearn.kernels.bsdf.dispatch.nee_class_share`: a rough plastic's term is
    split between its coating and base classes; 1 or 0 for every other material)."""
    c_coat, c_rest = nee_classes(mat, cfg.threshold)
    want_coat = _wanted(cfg, pc_push(state, c_coat))
    want_rest = _wanted(cfg, pc_push(state, c_rest))
    if want_coat == want_rest:
        return 1.0 if want_coat else 0.0
    dv = (q[0] - p[0], q[1] - p[1], q[2] - p[2])
    n = math.sqrt(dv[0] * dv[0] + dv[1] * dv[1] + dv[2] * dv[2])
    if not n > 0.0:
        return 0.0
    s, t = coordinate_system(ns)
    wi = to_local(wi_world, s, t, ns)
    wo = to_local((dv[0] / n, dv[1] / n, dv[2] / n), s, t, ns)
    return nee_class_share(mat, wi, wo, want_coat, want_rest)


@leaf
def _nee_pairs(sa, em, q, nq, p, nb, vis, cb, of, oi, diff, cfg, stack):
    """Shift the base's next-event sample (light point q, unweighted value nb) to every offset by
    reconnecting to the same light point (for a constant / directional emitter: the same direction).
    An offset JOINED at the base's vertex sends the base's shadow ray: its known visibility ``vis`` is reused."""
    fixed_point = True
    et = int(sa.emitters[em, EM_TYPE])
    if not (et == E_AREA or et == E_POINT or et == E_SPOT):
        fixed_point = False
    for k in range(4):
        co = (0.0, 0.0, 0.0)
        if oi[k, I_ALIVE] == ALIVE and oi[k, I_PENDING] == 0:
            # (mixed policies) an offset that escaped, or sits on a delta-only vertex, has no next-event
            # technique here: density 0, the base's sample keeps weight 1 (gpt_mixed)
            mat_o = sa.materials[max(oi[k, I_MAT], 0)]
            if (oi[k, I_ESCAPED] == 1 or bsdf_is_delta_only(mat_o)) and cfg.broken != BROKEN_UNPAIRED:
                unpaired(diff, k, cb)
                continue
            po = get3(of, k, F_POS)
            qo = q if fixed_point else same_direction_point(sa.emitters, em, p, q, po)
            share = _nee_share(mat_o, oi[k, I_STATE], get3(of, k, F_NS), get3(of, k, F_WI), po, qo, cfg)
            if share > 0.0:
                if oi[k, I_RECONN] == MERGED:
                    no = nb
                else:
                    v = vis if oi[k, I_RECONN] == JOINED else VIS_UNKNOWN
                    no, _ = nee_at_vis(sa, em, qo, nq, po, get3(of, k, F_NG), get3(of, k, F_NS), get3(of, k, F_WI),
                                       mat_o, stack, v)
                co = sc3(mul3(get3(of, k, F_BETA), no), share)
        _pair(diff, of, oi, k, co, cb, cfg)


# IR-inlined into its one caller, lockstep._shift_offsets: compiled there only (kernels.jit)
@ir_inline
def _shift_segment(sa, k, of, oi, cfg, bv, nx, stats, stack):
    """Shift offset k's segment leaving its vertex i (base vertex ``bv``: wi -> wo, decided by its class
    ``bv.cls_s``; next vertex ``nx``: p2 or escape, of class ``nx.cls``)."""
    cls_b, cls_next = bv.cls_s, nx.cls
    hit2, prim2, p2, ng2, ns2 = nx.hit, nx.prim, nx.p, nx.ng, nx.ns
    if oi[k, I_ESCAPED] == 1:
        record(stats, SHIFT_FAIL, False)
        oi[k, I_ALIVE] = FAILED
        return
    mat_o = sa.materials[oi[k, I_MAT]]
    action = decide(cfg.policy, cls_b, vertex_class(mat_o, cfg.threshold), cls_next)
    if action == SHIFT_FAIL:
        record(stats, SHIFT_FAIL, False)
        oi[k, I_ALIVE] = FAILED
        return
    p_o = get3(of, k, F_POS)
    ng_o = get3(of, k, F_NG)
    wo_w, ok, lcls, pdf_o, delta_o = shift_direction(sa, action, k, of, mat_o, bv, nx, cfg, stack)
    if ok and action != SHIFT_REPLAY:
        ok, lcls = relabel(of, k, mat_o, bv, wo_w, lcls, cfg)      # lcls: the effect class from here on
    elif ok:
        lcls = replayed_class(of, k, mat_o, bv.us[0], delta_o, lcls, cfg)
    if ok and action == SHIFT_RECONNECT:
        set_hit(sa, of, oi, k, True, prim2, p2, ng2, ns2, wo_w)
        oi[k, I_RECONN] = JOINED
    elif ok:
        hit, _, prim, q, ng, ns, _ = intersect(sa, offset_origin(p_o, ng_o, wo_w), wo_w, 0.0, math.inf, stack)
        set_hit(sa, of, oi, k, hit, prim, q, ng, ns, wo_w)
        # the next vertices must agree in kind, else the reverse shift would choose differently (this
        # implies gpt_mixed.inverse_reconnects is False: y_{i+1} connectable only if x_{i+1} is, and then
        # the base itself reconnected)
        ok = conn(vclass_of(sa, not hit, prim, cfg)) == conn(cls_next) and hit == hit2 or \
            cfg.broken == BROKEN_REVERSIBILITY
        # with manifold exploration a copied specular vertex must lie on the base's shape: then the
        # offset's chain qualifies for the manifold walk exactly when the base's does (gpt_manifold)
        if ok and hit and cfg.policy == POLICY_HALFVECTOR_RECONNECTION_MANIFOLD and cls_next == V_SPECULAR:
            ok = same_shape(sa, prim, prim2)
    record(stats, action, ok)
    if not ok:
        oi[k, I_ALIVE] = FAILED
        return
    set3(of, k, F_PREV_P, p_o)
    of[k, F_PREV_PDF] = pdf_o
    oi[k, I_PREV_DELTA] = 1 if delta_o else 0
    oi[k, I_STATE] = pc_push(oi[k, I_STATE], lcls)


@leaf
def _fail_mismatched(sa, mat, oi, stats, cfg):
    """Before the base extends its vertex x_i (next event, next bounce), fail every offset whose x'_i
    is of another kind: escaped (no vertex to continue from), connectable vs not, or delta-only vs
    not (the neighbour's tracer would not even try next-event estimation there, so a next-event
    pair would get weight 1/2 with no backward partner). Each rule is symmetric in x_i and x'_i,
    so the backward shift fails on the same pairs (STAR Sec. 3.5: weight 1, offset 0). Mixed policies
    fail on none of these: their next-event pairs are formed per technique (gpt_mixed)."""
    if is_mixed(cfg.policy):
        return
    cb = conn(vertex_class(mat, cfg.threshold))
    db = bsdf_is_delta_only(mat)
    for k in range(4):
        if oi[k, I_ALIVE] != ALIVE or oi[k, I_RECONN] != FREE:
            continue
        bad = oi[k, I_ESCAPED] == 1
        if not bad:
            mo = sa.materials[oi[k, I_MAT]]
            bad = conn(vertex_class(mo, cfg.threshold)) != cb or bsdf_is_delta_only(mo) != db
        if bad:
            record(stats, SHIFT_FAIL, False)
            oi[k, I_ALIVE] = FAILED


@leaf
def _roulette(of, oi, beta, eta, u):
    """Mitsuba's survival q = min(max throughput * eta^2, 0.95), the max taken over the base and the
    live offsets; returns q (0: stop). Survivors' throughputs are divided by q by the caller."""
    m = max3(beta)
    for k in range(4):
        if oi[k, I_ALIVE] == ALIVE:
            m = max(m, max3(get3(of, k, F_BETA)))
    q = min(m * eta * eta, 0.95)
    if not q > 0.0 or u >= q:
        return 0.0
    return q


@leaf
def _next_event(sa, p, ng, ns, wi_world, mat, beta, state, rng, depth, of, oi, diff, cfg, stack):
    """The base's next-event sample at vertex p (``surface_path.nee_surface``'s random numbers, ``rng``:
    :class:`~gdlearn.integrators.path.params.PathRng`) and its shifts (:func:`_nee_pairs`); returns the base
    contribution."""
    h = path_state(rng.seed, rng.key, rng.s)     # the caller's, after inlining
    n_em = sa.emitters.shape[0]
    u_sel = rand_at(h, dim(depth, D_EM_SEL))
    em_b, q, nq, _, _, _, _, _, _ = sample_emitter(
        sa.emitters, sa.em_prims, sa.em_cdf, sa.prims, sa.prim_info, p, u_sel,
        rand_at(h, dim(depth, D_EM_U1)), rand_at(h, dim(depth, D_EM_U2)))
    # the chosen emitter even when the sample is black for the base (back side): an offset may
    # still see the light point's front
    em = min(int(u_sel * n_em), n_em - 1)
    nb = (0.0, 0.0, 0.0)
    vis = VIS_UNKNOWN
    if em_b >= 0:
        nb, vis = nee_at_vis(sa, em, q, nq, p, ng, ns, wi_world, mat, stack, VIS_UNKNOWN)
    cb = (0.0, 0.0, 0.0)
    share = _nee_share(mat, state, ns, wi_world, p, q, cfg)
    if share > 0.0:
        cb = sc3(mul3(beta, nb), share)
    _nee_pairs(sa, em, q, nq, p, nb, vis, cb, of, oi, diff, cfg, stack)
    return cb


@inlined
def _manifold_segment(sa, mtab, k, of, oi, m, cf, ci, cfg, bv, stats, stack):
    """Free offset k takes the manifold shift through the base's looked-ahead chain of length m."""
    mat_o = sa.materials[oi[k, I_MAT]]
    if decide(cfg.policy, bv.cls_s, vertex_class(mat_o, cfg.threshold), V_SPECULAR) == SHIFT_FAIL:
        record(stats, SHIFT_FAIL, False)
        oi[k, I_ALIVE] = FAILED
        return
    ok = manifold_offset(sa, mtab, k, of, oi, m, cf, ci, bv.x, mat_o, bv.pdf, cfg,
                         cfg.broken == BROKEN_MANIFOLD_JACOBIAN, stack)
    record(stats, SHIFT_MANIFOLD, ok)
    if not ok:
        oi[k, I_ALIVE] = FAILED


# inlined (leaf): called per base vertex with the scene's arrays and the vertex tuples as arguments;
# the mtab-is-None pruning still happens (numba types it as a function of its own first). Not
# IR-inlined into gpt_sample: that saved 5-10 s of the close-up's cold compile but made the surface
# scenes' passes 3-5 % slower (benchmarks/README.md, "Compiled once")
@leaf
def _shift_offsets(sa, of, oi, cfg, bv, nx, stats, stack, mtab, m, cf, ci):
    """Extend every live offset by the segment the base just sampled, x_b = ``bv.x`` -> x_{b+1} = ``nx.p``
    along ``nx.d`` (:class:`~gdlearn.integrators.path.params.BaseVertex`, ``NextVertex``). ``m`` > 0: the
    segment starts a qualifying specular chain of length m (cf, ci: :func:`gpt_manifold.lookahead_chain`),
    and free offsets take the manifold shift. ``cls_b``: the base lobe's effect class; ``cls_s``: its
    class for the shift decisions (a function of the path, :mod:`gdlearn.shifts.policy`): ``bv.cls_b``,
    ``bv.cls_s``."""
    for k in range(4):
        if oi[k, I_ALIVE] != ALIVE:
            continue
        if oi[k, I_PENDING] > 0:             # moved to x_c already: wait for the base
            oi[k, I_PENDING] -= 1
            continue
        if oi[k, I_RECONN] == MERGED:        # moved by the caller (_follow_merged_all)
            continue
        if mtab is not None:              # None: this specialisation has no manifold code (gpt_sample)
            if m > 0 and oi[k, I_RECONN] == FREE and oi[k, I_ESCAPED] == 0:
                _manifold_segment(sa, mtab, k, of, oi, m, cf, ci, cfg, bv, stats, stack)
                continue
        if oi[k, I_RECONN] != FREE:
            follow_base(sa, k, of, oi, bv, cfg)
            if oi[k, I_ALIVE] == ALIVE:
                set_hit(sa, of, oi, k, nx.hit, nx.prim, nx.p, nx.ng, nx.ns, nx.d)
        elif is_mixed(cfg.policy):
            shift_segment_mixed(sa, k, of, oi, cfg, bv, nx, stats, stack)
        else:
            _shift_segment(sa, k, of, oi, cfg, bv, nx, stats, stack)


@leaf
def _follow_merged_all(sa, of, oi, bv, nx):
    """Move every MERGED offset along the base's segment x_b -> x_{b+1} (``vertex.follow_merged``, then
    x_{b+1} as its vertex). Returns True when another live offset needs :func:`_shift_offsets`: once
    all offsets have merged (or failed), the per-bounce cost of the four is a few multiplications, and
    the large, non-inlined shift function is not entered at all."""
    need = False
    for k in range(4):
        if oi[k, I_ALIVE] != ALIVE:
            continue
        if oi[k, I_RECONN] != MERGED or oi[k, I_PENDING] > 0:
            need = True
            continue
        follow_merged(of, oi, k, bv)
        set_hit(sa, of, oi, k, nx.hit, nx.prim, nx.p, nx.ng, nx.ns, nx.d)
    return need


@leaf
def _any_free(oi):
    for k in range(4):
        if oi[k, I_ALIVE] == ALIVE and oi[k, I_RECONN] == FREE and oi[k, I_PENDING] == 0:
            return True
    return False


@leaf
def cls_next_of(sa, hit2, prim2, cfg):
    return vclass_of(sa, not hit2, prim2, cfg)


@ir_inline
def gpt_sample(sa, px, rng, cfg, of, oi, diff, stats, stack, mtab, cf, ci):
    """One base path through film point (fx, fy) of pixel (x, y) (``px``:
    :class:`~gdlearn.integrators.path.params.Pixel`, random numbers ``rng``: ``PathRng``) and its four shifts. Returns the
    base radiance (the primal sample); ``diff`` (8, 3): ``diff[k]`` receives the gradient sample of
    shift k (right, left, down, up), zero for a shift outside the image, and ``diff[4 + k]`` the
    MIS-weighted offset contribution sum w C' of shift k (:func:`_pair`). ``mtab``: the manifold
    shape table, or None for a specialisation without the manifold walk: numba prunes the
    ``mtab is not None`` branches of a None argument before typing, so the walk (a third of gpt's
    compile) is compiled only for the manifold kernel (the pruning also works IR-inlined: numba
    prunes again after inlining, and ``mtab`` is then the rows kernel's own argument).

    IR-inlined into its one caller, ``gpt._gpt_rows``: as a function of its own it was compiled
    twice, once in its own library and again in the rows kernel's, which links its callees' code in
    and optimises and emits it anew (~7 s of a cold compile; kernels.jit)."""
    h = path_state(rng.seed, rng.key, rng.s)     # hashed once: each number is then one finaliser (rng)
    diff[:] = 0.0
    o, d, tmax = camera_ray(sa.camera, px.fx, px.fy)
    hit, _, prim, p, ng, ns, _ = intersect(sa, o, d, 0.0, tmax, stack)
    _start_offsets(sa, px, of, oi, stack)
    beta = ONE3
    eta = 1.0
    prev_p, prev_pdf, prev_delta = o, 1.0, True
    state = pc_init()
    L = (0.0, 0.0, 0.0)
    depth = 0
    n_em = sa.emitters.shape[0]
    while True:
        cb = (0.0, 0.0, 0.0)
        le_b = emitted(sa, not hit, prim, p, ns, d, prev_p, prev_pdf, prev_delta)
        if _wanted(cfg, state):
            cb = mul3(beta, le_b)
        L = (L[0] + cb[0], L[1] + cb[1], L[2] + cb[2])
        _emission_pairs(sa, of, oi, diff, cb, le_b, cfg)
        if not hit or depth + 1 >= cfg.max_depth:
            break
        mat = sa.materials[sa.prim_info[prim, 1]]
        _fail_mismatched(sa, mat, oi, stats, cfg)
        sf, tf = coordinate_system(ns)
        wi_world = (-d[0], -d[1], -d[2])
        wi = to_local(wi_world, sf, tf, ns)
        if not bsdf_is_delta_only(mat) and n_em > 0:
            cb = _next_event(sa, p, ng, ns, wi_world, mat, beta, state, rng, depth, of, oi, diff, cfg, stack)
            L = (L[0] + cb[0], L[1] + cb[1], L[2] + cb[2])
        u_lobe = rand_at(h, dim(depth, D_LOBE))
        u1 = rand_at(h, dim(depth, D_BSDF_U1))
        u2 = rand_at(h, dim(depth, D_BSDF_U2))
        wo, weight, pdf, delta = bsdf_sample(mat, wi, u_lobe, u1, u2)
        if not pdf > 0.0:
            break
        cls_b = sampled_lobe_class(mat, wi, u_lobe, delta, cfg.threshold)
        cls_s = cls_b if cfg.broken == BROKEN_LOBE_CLASS else lobe_class(mat, delta, cfg.threshold)
        d2 = to_world(wo, sf, tf, ns)
        hit2, _, prim2, p2, ng2, ns2, _ = intersect(sa, offset_origin(p, ng, d2), d2, 0.0, math.inf, stack)
        # x_b and x_{b+1} of the segment the offsets shift next (params.BaseVertex, NextVertex)
        bv = BaseVertex(VB_SURFACE, p, ng, ns, prim, -1, mat, wi, wo, d2, weight, pdf, delta, cls_b, cls_s,
                        (u_lobe, u1, u2))
        nx = NextVertex(hit2, EV_SURFACE if hit2 else EV_ESCAPE, prim2, p2, ng2, ns2, d2, -1,
                        cls_next_of(sa, hit2, prim2, cfg), False)
        m = 0
        if mtab is not None:
            if cfg.policy == POLICY_HALFVECTOR_RECONNECTION_MANIFOLD and conn(cls_s) and hit2 and \
                    vclass_of(sa, False, prim2, cfg) == V_SPECULAR and _any_free(oi):
                m = lookahead_chain(sa, mtab, nx, rng, depth + 1, cfg, cf, ci, stack)
        if _follow_merged_all(sa, of, oi, bv, nx):
            _shift_offsets(sa, of, oi, cfg, bv, nx, stats, stack, mtab, m, cf, ci)
        beta = mul3(beta, weight)
        eta *= bsdf_eta(mat, wi, wo)
        prev_p, prev_pdf, prev_delta = p, pdf, delta
        state = pc_push(state, cls_b)
        hit, prim, p, ng, ns, d = hit2, prim2, p2, ng2, ns2, d2
        depth += 1
        if depth >= cfg.rr_depth:
            q_rr = _roulette(of, oi, beta, eta, rand_at(h, dim(depth - 1, D_RR)))
            if q_rr == 0.0:
                break
            beta = sc3(beta, 1.0 / q_rr)
            for k in range(4):
                if oi[k, I_ALIVE] == ALIVE:
                    set3(of, k, F_BETA, sc3(get3(of, k, F_BETA), 1.0 / q_rr))
    return L
