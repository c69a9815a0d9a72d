"""Completing the light subpath of a shifted volume photon in G-VPM (Gruson et al. 2018, Sec. 4.3;
PHOTONS.md Sec. 5.4): the reconnection from the photon's parent a = y_{s-1} to the offset photon b'.

The photon shift moved b (a medium vertex) to b' in the same medium with ``|db'/db|`` = 1 (Eq. 16: no
projection step, unlike surfaces). The light subpath y_0 .. a is kept and the edge a -> b' replaces
a -> b. In ratio form, with the photon's power beta_b (its light subpath's f / p, the medium's
sigma_s T / pdf of the edge included; :mod:`gdlearn.photons.records`), the offset photon's power is
(Gruson et al. 2018, Eq. 11-12, the light-subpath factor and tau(a, b') G(a, b'))

    beta_b' = beta_b * [f_a(w') / f_a(w)] * [T(l') / T(l)] * (l^2 / l'^2)

with w, w' the directions a -> b, a -> b', l, l' their lengths, f_a the parent's scattering in its
sampling measure (sigma_s-free phase function at a medium vertex, cosine-weighted adjoint BSDF at a
surface, the emission profile at an emitter) and T the edge's transmittance per channel: the offset
contribution f(T x) ``|dT/dx|`` / p(x) keeps the base's density p(b | a) = p_w(w) p_l(l) / l^2 (volume
measure, dV = l^2 dw dl). The light side of the MIS ratio (Eq. 19) is the density of b' over b's,

    p(b' | a) / p(b | a) = [p_w(w') / p_w(w)] * [p_l(l') / p_l(l)] * (l^2 / l'^2),

p_l the tracer's collision density (:func:`gdlearn.kernels.media.medium.distance_pdf`, spectral MIS).
Base and offset densities are computed by the same function from positions, so the reverse shift's
ratio is the exact reciprocal and the two MIS weights of a pair sum to one.

Null interfaces (a medium's index-matched boundary) are not scattering vertices: the records keep
them as vertices of their own, but the parent a is the nearest ancestor that is not one, and the
edge a -> b is a straight line through them (a spot light above a block of smoke: every
single-scattered photon's edge crosses the block's top). The offset edge a -> b' is walked through
the same number of them (:func:`edge_walk`), T is the product over its media segments and p_l the
pass probabilities of the earlier segments times the collision density of the last (what the
tracer samples).

Refused (the shift fails: weight 1, no offset): a parent on a specular lobe (the manifold walk is
not implemented for volumes yet), a surface parent whose new direction leaves on the other side of
its geometric normal (Sec. 5.11), an offset edge that crosses another number of null interfaces or
ends in another medium, and one that meets any other surface before b' -- visibility is tested over
the *whole* segment a -> b' (the reference code's test covers only its first 0.1 %, PHOTONS.md E8).
The rules are symmetric between a shift and its reverse.
"""
from __future__ import annotations

import math

from gdlearn.kernels.accel.bvh import closest_hit_inline
from gdlearn.kernels.bsdf.dispatch import bsdf_is_null
from gdlearn.kernels.geometry import INFO_MAT, offset_origin, surface
from gdlearn.kernels.jit import block, inlined
from gdlearn.kernels.media.boundary import next_medium
from gdlearn.kernels.media.medium import distance_pdf, medium_params, pass_probability
from gdlearn.kernels.media.phase import hg_eval
from gdlearn.photons.records import K_MEDIUM, K_SURFACE
from gdlearn.integrators.photon.gpm_light import _dir, parent_base, parent_offset

#: reconnect() outcomes
OK, FAIL, FAIL_SPECULAR = 0, 1, 2


#: parent_base_vol's kind of a medium parent (beside gpm_light's P_FAIL .. P_SPECULAR)
P_MEDIUM = 4


@inlined
def _parent_ratio(sa, lp, q, v, w_new):
    """(status, f_a(w') / f_a(w) per channel, p_w(w') / p_w(w)) of parent row q towards w_new."""
    return parent_offset_vol(sa, lp, q, parent_base_vol(sa, lp, q, v), w_new)


@inlined
def parent_base_vol(sa, lp, q, v):
    """The half of ``_parent_ratio`` that does not depend on the new direction, for photon row v
    and its parent row q (Gruson et al. 2018, Sec. 4.3: the light subpath up to a is kept): at a
    medium vertex (P_MEDIUM, Mitsuba's wi, the phase function towards the base direction in every
    channel, the HG asymmetry g), else ``gpm_light.parent_base`` (Hua et al. 2017, Sec. 4.2). Once
    per photon where one photon is shifted to several neighbours (the surface pass)."""
    if lp.kind[q] == K_MEDIUM:
        g = medium_params(sa.media[lp.obj[q]])[2]
        w_old, _ = _dir((lp.pos[q, 0], lp.pos[q, 1], lp.pos[q, 2]), (lp.pos[v, 0], lp.pos[v, 1], lp.pos[v, 2]))
        wi = (-lp.d_in[q, 0], -lp.d_in[q, 1], -lp.d_in[q, 2])       # Mitsuba's wi: back along the arrival
        fb = hg_eval(g, wi[0] * w_old[0] + wi[1] * w_old[1] + wi[2] * w_old[2])
        return P_MEDIUM, wi, (fb, fb, fb), g
    return parent_base(sa, lp, q, v)


@inlined
def parent_offset_vol(sa, lp, q, base, w_new):
    """``_parent_ratio`` towards ``w_new`` from its base half ``base`` (:func:`parent_base_vol`):
    (status OK | FAIL | FAIL_SPECULAR, value ratio per channel, density ratio)."""
    one = (1.0, 1.0, 1.0)
    kind, wi, fb3, g = base
    if kind == P_MEDIUM:
        fb = fb3[0]
        fo = hg_eval(g, wi[0] * w_new[0] + wi[1] * w_new[1] + wi[2] * w_new[2])
        if not (fb > 0.0 and fo > 0.0):
            return FAIL, one, 0.0
        r = fo / fb                   # HG is sampled exactly: the pdf ratio is the value ratio
        return OK, (r, r, r), r
    status, fr, pr = parent_offset(sa, lp, q, base, w_new)
    if status == 2:
        return FAIL_SPECULAR, one, 0.0
    if status != 0:
        return FAIL, one, 0.0
    return OK, fr, pr


#: null interfaces the edge a -> b may cross (a light path records at most a few: a medium's boundary)
MAX_CROSSINGS = 16


@inlined
def _ancestor(sa, lp, v):
    """(a, child, crossings): the photon's parent a = y_{s-1} -- its nearest ancestor that is not a null
    interface (those only change the medium: the edge a -> b is one straight line through them) --,
    the row after a on that edge (whose ``medium`` the edge starts in), and how many it crosses."""
    child = v
    q = lp.parent[v]
    n = 0
    while q >= 0 and lp.kind[q] == K_SURFACE and bsdf_is_null(sa.materials[lp.obj[q]]):
        child = q
        q = lp.parent[q]
        n += 1
    return int(q), child, n         # int64 (lp.parent is int32): one _spawn specialisation for every caller


@inlined
def edge_walk(sa, a, o, w, target, medium, stack):
    """Walk the straight edge from the vertex ``a`` (rays spawned at ``o``, a pushed off a surface) towards ``target``: through null interfaces
    (the medium changes at each, Mitsuba's rule), failing at any other surface -- visibility over
    the whole segment, PHOTONS.md E8. Returns (ok, null crossings, optical depth per channel, log of
    the tracer's density of a collision at ``target`` -- the pass probabilities of the earlier media
    segments times the collision density of the last, spectral MIS --, the medium at ``target``)."""
    tau = (0.0, 0.0, 0.0)
    logp = 0.0
    prev = a            # lengths from the vertex itself, as the analytic base of reconnect(): exact reciprocals
    n = 0
    for _ in range(MAX_CROSSINGS + 1):
        t, prim, uu, vv = closest_hit_inline(sa.nodes, sa.node_info, sa.prims, sa.prim_info, o, w, 0.0, math.inf,
                                             stack)
        reach = math.sqrt((target[0] - o[0]) ** 2 + (target[1] - o[1]) ** 2 + (target[2] - o[2]) ** 2)
        if prim < 0 or t > reach:
            ln = math.sqrt((target[0] - prev[0]) ** 2 + (target[1] - prev[1]) ** 2 + (target[2] - prev[2]) ** 2)
            if medium < 0:
                return False, n, tau, 0.0, medium          # a photon lies in a medium
            sig = medium_params(sa.media[medium])[0]
            pc = distance_pdf(sig, ln)
            if not pc > 0.0:
                return False, n, tau, 0.0, medium
            return True, n, (tau[0] + sig[0] * ln, tau[1] + sig[1] * ln, tau[2] + sig[2] * ln), logp + math.log(pc), \
                medium
        if not bsdf_is_null(sa.materials[sa.prim_info[prim, INFO_MAT]]):
            return False, n, tau, 0.0, medium              # occluded before b'
        p, ng, _ = surface(sa.prims, sa.prim_info, prim, o, w, t, uu, vv)
        if medium >= 0:
            ln = math.sqrt((p[0] - prev[0]) ** 2 + (p[1] - prev[1]) ** 2 + (p[2] - prev[2]) ** 2)
            sig = medium_params(sa.media[medium])[0]
            pp = pass_probability(sig, ln)
            if not pp > 0.0:
                return False, n, tau, 0.0, medium
            tau = (tau[0] + sig[0] * ln, tau[1] + sig[1] * ln, tau[2] + sig[2] * ln)
            logp += math.log(pp)
        medium = next_medium(sa.prim_info, prim, medium, w, ng)
        o = offset_origin(p, ng, w)
        prev = p
        n += 1
    return False, n, tau, 0.0, medium


#: a photon's recorded edge a -> b (:func:`base_edge`) as a scratch row: status, parent row, child row,
#: null crossings, optical depth (3), log density; status EDGE_UNKNOWN: not computed yet
EDGE_COLS = 8
EDGE_UNKNOWN = -1.0
#: base_edge() statuses besides OK: the edge has no parent or no length (the shift fails at once), or
#: its walk or density failed (the shift fails after the parent and the offset edge were checked,
#: the order in which reconnect() has always reported its outcomes)
EDGE_NONE, EDGE_LATE = 1, 3


@inlined
def base_edge(sa, lp, v, stack):
    """What every neighbour's reconnection of photon row v shares: the recorded edge a -> b. Returns
    (status, parent row a, the row after a on the edge, null crossings, optical depth per channel, log
    of the tracer's density of b) -- the edge walked through its null interfaces, or analytic when it
    crosses none (a recorded edge in one medium needs no ray)."""
    zero = (0.0, 0.0, 0.0)
    q, child, n_null = _ancestor(sa, lp, v)
    if q < 0:
        return EDGE_NONE, q, child, n_null, zero, 0.0
    a = (lp.pos[q, 0], lp.pos[q, 1], lp.pos[q, 2])
    w_old, l_old = _dir(a, (lp.pos[v, 0], lp.pos[v, 1], lp.pos[v, 2]))
    if not l_old > 0.0:
        return EDGE_NONE, q, child, n_null, zero, 0.0
    if n_null == 0:
        sig = medium_params(sa.media[lp.medium[v]])[0]
        pc = distance_pdf(sig, l_old)
        if not pc > 0.0:
            return EDGE_LATE, q, child, n_null, zero, 0.0
        return OK, q, child, n_null, (sig[0] * l_old, sig[1] * l_old, sig[2] * l_old), math.log(pc)
    ok, n_b, tau_b, logp_b, med_b = edge_walk(sa, a, _spawn(lp, q, a, w_old), w_old, (lp.pos[v, 0], lp.pos[v, 1],
                                              lp.pos[v, 2]), lp.medium[child], stack)
    if not (ok and n_b == n_null and med_b == lp.medium[v]):
        return EDGE_LATE, q, child, n_null, zero, 0.0
    return OK, q, child, n_null, tau_b, logp_b


@inlined
def store_edge(edge, i, e):
    edge[i, 0] = e[0]
    edge[i, 1] = e[1]
    edge[i, 2] = e[2]
    edge[i, 3] = e[3]
    for c in range(3):
        edge[i, 4 + c] = e[4][c]
    edge[i, 7] = e[5]


@inlined
def load_edge(edge, i):
    return (int(edge[i, 0]), int(edge[i, 1]), int(edge[i, 2]), int(edge[i, 3]), (edge[i, 4], edge[i, 5], edge[i, 6]),
            edge[i, 7])


@block
def reconnect(sa, lp, v, b_off, stack):
    """Reconnect photon row v's parent to the offset photon ``b_off`` (module docstring). Returns
    (status, beta_b' / beta_b per channel, light-side density ratio p(b' | a) / p(b | a), the
    direction a -> b' the offset photon arrives along)."""
    return reconnect_edge(sa, lp, v, b_off, stack, base_edge(sa, lp, v, stack))


@inlined
def reconnect_edge(sa, lp, v, b_off, stack, edge):
    """:func:`reconnect` with the recorded edge a -> b given (:func:`base_edge`): a camera sample's
    neighbours shift the same photon and walk that edge once."""
    zero = (0.0, 0.0, 0.0)
    st, q, child, n_null, tau_b, logp_b = edge
    if st == EDGE_NONE:
        return FAIL, zero, 0.0, zero
    a = (lp.pos[q, 0], lp.pos[q, 1], lp.pos[q, 2])
    w_new, l_new = _dir(a, b_off)
    w_old, l_old = _dir(a, (lp.pos[v, 0], lp.pos[v, 1], lp.pos[v, 2]))
    if not l_new > 0.0:
        return FAIL, zero, 0.0, zero
    status, fr, pr = _parent_ratio(sa, lp, q, v, w_new)
    if status != OK:
        return status, zero, 0.0, zero
    ok, n_o, tau_o, logp_o, med_o = edge_walk(sa, a, _spawn(lp, q, a, w_new), w_new, b_off, lp.medium[child], stack)
    if not (ok and n_o == n_null and med_o == lp.medium[v]) or st != OK:
        return FAIL, zero, 0.0, zero
    geo = (l_old * l_old) / (l_new * l_new)
    # T(a, b') / T(a, b) = exp(-(tau' - tau)) per channel: one exponential, no 0 / 0 in a dense medium
    f3 = (fr[0] * math.exp(tau_b[0] - tau_o[0]) * geo, fr[1] * math.exp(tau_b[1] - tau_o[1]) * geo,
          fr[2] * math.exp(tau_b[2] - tau_o[2]) * geo)
    return OK, f3, pr * math.exp(logp_o - logp_b) * geo, w_new


@inlined
def _spawn(lp, q, a, w):
    """Where a ray from vertex row q leaves along w: a medium vertex in place, a surface or an emitter
    pushed off its geometric normal (a point light's zero normal leaves it in place)."""
    if lp.kind[q] == K_MEDIUM:
        return a
    return offset_origin(a, (lp.nrm[q, 0], lp.nrm[q, 1], lp.nrm[q, 2]), w)
