"""Per-vertex pieces of gradient-domain path tracing with shift mappings (Kettunen et al. 2015; STAR,
Hua et al. 2019, Sec. 3-4.1): emission and next-event terms evaluated on an *offset* vertex, and the
shift of one path segment (replay, half-vector copy, reconnection). The lockstep loop that calls
them is :mod:`gdlearn.integrators.path.gpt_surface.lockstep`.

Measure. A camera path is parametrised by its film point and the direction sampled at every vertex
(solid angle, or a discrete lobe probability at a delta lobe); a next-event vertex z on a light by
its area measure. In that measure the integrand of one vertex is ``bsdf_eval`` (f |cos theta_o|),
and the shift's Jacobian is a product of per-vertex factors: 1 for the film move (one pixel, same
jitter), ``J_w`` of the half-vector copy (:mod:`gdlearn.shifts.halfvector`), the solid-angle form of
the reconnection (:mod:`gdlearn.shifts.reconnection`), p_b / p_o for replay, 1 for a copied delta
lobe or a shared direction, and 1 for the light point (area measure, STAR Sec. 3.3).

Offset state (one row per neighbour, arrays ``of`` float64 and ``oi`` int64, columns below): the
offset vertex, its incoming direction, the offset throughput ``beta' = prod f'_j J_j / p_j`` (base
densities p_j, so beta' * Le is f(T x) |J| / p(x) of Eq. 16), and ``lr = sum log(p'_j J_j / p_j)``,
the log of the density ratio that Eq. 17's MIS weight needs (:func:`gdlearn.shifts.mis.mis_weight_from_log_ratio`),
with that weight ``w`` kept beside it: lr changes once per shifted segment, the weight is read by every
technique of every later vertex (an ``exp`` each, ~5 % of a Cornell-box sample before it was kept).
"""
import math


from gdlearn.kernels import layout as L
from gdlearn.kernels.bsdf.dispatch import (bsdf_eval_pdf, bsdf_sample, lobe_class, lobe_class_ratio,
                                           sampled_lobe_class, vertex_class)
from gdlearn.kernels.pathclass import ALL_MASK
from gdlearn.integrators.path.params import VB_SURFACE
from gdlearn.kernels.pathclass import pc_push
from gdlearn.kernels.lights import (E_AREA, E_POINT, E_SPOT, EM_AREA, EM_RGB, EM_TYPE, INV_FOUR_PI,
                                    E_CONSTANT, emitter_pdf, eval_emitter, spot_falloff)
from gdlearn.kernels.sampling import power_heuristic
from gdlearn.kernels.scene_query import occluded
from gdlearn.kernels.vec import coordinate_system, dot, to_local, to_world
from gdlearn.shifts.halfvector import halfvector_copy_mat
from gdlearn.shifts.mis import mis_weight_from_log_ratio
from gdlearn.shifts.policy import ESCAPED, SHIFT_RECONNECT, SHIFT_REPLAY
from gdlearn.shifts.reconnection import reconnect
from gdlearn.kernels.jit import leaf, noalloc

ZERO3 = (0.0, 0.0, 0.0)
#: deliberately broken variants, for tests that must be able to fail: Eq. 17 weight 1 on both sides;
#: the reconnection's solid-angle Jacobian replaced by 1; the half-vector copy's J_w replaced by 1;
#: the offset's share of the MIS primal left unweighted (S_k = sum C' instead of sum w C'); the
#: manifold shift's Jacobian |dx'_1/dx_1| replaced by 1; no reversibility check after a step that did
#: not reconnect (an offset whose backward shift would reconnect keeps Eq. 17's weight); the shift
#: decisions read the *sampled* lobe of a rough plastic (not a function of the path); a base technique
#: the offset does not have (next event at a delta-only offset vertex) weighted by Eq. 17 instead of 1;
#: a mixed policy's replayed direction or flight without its weight f'/p' (the replay Jacobian p_b / p'
#: and the offset's own integrand dropped)
(BROKEN_NONE, BROKEN_MIS, BROKEN_JACOBIAN, BROKEN_HV_JACOBIAN, BROKEN_PRIMAL, BROKEN_MANIFOLD_JACOBIAN,
 BROKEN_REVERSIBILITY, BROKEN_LOBE_CLASS, BROKEN_UNPAIRED, BROKEN_REPLAY_WEIGHT) = range(10)

# float columns of ``of``
F_POS, F_NG, F_NS, F_WI, F_BETA, F_LR, F_PREV_PDF, F_PREV_P, F_W = 0, 3, 6, 9, 12, 15, 16, 17, 20
NF = 21
# int columns of ``oi`` (I_PENDING: base segments left until the base reaches the vertex a manifold
# shift already moved the offset to, :mod:`gdlearn.integrators.path.gpt_surface.manifold`)
I_ALIVE, I_MAT, I_RECONN, I_PREV_DELTA, I_ESCAPED, I_STATE, I_PRIM, I_PENDING = range(8)
NI = 8
# I_RECONN values: not yet joined, joined at this vertex (own incoming direction), identical to base
FREE, JOINED, MERGED = 0, 1, 2
#: I_ALIVE values: shift not traced (outside the image), failed (or ended: every later base technique
#: is unpaired, weight 1), alive
OUTSIDE, FAILED, ALIVE = -1, 0, 1


@leaf
def get3(a, k, j):
    return (a[k, j], a[k, j + 1], a[k, j + 2])


@leaf
def set3(a, k, j, v):
    a[k, j] = v[0]
    a[k, j + 1] = v[1]
    a[k, j + 2] = v[2]


@leaf
def mul3(a, b):
    return (a[0] * b[0], a[1] * b[1], a[2] * b[2])


@leaf
def sc3(a, s):
    return (a[0] * s, a[1] * s, a[2] * s)


@leaf
def set_hit(sa, of, oi, k, hit, prim, p, ng, ns, d):
    """Make (p, ng, ns) of primitive prim, reached along d, offset k's current vertex."""
    set3(of, k, F_POS, p)
    set3(of, k, F_NG, ng)
    set3(of, k, F_NS, ns)
    set3(of, k, F_WI, (-d[0], -d[1], -d[2]))
    oi[k, I_ESCAPED] = 0 if hit else 1
    oi[k, I_PRIM] = prim
    oi[k, I_MAT] = sa.prim_info[prim, 1] if hit else -1


@leaf
def emitted(sa, escaped, prim, p, ns, d, prev_p, prev_pdf, prev_delta):
    """Le seen along the travel direction d at hit p (or the constant emitter on escape), MIS-weighted
    against next-event estimation from prev_p exactly as ``surface_path.radiance_path`` does."""
    if escaped:
        if sa.env < 0:
            return ZERO3
        le = eval_emitter(sa.emitters, sa.env, d, d)
        w = 1.0 if prev_delta else power_heuristic(prev_pdf, emitter_pdf(sa.emitters, sa.env, prev_p, d, d))
        return sc3(le, w)
    em = sa.prim_info[prim, 2]
    if em < 0:
        return ZERO3
    le = eval_emitter(sa.emitters, em, ns, d)
    if not (le[0] + le[1] + le[2] > 0.0):
        return ZERO3
    w = 1.0 if prev_delta else power_heuristic(prev_pdf, emitter_pdf(sa.emitters, em, prev_p, p, ns))
    return sc3(le, w)


@noalloc
def light_weight(sa, em, q, nq, p):
    """``(Le / pdf_sa, pdf_sa, is_delta, dir p->q)`` of a *fixed* light point q (normal nq) of emitter
    em seen from p: the next-event weight of ``lights.sample_emitter`` re-evaluated at another
    shading point. For an area light the density is the same area density at q for every p (the
    light point is shared by base and offset, area Jacobian 1), converted to solid angle at p."""
    n_em = sa.emitters.shape[0]
    et = int(sa.emitters[em, EM_TYPE])
    dv = (q[0] - p[0], q[1] - p[1], q[2] - p[2])
    d2 = dot(dv, dv)
    if not d2 > 0.0:
        return ZERO3, 0.0, False, ZERO3
    dist = math.sqrt(d2)
    dl = (dv[0] / dist, dv[1] / dist, dv[2] / dist)
    rgb = get3(sa.emitters, em, EM_RGB)
    sel = 1.0 / n_em
    if et == E_AREA:
        cos_q = -dot(dl, nq)
        if not cos_q > 0.0:          # back of a one-sided emitter
            return ZERO3, 0.0, False, dl
        pdf = sel / sa.emitters[em, EM_AREA] * d2 / cos_q
        return sc3(rgb, 1.0 / pdf), pdf, False, dl
    if et == E_POINT or et == E_SPOT:
        f = 1.0 / (d2 * sel)
        if et == E_SPOT:
            f *= spot_falloff(sa.emitters, em, (-dl[0], -dl[1], -dl[2]))
        return sc3(rgb, f), sel, True, dl
    if et == E_CONSTANT:             # direction copied by the caller (q = p + the base's offset)
        pdf = sel * INV_FOUR_PI
        return sc3(rgb, 1.0 / pdf), pdf, False, dl
    return sc3(rgb, 1.0 / sel), sel, True, dl      # directional


@noalloc
def nee_at(sa, em, q, nq, p, ng, ns, wi_world, mat, stack):
    """Next-event contribution (without throughput) of light point q at a surface vertex p whose path
    arrives from wi_world: f(wi, wo) |cos| Le / pdf, MIS (power heuristic) against BSDF sampling."""
    return nee_at_vis(sa, em, q, nq, p, ng, ns, wi_world, mat, stack, VIS_UNKNOWN)[0]


#: visibility of a shadow ray already traced: unknown, occluded, visible
VIS_UNKNOWN, VIS_OCCLUDED, VIS_VISIBLE = -1, 0, 1


@noalloc
def nee_at_vis(sa, em, q, nq, p, ng, ns, wi_world, mat, stack, vis):
    """:func:`nee_at` that reuses a known visibility of the segment p -> q (``vis``, e.g. the base's
    shadow ray for an offset JOINED at the base's own vertex) and returns ``(value, vis)``."""
    w_em, pdf_em, delta, dl = light_weight(sa, em, q, nq, p)
    if not (w_em[0] + w_em[1] + w_em[2] > 0.0):
        return ZERO3, vis
    s, t = coordinate_system(ns)
    wi = to_local(wi_world, s, t, ns)
    wo = to_local(dl, s, t, ns)
    f, pdf_b = bsdf_eval_pdf(mat, wi, wo)
    if f[0] == 0.0 and f[1] == 0.0 and f[2] == 0.0:
        return ZERO3, vis
    if vis == VIS_UNKNOWN:
        vis = VIS_OCCLUDED if occluded(sa, p, ng, q, stack) else VIS_VISIBLE
    if vis == VIS_OCCLUDED:
        return ZERO3, vis
    w = 1.0 if delta else power_heuristic(pdf_em, pdf_b)
    return sc3(mul3(f, w_em), w), vis


@leaf
def vclass_of(sa, escaped, prim, cfg):
    """The material class of a hit (``bsdf.vertex_class``), ESCAPED for a path that left the scene."""
    if escaped:
        return ESCAPED
    return vertex_class(sa.materials[sa.prim_info[prim, 1]], cfg.threshold)


@leaf
def same_delta_lobe(mat, wi, refl):
    """Sample the offset's delta lobe of the same kind as the base's (reflection if ``refl`` else
    transmission): the half-vector copy at a smooth interface (h = n, Jacobian 1). Returns
    ``(wo, weight, pdf, ok)``; the lobe is found by the extreme lobe-selection numbers (Mitsuba's
    dielectric reflects for u <= F, plastics pick their coating first)."""
    for u in (0.0, 0.9999999999999999):
        wo, wt, pdf, dl = bsdf_sample(mat, wi, u, 0.5, 0.5)
        if dl and pdf > 0.0 and ((wo[2] * wi[2] > 0.0) == refl):
            return wo, wt, pdf, True
    return ZERO3, ZERO3, 0.0, False


# leaf (forceinline), as same_delta_lobe, mixed.replay_direction, halfvector.halfvector_copy* and
# reconnection.reconnect: as plain non-inlined functions, shared with the volume kernel, LLVM inlined them
# into the surface kernel only when that kernel compiled them first; after a fog-box render (the volume
# kernel first, in one process or through the disk cache) the surface kernel called them with the scene
# as ~100 scalars and ran 30 % slower (benchmarks/README.md, "gpt speed ... session 2")
@leaf
def shift_direction(sa, action, k, of, mat_o, bv, nx, cfg, stack):
    """Shift the segment leaving offset vertex k by ``action`` (base vertex ``bv``
    (:class:`~gdlearn.integrators.path.params.BaseVertex`): local wi_b -> wo_b sampled with density pdf_b
    and numbers us; ``nx``: the base's next vertex x_{b+1}). Updates beta' and lr in place and returns
    ``(wo_world, ok, lobe_class', pdf', delta')``. For a reconnection wo_world points at x_{b+1} and
    visibility has been tested."""
    x_b, wi_b, wo_b, pdf_b, delta_b = bv.x, bv.wi, bv.wo, bv.pdf, bv.delta
    u_lobe, u1, u2 = bv.us[0], bv.us[1], bv.us[2]
    x_next, ng_next = nx.p, nx.ng
    p_o = get3(of, k, F_POS)
    ns_o = get3(of, k, F_NS)
    s, t = coordinate_system(ns_o)
    wi_o = to_local(get3(of, k, F_WI), s, t, ns_o)
    if action == SHIFT_REPLAY:           # Sec. 3.1: the base's random numbers, J = p_b / p'
        wo, wt, pdf, dl = bsdf_sample(mat_o, wi_o, u_lobe, u1, u2)
        if not pdf > 0.0 or dl != delta_b:
            return ZERO3, False, 0, 0.0, False
        set3(of, k, F_BETA, mul3(get3(of, k, F_BETA), wt))          # f' J / p_b = f' / p'
        return to_world(wo, s, t, ns_o), True, lobe_class(mat_o, dl, cfg.threshold), pdf, dl
    if action == SHIFT_RECONNECT:        # Sec. 3.3: join x'_i to x_{i+1}, area Jacobian 1
        w_b, _, _, j_sa, ok = reconnect(x_b, p_o, x_next, ng_next)
        if not ok:
            return ZERO3, False, 0, 0.0, False
        if cfg.broken == BROKEN_JACOBIAN:
            j_sa = 1.0
        if occluded(sa, p_o, get3(of, k, F_NG), x_next, stack):
            return ZERO3, False, 0, 0.0, False
        wo = to_local(w_b, s, t, ns_o)
        f, pdf = bsdf_eval_pdf(mat_o, wi_o, wo)
        _update(of, k, f, j_sa, pdf, pdf_b)
        return w_b, True, lobe_class(mat_o, False, cfg.threshold), pdf, False
    # Sec. 3.2, Eq. 15: half-vector copy
    if delta_b:
        wo, wt, pdf, ok = same_delta_lobe(mat_o, wi_o, wi_b[2] * wo_b[2] > 0.0)
        if not ok:
            return ZERO3, False, 0, 0.0, False
        _update(of, k, sc3(wt, pdf), 1.0, pdf, pdf_b)
        return to_world(wo, s, t, ns_o), True, L.V_SPECULAR, pdf, True
    wo, j, ok = halfvector_copy_mat(mat_o, wi_b, wo_b, wi_o, False)
    if not ok:
        return ZERO3, False, 0, 0.0, False
    if cfg.broken == BROKEN_HV_JACOBIAN:
        j = 1.0
    f, pdf = bsdf_eval_pdf(mat_o, wi_o, wo)
    _update(of, k, f, j, pdf, pdf_b)
    return to_world(wo, s, t, ns_o), True, lobe_class(mat_o, False, cfg.threshold), pdf, False


@leaf
def relabel(of, k, mat_o, bv, wo_w, lcls, cfg):
    """``(ok, effect class)`` of offset k's vertex after a shift that did not sample its lobe
    (reconnection, half-vector copy, following the base), when the effects mask is restricted (the
    class for the shift decisions stays ``lcls``): on a rough plastic
    the base's sampled label ``bv.cls_b`` with the weight P_y / P_x of
    :func:`~gdlearn.kernels.bsdf.dispatch.lobe_class_ratio` folded into beta', so the offset's
    expected per-class value is its own path's split; ``ok`` False fails the shift where that split
    cannot be carried over (one side a rough plastic, the other not). Unrestricted renders and
    non-plastic pairs keep ``lcls`` (the class does not matter there, or is exact)."""
    if cfg.mask == ALL_MASK or bv.delta or bv.kind != VB_SURFACE:
        return True, lcls
    ns = get3(of, k, F_NS)
    s, t = coordinate_system(ns)
    r, ok = lobe_class_ratio(bv.mat, bv.wi, bv.wo, bv.cls_b, mat_o, to_local(get3(of, k, F_WI), s, t, ns),
                             to_local(wo_w, s, t, ns), cfg.threshold)
    if not ok:
        return False, lcls
    if int(mat_o[L.MAT_TYPE]) != L.ROUGHPLASTIC:
        return True, lcls
    set3(of, k, F_BETA, sc3(get3(of, k, F_BETA), r))
    return True, bv.cls_b


@leaf
def replayed_class(of, k, mat_o, u_lobe, delta_o, lcls, cfg):
    """The effect class of offset k's vertex after a *replay* (call it before ``set_hit`` moves the
    offset on): the lobe the offset's own BSDF sampled with the base's ``u_lobe``, exact for a rough
    plastic's coating or base, in effects-restricted renders. ``lcls`` (:func:`lobe_class`) stays the
    class for the shift decisions, which must be a function of the path, not of the sampled lobe."""
    if cfg.mask == ALL_MASK:
        return lcls
    ns = get3(of, k, F_NS)
    s, t = coordinate_system(ns)
    return sampled_lobe_class(mat_o, to_local(get3(of, k, F_WI), s, t, ns), u_lobe, delta_o, cfg.threshold)


@leaf
def _update(of, k, f, j, pdf_o, pdf_b):
    """beta' *= f' J / p_b and lr += log(p' J / p_b) (-inf when the offset density is 0: Eq. 17 then
    gives the base weight 1, as it must for a path the neighbour's tracer never samples); the weight
    w = 1 / (1 + exp(lr)) follows lr (the only writer of lr after :func:`start_weights`)."""
    set3(of, k, F_BETA, sc3(mul3(get3(of, k, F_BETA), f), j / pdf_b))
    r = pdf_o * j / pdf_b
    of[k, F_LR] += math.log(r) if r > 0.0 else -math.inf
    of[k, F_W] = mis_weight_from_log_ratio(of[k, F_LR])


@leaf
def start_weights(of, k):
    """lr = 0 and its weight 1/2 (Eq. 17 for equal densities) for an offset at the pixel shift."""
    of[k, F_LR] = 0.0
    of[k, F_W] = mis_weight_from_log_ratio(0.0)


@leaf
def follow_base(sa, k, of, oi, bv, cfg):
    """Offset k shares the base vertex x_b (``bv``): same outgoing direction (J = 1). A JOINED offset
    arrives from its own direction, so f and the density differ once more; a delta lobe cannot be followed."""
    mat, wo, pdf, delta, p = bv.mat, bv.wo, bv.pdf, bv.delta, bv.x
    if oi[k, I_RECONN] == JOINED:
        if delta:
            oi[k, I_ALIVE] = FAILED
            return
        ns = get3(of, k, F_NS)
        s, t = coordinate_system(ns)
        wi_o = to_local(get3(of, k, F_WI), s, t, ns)
        f, pdf_o = bsdf_eval_pdf(mat, wi_o, wo)
        _update(of, k, f, 1.0, pdf_o, pdf)
        ok, lcls = relabel(of, k, mat, bv, to_world(wo, s, t, ns), lobe_class(mat, False, cfg.threshold), cfg)
        if not ok:
            oi[k, I_ALIVE] = FAILED
            return
        of[k, F_PREV_PDF] = pdf_o
        oi[k, I_PREV_DELTA] = 0
        oi[k, I_STATE] = pc_push(oi[k, I_STATE], lcls)
        oi[k, I_RECONN] = MERGED
    else:
        follow_merged(of, oi, k, bv)
        return
    set3(of, k, F_PREV_P, p)


@leaf
def follow_merged(of, oi, k, bv):
    """A MERGED offset (identical to the base from x_b on) follows the base's segment leaving x_b:
    f' / p = the base's weight. No ray, no BSDF evaluation (the reference implementation's cost of
    a reconnected offset); the caller moves its vertex to x_{b+1} (:func:`set_hit`)."""
    set3(of, k, F_BETA, mul3(get3(of, k, F_BETA), bv.weight))
    of[k, F_PREV_PDF] = bv.pdf
    oi[k, I_PREV_DELTA] = 1 if bv.delta else 0
    oi[k, I_STATE] = pc_push(oi[k, I_STATE], bv.cls_b)
    set3(of, k, F_PREV_P, bv.x)
