"""Mixed replay / reconnection shifts of gradient-domain path tracing on surfaces: the policies
``replay+reconnection`` and ``halfvector+replay+reconnection`` (STAR, Hua et al. 2019, Sec. 3.5
"Combined Shift Mapping": "combining random sequence replay with path reconnection is a simple but
effective approach to improve robustness"; :mod:`gdlearn.shifts.policy` has the rules). The lockstep
loop that calls :func:`shift_segment_mixed` is :mod:`gdlearn.integrators.path.gpt_surface.lockstep`.

The shift. At each vertex x_b of the base path, with the offset at x'_b: reconnect x'_b to x_{b+1}
when the criterion C(x_b, x'_b, x_{b+1}) holds -- both vertices connectable (the base's by the lobe of
its sampled direction), x_{b+1} a connectable surface vertex, both segments x_b -> x_{b+1} and
x'_b -> x_{b+1} at least twice the distance between x_b and x'_b
(:func:`gdlearn.shifts.reconnection.far_enough`: it bounds the Jacobian's distance ratio to
[0.44, 2.25]), the segment x'_b -> x_{b+1} free and not grazing
(:func:`gdlearn.shifts.reconnection.reconnect`). Otherwise the offset *continues*: it replays
the base's random numbers through its own BSDF (Sec. 3.1) -- or, under the half-vector policy, copies
the half vector where both vertices are glossy / specular (Sec. 3.2) -- whatever the two vertices'
classes. A class mismatch is therefore not a failure: replay is the identity in primary sample space.

Reversibility (Sec. 3.5, Fig. 4). C is symmetric in x_b and x'_b given the shared next vertex, so the
backward shift of a reconnected pair reconnects too. A step that continued leaves the offset at its
own y_{b+1}; the backward shift would reconnect x_b to y_{b+1} exactly when C(x'_b, x_b, y_{b+1})
holds, so the forward step fails then (:func:`inverse_reconnects`) -- the only failure of
``replay+reconnection``. Everything else is a function of the pair of paths, so T^{-1}(T(x)) = x
(tests/test_gpt_reversibility.py replays both directions vertex by vertex).

Jacobian. Let the offset replay vertices 1..b and reconnect at b. Parametrise both paths by the
primary samples u_1..u_{b-1} of the replayed directions, then the area measure of x_{b+1}, x_{b+2}, ...
In those coordinates the shift is the identity: the offset has the same u's and shares x_{b+1} on, so
its Jacobian is 1 there. In the path-space (area) measure of Eq. 16-17 this is

    |dT/dx| = prod_{i<=b} p(x_i | x_<i) / p'(y_i | y_<i)   (replay, Sec. 3.1, Eq. 6)
              * 1                                           (x_{b+1}, ... shared, Sec. 3.3)

and in the solid-angle measure of the directions the path tracer samples: p_i / p'_i per replayed
direction, the solid-angle form of the reconnection (|cos'_{b+1}| / |cos_{b+1}| * |x_b - x_{b+1}|^2 /
|y_b - x_{b+1}|^2, :mod:`gdlearn.shifts.reconnection`) for the direction leaving b, and 1 for the
shared directions. Hence, per technique, f(T x)|J| / p(x) = prod_{i<b} (f'_i / p'_i) * f'_b J_b / p_b *
f'_{b+1} / p_{b+1} * (the base's weights after b+1) -- the offset throughput beta' -- and Eq. 17's
ratio p'(Tx)|J| / p(x) = 1 for the replayed directions (the densities cancel, Eq. 6: weights 1/2 on a
purely replayed pair) times p'_b J_b / p_b * p'_{b+1} / p_{b+1}, the log ratio ``lr`` accumulates. A
half-vector step contributes J_w (Eq. 15) as in Kettunen et al.'s policy.

Techniques. A pair is formed per technique of the base (an emitter hit or a next-event sample at
some depth). Where the offset has no such technique -- a next-event sample at a delta-only offset
vertex, a path that ended (escaped, or its replayed direction has zero density) -- it has density
zero, Eq. 17 gives the base weight 1 and the offset nothing (:func:`unpaired`); where the base has
none (a delta-only base vertex), the neighbour's base path carries that technique with weight 1.
"""
import math


from gdlearn.kernels.bsdf.dispatch import bsdf_sample, lobe_class, vertex_class
from gdlearn.kernels.geometry import offset_origin
from gdlearn.integrators.path.gpt_surface.vertex import (BROKEN_REPLAY_WEIGHT, BROKEN_REVERSIBILITY, F_BETA, F_NG,
                                                         F_NS, F_POS, F_PREV_P, F_PREV_PDF, F_WI, I_ALIVE, I_ESCAPED,
                                                         I_MAT, I_PREV_DELTA, I_RECONN, I_STATE, JOINED, FAILED,
                                                         get3, mul3, relabel, replayed_class, set3, set_hit, shift_direction,
                                                         vclass_of)
from gdlearn.shifts.policy import conn
from gdlearn.kernels.pathclass import pc_push
from gdlearn.kernels.scene_query import intersect, occluded
from gdlearn.kernels.vec import coordinate_system, to_local, to_world
from gdlearn.shifts.policy import SHIFT_HALFVECTOR, SHIFT_RECONNECT, SHIFT_REPLAY, mixed_action, mixed_decide, record
from gdlearn.shifts.reconnection import far_enough, reconnect
from gdlearn.kernels.jit import ir_inline, leaf

ZERO3 = (0.0, 0.0, 0.0)


@leaf
def replay_direction(sa, k, of, mat_o, u_lobe, u1, u2, cfg):
    """Random replay at offset vertex k (Sec. 3.1): the base's numbers through the offset's own BSDF,
    any lobe (delta or not, whatever the base's was). beta' *= f'/p' (= f' J / p_b with J = p_b / p');
    the density ratio is 1, so lr is unchanged. Returns ``(wo_world, ok, lobe_class', pdf', delta')``;
    ok False where the neighbour's path tracer would stop (zero density)."""
    ns_o = get3(of, k, F_NS)
    s, t = coordinate_system(ns_o)
    wi_o = to_local(get3(of, k, F_WI), s, t, ns_o)
    wo, wt, pdf, dl = bsdf_sample(mat_o, wi_o, u_lobe, u1, u2)
    if not pdf > 0.0:
        return ZERO3, False, 0, 0.0, False
    if cfg.broken != BROKEN_REPLAY_WEIGHT:
        set3(of, k, F_BETA, mul3(get3(of, k, F_BETA), wt))
    return to_world(wo, s, t, ns_o), True, lobe_class(mat_o, dl, cfg.threshold), pdf, dl


@leaf
def inverse_reconnects(sa, lobe_y, cls_x, y_b, x_b, ng_x, hit_y2, prim_y2, y2, ng_y2, cfg, stack):
    """Would the backward shift -- base y (the offset), offset x (the base) -- reconnect x_b to y's next
    vertex y2? C(y_b, x_b, y2) of the module docstring: y's direction at y_b of a connectable lobe
    (``lobe_y``), x_b's material connectable (``cls_x``), y2 a connectable surface vertex, both
    segments to y2 long enough (``far_enough``), the segment x_b -> y2 not degenerate, not grazing y2
    and not blocked."""
    if not (hit_y2 and conn(lobe_y) and conn(cls_x)):
        return False
    if not conn(vclass_of(sa, False, prim_y2, cfg)):
        return False
    if not far_enough(y_b, x_b, y2):
        return False
    _, _, _, _, ok = reconnect(y_b, x_b, y2, ng_y2)
    return ok and not occluded(sa, x_b, ng_x, y2, stack)


@leaf
def unpaired(diff, k, cb):
    """A base technique the offset does not have (density zero): Eq. 17 weight 1, offset 0."""
    for c in range(3):
        diff[k, c] -= cb[c]


@leaf
def _reconnected(sa, of, oi, k, wo_w, prim2, p2, ng2, ns2, stats):
    set_hit(sa, of, oi, k, True, prim2, p2, ng2, ns2, wo_w)
    oi[k, I_RECONN] = JOINED
    record(stats, SHIFT_RECONNECT, True)


# IR-inlined into its one caller, lockstep._shift_offsets: compiled there only (kernels.jit)
@ir_inline
def shift_segment_mixed(sa, k, of, oi, cfg, bv, nx, stats, stack):
    """Shift offset k's segment leaving its vertex by a mixed policy (module docstring). The base
    leaves x_b = ``bv.x`` (:class:`~gdlearn.integrators.path.params.BaseVertex`: geometric normal ng, material
    mat_b, direction of lobe class ``bv.cls_s``: local wi -> wo, density pdf, ``delta``, numbers us) to
    x_{b+1} = ``nx.p`` (or escapes: ``nx.hit`` False)."""
    cls_b, mat_b, p, ng, us = bv.cls_s, bv.mat, bv.x, bv.ng, bv.us
    hit2, prim2, p2, ng2, ns2 = nx.hit, nx.prim, nx.p, nx.ng, nx.ns
    if oi[k, I_ESCAPED] == 1:             # the offset path ended: later base techniques are unpaired
        oi[k, I_ALIVE] = FAILED
        return
    mat_o = sa.materials[oi[k, I_MAT]]
    cls_o = vertex_class(mat_o, cfg.threshold)
    cb, co = conn(cls_b), conn(cls_o)
    p_o = get3(of, k, F_POS)
    ng_o = get3(of, k, F_NG)
    if mixed_decide(cfg.policy, cls_b, cls_o, vclass_of(sa, not hit2, prim2, cfg)) == SHIFT_RECONNECT and \
            far_enough(p, p_o, p2):
        # C(x_b, x'_b, x_{b+1}) with segments long enough; shift_direction tests the segment (blocked or
        # grazing: continue instead, and the backward shift's criterion fails alike)
        wo_w, ok, lcls, pdf_o, delta_o = shift_direction(sa, SHIFT_RECONNECT, k, of, mat_o, bv, nx, cfg, stack)
        if ok:
            kept, ecls = relabel(of, k, mat_o, bv, wo_w, lcls, cfg)
            if not kept:                  # a rough plastic on one side only: the shift fails (not a
                record(stats, SHIFT_RECONNECT, False)      # fallback to continuing: the backward
                oi[k, I_ALIVE] = FAILED                     # shift would reconnect)
                return
            _reconnected(sa, of, oi, k, wo_w, prim2, p2, ng2, ns2, stats)
            _advance(of, oi, k, p_o, pdf_o, delta_o, ecls)
            return
    action = mixed_action(cfg.policy, cb, co)
    if action == SHIFT_REPLAY:
        wo_w, ok, lcls, pdf_o, delta_o = replay_direction(sa, k, of, mat_o, us[0], us[1], us[2], cfg)
        if not ok:                        # the neighbour's tracer stops here too: the path ends
            record(stats, SHIFT_REPLAY, True)
            oi[k, I_ALIVE] = FAILED
            return
        ecls = replayed_class(of, k, mat_o, us[0], delta_o, lcls, cfg)
    else:
        wo_w, ok, lcls, pdf_o, delta_o = shift_direction(sa, SHIFT_HALFVECTOR, k, of, mat_o, bv, nx, cfg, stack)
        if ok:
            ok, ecls = relabel(of, k, mat_o, bv, wo_w, lcls, cfg)
        if not ok:
            record(stats, SHIFT_HALFVECTOR, False)
            oi[k, I_ALIVE] = FAILED
            return
    hit, _, prim, q, ng_q, ns_q, _ = intersect(sa, offset_origin(p_o, ng_o, wo_w), wo_w, 0.0, math.inf, stack)
    set_hit(sa, of, oi, k, hit, prim, q, ng_q, ns_q, wo_w)
    if cfg.broken != BROKEN_REVERSIBILITY:
        # the backward shift from y must continue the same way: no reconnection x_b -> y_{b+1}, same action
        cls_x = vertex_class(mat_b, cfg.threshold)
        ok = not inverse_reconnects(sa, lcls, cls_x, p_o, p, ng, hit, prim, q, ng_q, cfg, stack) and \
            mixed_action(cfg.policy, conn(lcls), conn(cls_x)) == action
    record(stats, action, ok)
    if not ok:
        oi[k, I_ALIVE] = FAILED
        return
    _advance(of, oi, k, p_o, pdf_o, delta_o, ecls)


@leaf
def _advance(of, oi, k, p_o, pdf_o, delta_o, lcls):
    """The offset's new previous vertex, direction density and lobe kind (next-event MIS, effects)."""
    set3(of, k, F_PREV_P, p_o)
    of[k, F_PREV_PDF] = pdf_o
    oi[k, I_PREV_DELTA] = 1 if delta_o else 0
    oi[k, I_STATE] = pc_push(oi[k, I_STATE], lcls)
