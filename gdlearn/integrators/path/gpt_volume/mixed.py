"""Mixed replay / reconnection shifts of volumetric G-PT (policies ``replay+reconnection`` and
``halfvector+replay+reconnection``; STAR, Hua et al. 2019, Sec. 3.1, 3.3, 3.5 and 7.1). The surface
version, with the Jacobian and the reversibility argument, is :mod:`gdlearn.integrators.path.gpt_surface.mixed`; the
loop that calls :func:`shift_free_mixed` is :mod:`gdlearn.integrators.path.gpt_volume.lockstep`.

What changes in a medium. Kettunen et al.'s policy copies the base's free-flight distance to the
offset's ray (Gruson et al. 2018, Sec. 4.1) and fails when the offset meets a surface first. A mixed
policy instead *replays* the flight: volpath's distance sampling runs along the offset's ray with the
base's random numbers (:func:`gdlearn.integrators.path.gpt_volume.flight.base_flight`), so the offset scatters
where the neighbour's path tracer would, or reaches its own surface, or escapes -- an event of any
kind, never a failure. In one homogeneous medium that *is* the distance copy whenever the offset's
ray is long enough. Replayed flights are primary-sample-space identities: beta' *= f'/p' of the
offset's own flight (transmittances, collision or pass densities, spectral MIS) and the Eq. 17 log
ratio is unchanged, exactly as for a replayed direction (Eq. 6). Phase sampling at a medium vertex
is replayed; a medium vertex is connectable, so a scattering offset reconnects to a connectable base
vertex and vice versa. A replayed flight may cross more or fewer null interfaces than the base's
(one ray enters a medium's boundary, its neighbour passes beside it): the random numbers of the
flights after null interfaces have their own dimensions (``surface.flight_dim``), so the offset
still reads, at its next vertex, the numbers its own path tracer would read there, and the shift
stays the identity in primary sample space. (Numbered by segments instead, 11 % of the replays on
the medium cube had to fail; benchmarks/README.md, issue 20.)

Short segments: a reconnection also needs both segments to x_{b+1} at least twice as long as the
distance between x_b and x'_b (``reconnection.far_enough``): it bounds the distance ratio of the
Jacobian, which a dense medium's short flights otherwise swing by factors of 10; such a step replays.

Reversibility: as on surfaces, a step that did not reconnect fails when the backward shift would
reconnect the base vertex to the offset's new vertex y_{b+1} (:func:`inverse_reconnects_volume`:
connectable classes, segments long enough, not grazing, the segment x_b -> y_{b+1} free of non-null
surfaces and arriving in y_{b+1}'s medium). tests/test_gpt_volume_reversibility.py shifts base paths
of the four media scenes forward and back, vertex by vertex.
"""


from gdlearn.kernels.bsdf.dispatch import vertex_class
from gdlearn.kernels.geometry import offset_origin
from gdlearn.integrators.path.gpt_surface.mixed import replay_direction
from gdlearn.integrators.path.gpt_surface.vertex import (BROKEN_REPLAY_WEIGHT, BROKEN_REVERSIBILITY, F_BETA, F_NG,
                                                         F_POS, F_PREV_P, F_PREV_PDF, I_MAT, I_PREV_DELTA, I_PRIM,
                                                         I_STATE, get3, mul3, set3, shift_direction)
from gdlearn.shifts.policy import conn
from gdlearn.integrators.path.gpt_volume.flight import EV_FAIL, EV_SCATTER, EV_SURFACE, base_flight, segment_to
from gdlearn.integrators.path.gpt_volume.vertex import (F_D, F_O, F_TMAX, I_KIND, I_MED, K_ESCAPED, K_MEDIUM, K_SURFACE,
                                               reconnect_offset, replay_phase, set_ray, set_vertex)
from gdlearn.kernels.layout import V_MEDIUM
from gdlearn.kernels.pathclass import pc_push
from gdlearn.integrators.path.volume import next_medium
from gdlearn.shifts.policy import SHIFT_HALFVECTOR, SHIFT_RECONNECT, SHIFT_REPLAY, mixed_action, mixed_decide, record
from gdlearn.shifts.reconnection import far_enough, reconnect
from gdlearn.kernels.jit import leaf, noalloc
from gdlearn.integrators.path.params import VB_CAMERA, VB_MEDIUM

ONE3 = (1.0, 1.0, 1.0)


@noalloc
def replay_flight(sa, of, oi, k, bounce, rng, cfg, stack):
    """volpath's flight along offset k's ray with the base's random numbers of the flight leaving
    ``bounce`` (module docstring). False if it ends in no event (more than ``MAX_SEGMENTS`` null
    interfaces)."""
    d = get3(of, k, F_D)
    ev, med, _, W, _, _, prim, p, ng, ns = base_flight(sa, get3(of, k, F_O), d, of[k, F_TMAX], oi[k, I_MED],
                                                       ONE3, rng, bounce, stack, False)   # log p unused
    if ev == EV_FAIL:
        return False
    if cfg.broken != BROKEN_REPLAY_WEIGHT:
        set3(of, k, F_BETA, mul3(get3(of, k, F_BETA), W))
    kind = K_SURFACE if ev == EV_SURFACE else (K_MEDIUM if ev == EV_SCATTER else K_ESCAPED)
    set_vertex(sa, of, oi, k, kind, prim, p, ng, ns, d, med)
    return True


@noalloc
def inverse_reconnects_volume(sa, oi, of, k, lobe_y, y_b, bv, cls_x, cfg, stack):
    """Would the backward shift (base: offset k, whose new vertex y2 is its current one; offset: the base
    vertex x_b = ``bv.x``) reconnect x_b to y2? ``lobe_y``: class of the offset's direction at y_b;
    ``cls_x``: class of x_b; x_b arrived in medium ``bv.med`` (on primitive ``bv.prim``, geometric normal
    ``bv.ng``, unless it is a medium vertex)."""
    x_b, ng_b, prim_b, med_b, vb_medium = bv.x, bv.ng, bv.prim, bv.med, bv.kind == VB_MEDIUM
    kind = oi[k, I_KIND]
    if kind == K_ESCAPED or not (conn(lobe_y) and conn(cls_x)):
        return False
    if kind == K_SURFACE and not conn(vertex_class(sa.materials[oi[k, I_MAT]], cfg.threshold)):
        return False
    y2 = get3(of, k, F_POS)
    if not far_enough(y_b, x_b, y2):
        return False
    w, _, _, _, ok = reconnect(y_b, x_b, y2, get3(of, k, F_NG))
    if not ok:
        return False
    m = med_b if vb_medium else next_medium(sa.prim_info, prim_b, med_b, w, ng_b)
    seg_ok, _, _, med_arr = segment_to(sa, x_b, ng_b, y2, m, kind == K_MEDIUM, stack)
    return seg_ok and med_arr == oi[k, I_MED]


@noalloc
def _continue(sa, of, oi, k, action, medium_o, mat_o, bv, nx, cfg, stack):
    """The offset's own next direction (replay, or the half-vector copy of the base's at ``bv``, towards
    ``nx``) and its ray. Returns ``(ok, lobe_class', pdf', delta')``."""
    us = bv.us
    if medium_o:                                       # phase sampling is replayed
        pdf_o = replay_phase(sa, of, oi, k, us[1], us[2])
        return pdf_o > 0.0, V_MEDIUM, pdf_o, False
    if action == SHIFT_REPLAY:
        wo_w, ok, lcls, pdf_o, delta_o = replay_direction(sa, k, of, mat_o, us[0], us[1], us[2], cfg)
    else:
        wo_w, ok, lcls, pdf_o, delta_o = shift_direction(sa, SHIFT_HALFVECTOR, k, of, mat_o, bv, nx, cfg, stack)
    if ok:
        p_o, ng_o = get3(of, k, F_POS), get3(of, k, F_NG)
        set_ray(of, oi, k, offset_origin(p_o, ng_o, wo_w), wo_w,
                next_medium(sa.prim_info, oi[k, I_PRIM], oi[k, I_MED], wo_w, ng_o))
    return ok, lcls, pdf_o, delta_o


# inlined: see gpt_volume.vertex.pair
@leaf
def shift_free_mixed(sa, of, oi, k, cfg, bv, nx, bounce, rng, lp_b, stats, stack):
    """Shift a not yet reconnected offset along the base's segment x_b -> x_{b+1} by a mixed policy
    (``bv``, ``nx``: :class:`~gdlearn.integrators.path.params.BaseVertex`, ``NextVertex``). Returns False
    when the offset fails or its path ends (the caller marks it: later base techniques are unpaired).
    ``bv.cls_s``: class of the base's direction at x_b (``lobe_class``, V_MEDIUM)."""
    vb_medium, mat_b, cls_s = bv.kind == VB_MEDIUM, bv.mat, bv.cls_s
    cls_next = nx.cls
    if bv.kind == VB_CAMERA:               # the pixel shift set the ray: replay the first flight
        ok = replay_flight(sa, of, oi, k, bounce, rng, cfg, stack)
        if not ok:
            record(stats, SHIFT_REPLAY, False)
        return ok
    if oi[k, I_KIND] == K_ESCAPED:         # the offset path ended
        return False
    medium_o = oi[k, I_KIND] == K_MEDIUM
    mat_o = sa.materials[max(oi[k, I_MAT], 0)]
    cls_o = V_MEDIUM if medium_o else vertex_class(mat_o, cfg.threshold)
    cb, co = conn(cls_s), conn(cls_o)
    p_o = get3(of, k, F_POS)
    # C(x_b, x'_b, x_{b+1}) (the table, shifts.policy.mixed_decide) and segments long enough
    # (reconnection.far_enough); too short, blocked or grazing: continue instead
    if mixed_decide(cfg.policy, cls_s, cls_o, cls_next) == SHIFT_RECONNECT and far_enough(bv.x, p_o, nx.p):
        ok, pdf_o = reconnect_offset(sa, of, oi, k, bv, nx, lp_b, cfg, stack)
        if ok:
            record(stats, SHIFT_RECONNECT, True)
            _advance(of, oi, k, p_o, pdf_o, False, medium_o, V_MEDIUM if medium_o else vertex_class(mat_o, cfg.threshold))
            return True
    action = mixed_action(cfg.policy, cb, co)
    ok, lcls, pdf_o, delta_o = _continue(sa, of, oi, k, action, medium_o, mat_o, bv, nx, cfg, stack)
    if not ok:                             # replay: the neighbour's tracer stops too; a copy failed
        record(stats, action, action == SHIFT_REPLAY)
        return False
    ok = replay_flight(sa, of, oi, k, bounce, rng, cfg, stack)
    if ok and cfg.broken != BROKEN_REVERSIBILITY:
        cls_x = V_MEDIUM if vb_medium else vertex_class(mat_b, cfg.threshold)
        ok = not inverse_reconnects_volume(sa, oi, of, k, lcls, p_o, bv, cls_x, cfg, stack) and \
            mixed_action(cfg.policy, conn(lcls), conn(cls_x)) == action
    record(stats, action, ok)
    if ok:
        _advance(of, oi, k, p_o, pdf_o, delta_o, medium_o, lcls)
    return ok


@leaf
def _advance(of, oi, k, p_o, pdf_o, delta_o, medium_o, lcls):
    set3(of, k, F_PREV_P, p_o)
    of[k, F_PREV_PDF] = pdf_o
    oi[k, I_PREV_DELTA] = 1 if delta_o else 0
    if not medium_o:
        oi[k, I_STATE] = pc_push(oi[k, I_STATE], lcls)
