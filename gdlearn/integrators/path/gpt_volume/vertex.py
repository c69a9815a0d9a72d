"""Per-vertex pieces of volumetric G-PT (Gruson et al. 2018, Sec. 6 "G-PT"; Kettunen et al. 2015;
STAR, Hua et al. 2019, Sec. 3 and 7.1): offset state, Eq. 16-17 pairs, next-event estimation on an
offset vertex (surface or medium), the phase-function replay, the reconnection to a surface *or
medium* vertex, and following a base path after a reconnection. The loop is :mod:`gdlearn.integrators.path.gpt_volume.lockstep`.

Offset state: the rows of the surface G-PT (:mod:`gdlearn.integrators.path.gpt_surface.vertex`: vertex, incoming
direction, beta' = f(T x) |J| / p(x) so far, lr = log of p'|J| / p, previous vertex and pdf) plus the
offset's current ray (origin, direction, tmax), the medium it travels in (or of its medium vertex)
and the kind of its vertex (surface, medium, escaped). A medium vertex has ng = ns = 0, material -1.
"""
import math


from gdlearn.kernels.bsdf.dispatch import bsdf_eval, bsdf_is_delta_only, bsdf_pdf, lobe_class, vertex_class
from gdlearn.kernels.camera import camera_ray
from gdlearn.integrators.path.gpt_surface.mixed import unpaired
from gdlearn.integrators.path.gpt_surface.vertex import (BROKEN_JACOBIAN, BROKEN_MIS, BROKEN_PRIMAL, BROKEN_UNPAIRED, F_BETA, F_LR, F_W,
                                       F_NG, F_NS, F_POS, F_PREV_P, F_PREV_PDF, F_WI, I_ALIVE, I_ESCAPED, I_MAT,
                                       I_PREV_DELTA, I_PRIM, I_RECONN, I_STATE, JOINED, MERGED, FREE, NF, NI, get3,
                                       light_weight, mul3, sc3, set3)
from gdlearn.kernels.layout import V_MEDIUM
from gdlearn.kernels.lights import E_AREA, E_POINT, E_SPOT, EM_TYPE, same_direction_point
from gdlearn.kernels.media.medium import medium_params
from gdlearn.kernels.pathclass import pc_class, pc_init, pc_push
from gdlearn.kernels.media.phase import hg_eval, hg_sample
from gdlearn.kernels.sampling import power_heuristic
from gdlearn.kernels.vec import coordinate_system, dot, to_local
from gdlearn.integrators.path.volume import next_medium, shadow_transmittance
from gdlearn.integrators.path.gpt_volume.flight import EV_SCATTER, segment_to
from gdlearn.shifts.mis import mis_weight_from_log_ratio
from gdlearn.shifts.reconnection import reconnect
from gdlearn.shifts.replay import neighbour_inside, offset_film_position
from gdlearn.kernels.jit import leaf, noalloc
from gdlearn.integrators.path.params import VB_MEDIUM

ZERO3 = (0.0, 0.0, 0.0)
ONE3 = (1.0, 1.0, 1.0)
#: alive flags: shift not traced (outside the image), failed, alive
OUTSIDE, FAILED, ALIVE = -1, 0, 1
#: extra float columns: the offset's current ray; the log ratio F_WLR for which the Eq. 17 weight F_W
#: (``gpt_surface.vertex``'s column) was computed (:func:`pair` recomputes it only when lr has changed:
#: lr changes once per shifted segment, the weight is read by every technique of every vertex after it)
F_O, F_D, F_TMAX, F_WLR = NF, NF + 3, NF + 6, NF + 7
NFV = NF + 8
#: extra int columns: medium of the ray / medium vertex, vertex kind
I_MED, I_KIND = NI, NI + 1
NIV = NI + 2
K_SURFACE, K_MEDIUM, K_ESCAPED = 0, 1, 2


@leaf
def scatter_eval(sa, of, oi, k, w_out, ng):
    """The scattering function at offset vertex k towards world direction ``w_out``: the phase
    function at a medium vertex (Henyey-Greenstein, f = pdf), the BSDF f |cos| and its pdf at a
    surface vertex. Returns ``(f rgb, pdf, medium the ray towards w_out travels in)``; the medium
    changes only where a surface vertex sends the ray through its boundary."""
    wi_w = get3(of, k, F_WI)
    medium = oi[k, I_MED]
    if oi[k, I_KIND] == K_MEDIUM:
        _, _, g = medium_params(sa.media[medium])
        f1 = hg_eval(g, dot(wi_w, w_out))
        return (f1, f1, f1), f1, medium
    ns = get3(of, k, F_NS)
    mat = sa.materials[oi[k, I_MAT]]
    s, t = coordinate_system(ns)
    wi = to_local(wi_w, s, t, ns)
    wo = to_local(w_out, s, t, ns)
    f = bsdf_eval(mat, wi, wo)
    pdf = bsdf_pdf(mat, wi, wo)
    return f, pdf, next_medium(sa.prim_info, oi[k, I_PRIM], medium, w_out, ng)


@leaf
def wanted(cfg, state):
    return (cfg.mask >> pc_class(state)) & 1 == 1


# leaf (inlined), as are update, follow_joined and push_medium_vertex below, which run once per offset
# and vertex: as calls they took the scene as scalars (gpt on the spot medium and the medium cube
# 3-5 % faster inlined)
@leaf
def start_offsets(sa, px, of, oi):
    """The pixel shift (Eq. 3): the neighbours' camera rays with the base's sub-pixel jitter (``px``:
    :class:`~gdlearn.integrators.path.params.Pixel`), in the camera's medium. Their first flight is
    shifted once the base's is known."""
    fx, fy, x, y, w, h = px.fx, px.fy, px.x, px.y, px.w, px.h
    for k in range(4):
        if not neighbour_inside(x, y, k, w, h):
            oi[k, I_ALIVE] = OUTSIDE
            continue
        ox, oy = offset_film_position(fx, fy, k)
        o, d, tmax = camera_ray(sa.camera, ox, oy)
        set3(of, k, F_O, o)
        set3(of, k, F_D, d)
        of[k, F_TMAX] = tmax
        set3(of, k, F_BETA, ONE3)
        of[k, F_LR] = 0.0
        of[k, F_WLR] = 0.0
        of[k, F_W] = mis_weight_from_log_ratio(0.0)
        of[k, F_PREV_PDF] = 1.0
        set3(of, k, F_PREV_P, o)
        oi[k, I_PREV_DELTA] = 1
        oi[k, I_RECONN] = FREE
        oi[k, I_STATE] = pc_init()
        oi[k, I_MED] = sa.camera_medium
        oi[k, I_ALIVE] = ALIVE


@leaf
def set_vertex(sa, of, oi, k, kind, prim, p, ng, ns, d, medium):
    """Make the event of a flight along d offset k's current vertex."""
    set3(of, k, F_POS, p)
    set3(of, k, F_NG, ng)
    set3(of, k, F_NS, ns)
    set3(of, k, F_WI, (-d[0], -d[1], -d[2]))
    oi[k, I_KIND] = kind
    oi[k, I_ESCAPED] = 1 if kind == K_ESCAPED else 0
    oi[k, I_PRIM] = prim
    oi[k, I_MAT] = sa.prim_info[prim, 1] if kind == K_SURFACE else -1
    oi[k, I_MED] = medium


@noalloc
def set_ray(of, oi, k, o, d, medium):
    set3(of, k, F_O, o)
    set3(of, k, F_D, d)
    of[k, F_TMAX] = math.inf
    oi[k, I_MED] = medium


@leaf
def scale_log(of, k, log_f, log_p):
    """beta'_c *= exp(log f'_c - log p) (f' the offset's factor, p the base's density)."""
    b = get3(of, k, F_BETA)
    set3(of, k, F_BETA, (b[0] * math.exp(log_f[0] - log_p), b[1] * math.exp(log_f[1] - log_p),
                         b[2] * math.exp(log_f[2] - log_p)))


# pair, nee_offset, nee_pairs (and mixed.shift_free_mixed) are inlined: they run per offset and
# vertex, and a call passes the scene's arrays and the vertex tuples as well over a hundred scalars.
# Inlining them made gpt's passes in media 1.4-1.7x faster; inlining more made them slower again
# (benchmarks/README.md, "Calls that pass the scene").
@leaf
def pair(diff, summ, of, oi, k, co, cb, cfg):
    """Eq. 16 with Eq. 17's weight for one technique: D += w (C' - C), S += w C'; a failed shift
    D -= C (w = 1, offset 0). w = 0 (offset density overwhelming) adds nothing, even if C' overflowed.
    A pair of zeros adds nothing and is skipped."""
    if co[0] == 0.0 and co[1] == 0.0 and co[2] == 0.0 and cb[0] == 0.0 and cb[1] == 0.0 and cb[2] == 0.0:
        return
    if oi[k, I_ALIVE] == ALIVE:
        lr = of[k, F_LR]
        if lr != of[k, F_WLR]:            # (NaN: recomputed every time, weight 1)
            of[k, F_W] = mis_weight_from_log_ratio(lr)
            of[k, F_WLR] = lr
        wgt = 1.0 if cfg.broken == BROKEN_MIS else of[k, F_W]
        if wgt > 0.0:
            ws = 1.0 if cfg.broken == BROKEN_PRIMAL else wgt
            for c in range(3):
                diff[k, c] += wgt * (co[c] - cb[c])
                summ[k, c] += ws * co[c]
    elif oi[k, I_ALIVE] == FAILED:
        for c in range(3):
            diff[k, c] -= cb[c]


#: no transmittance known for :func:`nee_offset` (it traces the shadow segment itself)
TR_UNKNOWN = (-1.0, -1.0, -1.0)


@leaf
def nee_offset(sa, em, q, nq, of, oi, k, stack, tr_known, m_known):
    """Next event of offset k's vertex towards the fixed light point q (area Jacobian 1): Le / pdf,
    the BSDF (surface) or phase function (medium), the transmittance of the offset's *own* shadow
    segment (null interfaces crossed) and the power heuristic against BSDF / phase sampling.
    ``tr_known``: the transmittance of this very segment in medium ``m_known`` when the base traced
    it (an offset JOINED at the base's vertex, :func:`nee_pairs`), else :data:`TR_UNKNOWN`."""
    p = get3(of, k, F_POS)
    w_em, pdf_em, delta, dl = light_weight(sa, em, q, nq, p)
    if not (w_em[0] + w_em[1] + w_em[2] > 0.0):
        return ZERO3
    ng = get3(of, k, F_NG)
    f, pdf_dir, medium = scatter_eval(sa, of, oi, k, dl, ng)
    if f[0] == 0.0 and f[1] == 0.0 and f[2] == 0.0:
        return ZERO3
    if medium == m_known and tr_known[0] >= 0.0:
        tr = tr_known
    else:
        tr = shadow_transmittance(sa, p, ng, q, medium, stack)
    if tr[0] == 0.0 and tr[1] == 0.0 and tr[2] == 0.0:
        return ZERO3
    mw = 1.0 if delta else power_heuristic(pdf_em, pdf_dir)
    return sc3(mul3(mul3(f, w_em), tr), mw)


@leaf
def nee_pairs(sa, em, q, nq, p, nb, tr_b, m_b, cb, of, oi, diff, summ, cfg, medium_vertex, stack):
    """Shift the base's next-event sample (light point q, unweighted value nb) to every live offset
    by reconnecting to the same light point (directional / constant: the same direction). An offset
    JOINED at the base's vertex p has the base's shadow segment: its transmittance ``tr_b`` (in
    medium ``m_b``; :data:`TR_UNKNOWN` if the base traced none) is reused, as the surface kernel
    reuses the base's visibility."""
    et = int(sa.emitters[em, EM_TYPE])
    fixed_point = et == E_AREA or et == E_POINT or et == E_SPOT
    for k in range(4):
        co = ZERO3
        if oi[k, I_ALIVE] == ALIVE:
            kind = oi[k, I_KIND]
            # (mixed policies) no next-event technique at an escaped or delta-only offset vertex: weight 1
            if (kind == K_ESCAPED or (kind == K_SURFACE and bsdf_is_delta_only(sa.materials[max(oi[k, I_MAT], 0)]))) \
                    and cfg.broken != BROKEN_UNPAIRED:
                unpaired(diff, k, cb)
                continue
            st = oi[k, I_STATE]
            if kind == K_SURFACE:        # the offset's own vertex (of the base's kind unless mixed)
                st = pc_push(st, vertex_class(sa.materials[oi[k, I_MAT]], cfg.threshold))
            if wanted(cfg, st):
                if oi[k, I_RECONN] == MERGED:
                    no = nb
                else:
                    po = get3(of, k, F_POS)
                    qo = q if fixed_point else same_direction_point(sa.emitters, em, p, q, po)
                    same = oi[k, I_RECONN] == JOINED and fixed_point and po == p
                    no = nee_offset(sa, em, qo, nq, of, oi, k, stack, tr_b if same else TR_UNKNOWN, m_b)
                co = mul3(get3(of, k, F_BETA), no)
        pair(diff, summ, of, oi, k, co, cb, cfg)


@leaf
def update(of, k, f, j, pdf_o, pdf_b):
    """beta' *= f' J / p_b and lr += log(p' J / p_b) (-inf when the offset density is 0)."""
    set3(of, k, F_BETA, sc3(mul3(get3(of, k, F_BETA), f), j / pdf_b))
    r = pdf_o * j / pdf_b
    of[k, F_LR] += math.log(r) if r > 0.0 else -math.inf


@noalloc
def replay_phase(sa, of, oi, k, u1, u2):
    """Phase sampling at a medium vertex, replayed (STAR Sec. 3.1): the base's random numbers through
    the offset's own HG lobe. HG is sampled exactly, so f'/p' = 1 and the replay Jacobian p_b / p'
    makes the density ratio 1: beta' and lr are unchanged. Sets the offset's ray; returns p'."""
    _, _, g = medium_params(sa.media[oi[k, I_MED]])
    wo, pdf = hg_sample(g, get3(of, k, F_WI), u1, u2)
    p = get3(of, k, F_POS)
    set_ray(of, oi, k, p, wo, oi[k, I_MED])
    return pdf


@noalloc
def reconnect_offset(sa, of, oi, k, bv, nx, lp_b, cfg, stack):
    """Reconnection of offset vertex x'_i (surface or medium) to the base's next vertex x_{i+1} = ``nx.p``
    (``bv``: the base vertex x_i, :class:`~gdlearn.integrators.path.params.BaseVertex`)
    (surface or medium; STAR Sec. 3.3, Jacobian 1 in area / volume). In the (direction, distance)
    measure the Jacobian is |dw'/dw| of ``reconnection.reconnect`` (cosine 1 at a medium vertex:
    dV = t^2 dw dt on both paths); the offset segment's own transmittance, pass / collision density
    and the medium it arrives in (which must be the base's) come from ``segment_to``. Returns
    (ok, pdf' of the direction)."""
    x_b, pdf_b = bv.x, bv.pdf
    ev, prim2, p2, ng2, ns2, med2 = nx.ev, nx.prim, nx.p, nx.ng, nx.ns, nx.med
    p_o = get3(of, k, F_POS)
    ng_o = get3(of, k, F_NG)
    w_o, _, _, j_sa, ok = reconnect(x_b, p_o, p2, ng2)
    if not ok:
        return False, 0.0
    if cfg.broken == BROKEN_JACOBIAN:
        j_sa = 1.0
    f, pdf, medium = scatter_eval(sa, of, oi, k, w_o, ng_o)
    seg_ok, lf, lp, med_arr = segment_to(sa, p_o, ng_o, p2, medium, ev == EV_SCATTER, stack)
    if not seg_ok or med_arr != med2:
        return False, 0.0
    update(of, k, f, j_sa, pdf, pdf_b)
    scale_log(of, k, lf, lp_b)
    of[k, F_LR] += lp - lp_b
    kind = K_MEDIUM if ev == EV_SCATTER else K_SURFACE
    set_vertex(sa, of, oi, k, kind, prim2, p2, ng2, ns2, w_o, med2)
    oi[k, I_RECONN] = JOINED
    return True, pdf


@leaf
def follow_joined(sa, of, oi, k, bv, cfg):
    """A JOINED offset k shares the base vertex x_b (``bv``,
    :class:`~gdlearn.integrators.path.params.BaseVertex`) and takes the same outgoing direction
    (J = 1), but it arrives from its own direction, so f and the density differ once more (a delta
    lobe cannot be followed). From here on it is MERGED (:func:`follow_merged`)."""
    wo_b_local, pdf_b = bv.wo, bv.pdf
    wi_w = get3(of, k, F_WI)
    if bv.kind == VB_MEDIUM:
        _, _, g = medium_params(sa.media[oi[k, I_MED]])
        f1 = hg_eval(g, dot(wi_w, bv.wo_w))
        update(of, k, (f1, f1, f1), 1.0, f1, pdf_b)
        of[k, F_PREV_PDF] = f1
    else:
        if bv.delta:
            oi[k, I_ALIVE] = FAILED
            return
        ns = get3(of, k, F_NS)
        s, t = coordinate_system(ns)
        wi = to_local(wi_w, s, t, ns)
        f = bsdf_eval(bv.mat, wi, wo_b_local)
        pdf_o = bsdf_pdf(bv.mat, wi, wo_b_local)
        update(of, k, f, 1.0, pdf_o, pdf_b)
        of[k, F_PREV_PDF] = pdf_o
        oi[k, I_STATE] = pc_push(oi[k, I_STATE], lobe_class(bv.mat, False, cfg.threshold))
    oi[k, I_PREV_DELTA] = 0
    oi[k, I_RECONN] = MERGED
    set3(of, k, F_PREV_P, bv.x)


@leaf
def follow_merged(of, oi, k, bv):
    """A MERGED offset k (the base path itself from x_b on) follows the base's segment: f' / p = the
    base's weight, no evaluation. Inlined into the caller's offset loop (a call would pass the
    whole base vertex as arguments, once per offset and segment)."""
    set3(of, k, F_BETA, mul3(get3(of, k, F_BETA), bv.weight))
    of[k, F_PREV_PDF] = bv.pdf
    oi[k, I_PREV_DELTA] = 1 if bv.delta else 0
    if bv.kind != VB_MEDIUM:
        oi[k, I_STATE] = pc_push(oi[k, I_STATE], bv.cls_b)
    set3(of, k, F_PREV_P, bv.x)


@leaf
def push_medium_vertex(oi):
    """Every live offset that has just reached a medium vertex (with the base, or on its own under a
    mixed policy's replayed flight): its class joins the path state."""
    for k in range(4):
        if oi[k, I_ALIVE] == ALIVE and oi[k, I_KIND] == K_MEDIUM:
            oi[k, I_STATE] = pc_push(oi[k, I_STATE], V_MEDIUM)
