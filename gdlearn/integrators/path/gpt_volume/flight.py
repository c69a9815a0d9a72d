"""Free flights of the offset paths of volumetric G-PT: the distance copy and the passing segment
(Gruson et al. 2018, Sec. 4.1 "copy the distance ... the shift Jacobian is simply 1" and Sec. 6
"Gradient-domain volumetric path tracing"; STAR, Hua et al. 2019, Sec. 7.1).

Measure. After the direction leaving a vertex is sampled, ``volpath`` (:mod:`gdlearn.integrators.path.volume`)
samples a free-flight distance in every medium the ray crosses (null interfaces are crossed, they are
not vertices). A *flight* ends in one of three events: a scattering vertex at total distance tau
from the vertex (sum of the sub-segment lengths between null interfaces), a surface vertex, or the
escape. In the (direction, distance) parametrisation (dV = t^2 dw dt, medium "cosine" 1) the
integrand of a flight is

    scatter:  prod_j T_j  *  sigma_s T(t_last)          density: prod_j P_j(pass) * pdf(t_last)
    surface:  prod_j T_j                                density: prod_j P_j(pass)

with the spectral-MIS densities of :mod:`gdlearn.kernels.media.medium` (``distance_pdf``,
``pass_probability``) per sub-segment j. The offset's flight keeps the base's *event*: a scattering
base flight is copied to the same total distance tau along the offset's own ray (Jacobian 1), a
passing one passes. The shift fails when the offset's ray meets a non-null surface before tau, leaves
the scene, or is in vacuum at tau (vertex kinds must match, as at surfaces); the rule is symmetric
in base and offset, so the backward shift fails on the same pairs (STAR Sec. 3.5).

:func:`base_flight` is volpath's own flight with its random numbers: the base path's, and -- run
along an offset's ray with the base's numbers -- the *replayed* flight of the mixed policies
(:mod:`gdlearn.integrators.path.gpt_volume.mixed`, STAR Sec. 3.1), whose event may be of another kind.

Everything is returned in log form -- per-channel log f and the log density -- because dense media
(sigma_t = 1e4) underflow T and P to 0 where their ratio f' / p_base is ordinary; the caller forms
exp(log f'_c - log p_base) and the Eq. 17 log ratio from them.
"""
import math


from gdlearn.kernels.bsdf.dispatch import bsdf_is_null
# the traversal inlined into the flights: as a call it took the scene's arrays as ~30 scalars per
# segment (gpt on the medium cube 12 % faster; benchmarks/README.md, issue 20 session 16)
from gdlearn.kernels.accel.bvh import closest_hit_inline
from gdlearn.kernels.geometry import INFO_MAT, offset_origin, surface
from gdlearn.kernels.media.medium import medium_params, sample_distance
from gdlearn.kernels.rng import rand
from gdlearn.kernels.scene_query import SHADOW_EPS
from gdlearn.integrators.path.surface import D_MED_CH, D_MED_T, flight_dim
from gdlearn.integrators.path.volume import MAX_SEGMENTS, next_medium
from gdlearn.shifts.distance import lands_on_segment
from gdlearn.kernels.jit import leaf, noalloc

#: flight events
EV_SURFACE, EV_SCATTER, EV_ESCAPE, EV_FAIL = 0, 1, 2, 3
ZERO3 = (0.0, 0.0, 0.0)
ONE3 = (1.0, 1.0, 1.0)
_LOG3 = math.log(3.0)


@leaf
def _lsum3(a0, a1, a2):
    """log(exp(a0) + exp(a1) + exp(a2)) - log 3 without underflow (-inf entries allowed)."""
    m = max(a0, max(a1, a2))
    if m == -math.inf:
        return -math.inf
    return m + math.log(math.exp(a0 - m) + math.exp(a1 - m) + math.exp(a2 - m)) - _LOG3


@leaf
def _neg_tau(sigma, t):
    """-sigma t, with sigma = 0 giving 0 for any t (also t = inf)."""
    if sigma == 0.0:
        return 0.0
    return -sigma * t


@noalloc
def log_pass_probability(sigma_t, t):
    """log P(pass) = log((1/3) sum_c exp(-sigma_c t)) (``medium.pass_probability`` in log form)."""
    return _lsum3(_neg_tau(sigma_t[0], t), _neg_tau(sigma_t[1], t), _neg_tau(sigma_t[2], t))


@leaf
def _log_sigma_tr(sigma, t):
    """log(sigma exp(-sigma t)); -inf for sigma = 0 (that channel never collides)."""
    if sigma > 0.0:
        return math.log(sigma) - sigma * t
    return -math.inf


@noalloc
def log_distance_pdf(sigma_t, t):
    """log((1/3) sum_c sigma_c exp(-sigma_c t)) (``medium.distance_pdf`` in log form)."""
    return _lsum3(_log_sigma_tr(sigma_t[0], t), _log_sigma_tr(sigma_t[1], t), _log_sigma_tr(sigma_t[2], t))


@leaf
def _log_tr(lt, sigma_t, t):
    """Add log T(t) per channel to the 3-tuple lt."""
    return (lt[0] + _neg_tau(sigma_t[0], t), lt[1] + _neg_tau(sigma_t[1], t), lt[2] + _neg_tau(sigma_t[2], t))


@leaf
def _log_scatter(lt, sigma_t, albedo, t):
    """Add log(sigma_s T(t)) per channel (sigma_s = albedo sigma_t; -inf where it is 0)."""
    return (lt[0] + _log_sigma_tr(albedo[0] * sigma_t[0], 0.0) - _tau0(sigma_t[0], t),
            lt[1] + _log_sigma_tr(albedo[1] * sigma_t[1], 0.0) - _tau0(sigma_t[1], t),
            lt[2] + _log_sigma_tr(albedo[2] * sigma_t[2], 0.0) - _tau0(sigma_t[2], t))


@leaf
def _tau0(sigma, t):
    return -_neg_tau(sigma, t)


@noalloc
def offset_flight(sa, o, d, tmax, medium, tau, scatter, stack):
    """The offset's flight along its own ray (o, d) from its vertex, in ``medium``: to the scattering
    vertex at total distance ``tau`` (``scatter``: the distance copy) or to the first non-null surface
    / the escape (the base passed). Null interfaces are crossed as in ``volume_path``.

    Returns ``(ev, prim, p, ng, ns, medium_at_event, log_f (3), log_pdf)``; ev = EV_FAIL when the
    event cannot be copied (a surface or the escape before tau, vacuum at tau)."""
    travelled = 0.0
    lt = ZERO3
    lp = 0.0
    for _ in range(MAX_SEGMENTS):
        t, prim, u, v = closest_hit_inline(sa.nodes, sa.node_info, sa.prims, sa.prim_info, o, d, 0.0, tmax, stack)
        tmax = math.inf
        lands, tl = lands_on_segment(tau, travelled, t)
        if scatter and lands:                        # the copied distance lies on this sub-segment
            if medium < 0:
                break
            sig, alb, _ = medium_params(sa.media[medium])
            p = (o[0] + tl * d[0], o[1] + tl * d[1], o[2] + tl * d[2])
            return EV_SCATTER, -1, p, ZERO3, ZERO3, medium, _log_scatter(lt, sig, alb, tl), lp + log_distance_pdf(sig, tl)
        if medium >= 0:
            sig, _, _ = medium_params(sa.media[medium])
            lt = _log_tr(lt, sig, t)
            lp += log_pass_probability(sig, t)
        if prim < 0:
            if scatter:
                break
            return EV_ESCAPE, -1, o, ZERO3, ZERO3, medium, lt, lp
        p, ng, ns = surface(sa.prims, sa.prim_info, prim, o, d, t, u, v)
        if not bsdf_is_null(sa.materials[sa.prim_info[prim, INFO_MAT]]):
            if scatter:
                break
            return EV_SURFACE, prim, p, ng, ns, medium, lt, lp
        medium = next_medium(sa.prim_info, prim, medium, d, ng)
        o = offset_origin(p, ng, d)
        travelled += t
    return EV_FAIL, -1, o, ZERO3, ZERO3, medium, lt, lp


@noalloc
def segment_to(sa, p, ng, q, medium, collide, stack):
    """The reconnected segment p -> q (p on a surface of geometric normal ng, or a medium vertex with
    ng = 0) crossing null interfaces: ``(ok, log_f (3), log_pdf, medium at q)``. ``collide``: q is a
    medium vertex (the flight ends by scattering at q: sigma_s T and the collision density); else q is
    on a surface (T and the pass probability). Any non-null surface in between blocks (ok False)."""
    dv = (q[0] - p[0], q[1] - p[1], q[2] - p[2])
    o = offset_origin(p, ng, dv) if (ng[0] != 0.0 or ng[1] != 0.0 or ng[2] != 0.0) else p
    dv = (q[0] - o[0], q[1] - o[1], q[2] - o[2])
    dist = math.sqrt(dv[0] * dv[0] + dv[1] * dv[1] + dv[2] * dv[2])
    lt = ZERO3
    lp = 0.0
    if not dist > 0.0:
        return False, lt, lp, medium
    d = (dv[0] / dist, dv[1] / dist, dv[2] / dist)
    # a surface endpoint must not hit itself: the ray stops just short of q (shadow-ray epsilon);
    # the densities use the true remaining length
    remaining = dist if collide else dist * (1.0 - SHADOW_EPS)
    rem_true = dist
    for _ in range(MAX_SEGMENTS):
        t, prim, u, v = closest_hit_inline(sa.nodes, sa.node_info, sa.prims, sa.prim_info, o, d, 0.0, remaining, stack)
        if prim < 0:                                 # reached q
            if medium < 0:
                return (not collide), lt, lp, medium
            sig, alb, _ = medium_params(sa.media[medium])
            if collide:
                return True, _log_scatter(lt, sig, alb, rem_true), lp + log_distance_pdf(sig, rem_true), medium
            return True, _log_tr(lt, sig, rem_true), lp + log_pass_probability(sig, rem_true), medium
        if not bsdf_is_null(sa.materials[sa.prim_info[prim, INFO_MAT]]):
            return False, lt, lp, medium
        if medium >= 0:
            sig, _, _ = medium_params(sa.media[medium])
            lt = _log_tr(lt, sig, t)
            lp += log_pass_probability(sig, t)
        hp, hng, _ = surface(sa.prims, sa.prim_info, prim, o, d, t, u, v)
        medium = next_medium(sa.prim_info, prim, medium, d, hng)
        o = offset_origin(hp, hng, d)
        # aimed again at q from the pushed-off origin (volume_path.shadow_transmittance): the push
        # moves o off the line p -> q, and a short or grazing segment would then run past the
        # SHADOW_EPS slack into q's own surface
        dv = (q[0] - o[0], q[1] - o[1], q[2] - o[2])
        rem_true = math.sqrt(dv[0] * dv[0] + dv[1] * dv[1] + dv[2] * dv[2])
        if not rem_true > 0.0:
            break
        d = (dv[0] / rem_true, dv[1] / rem_true, dv[2] / rem_true)
        remaining = rem_true if collide else rem_true * (1.0 - SHADOW_EPS)
        if remaining <= 0.0:
            break
    return False, lt, lp, medium


# inlined (leaf): as a call of its own it took the scene as ~100 scalars once per base segment, and
# gpt's passes in media were 20-30 % slower (benchmarks/README.md, issue 20 session 16)
@leaf
def base_flight(sa, o, d, tmax, medium, beta, rng, bounce, stack, need_lp):
    """volpath's loop from (o, d) up to its next real event, null interfaces crossed, same random
    numbers (``rng``: :class:`~gdlearn.integrators.path.params.PathRng`; the flight leaving bounce
    ``bounce``, ``surface.flight_dim``) and the same beta updates. Returns ``(ev, medium, beta, W,
    log p, tau, prim, p, ng, ns)``: W the product of the flight's weights, log p its density (pass
    probabilities and the collision pdf, spectral MIS), tau the total distance.
    ``need_lp`` False: log p is not computed (returned as 0): only a free offset's shift reads it, and
    its logs and exponentials (up to 7 per flight) cost a grey medium's flight more than volpath's
    whole sampling, which needs none."""
    seed, key, s = rng.seed, rng.key, rng.s
    W = ONE3
    lp = 0.0
    tau = 0.0
    j = 0                                    # media passed through
    n = 0                                    # segments
    while n < MAX_SEGMENTS:
        t, prim, u, v = closest_hit_inline(sa.nodes, sa.node_info, sa.prims, sa.prim_info, o, d, 0.0, tmax, stack)
        tmax = math.inf
        if medium >= 0:
            sig, alb, _ = medium_params(sa.media[medium])
            ts, scattered, w = sample_distance(sig, alb, t, rand(seed, key, s, flight_dim(bounce, j, D_MED_CH)),
                                               rand(seed, key, s, flight_dim(bounce, j, D_MED_T)))
            j += 1
            beta = (beta[0] * w[0], beta[1] * w[1], beta[2] * w[2])
            W = (W[0] * w[0], W[1] * w[1], W[2] * w[2])
            if scattered:
                p = (o[0] + ts * d[0], o[1] + ts * d[1], o[2] + ts * d[2])
                if need_lp:
                    lp += log_distance_pdf(sig, ts)
                return EV_SCATTER, medium, beta, W, lp, tau + ts, -1, p, ZERO3, ZERO3
            if need_lp:
                lp += log_pass_probability(sig, t)
        if prim < 0:
            return EV_ESCAPE, medium, beta, W, lp, tau, -1, o, ZERO3, ZERO3
        p, ng, ns = surface(sa.prims, sa.prim_info, prim, o, d, t, u, v)
        if not bsdf_is_null(sa.materials[sa.prim_info[prim, INFO_MAT]]):
            return EV_SURFACE, medium, beta, W, lp, tau + t, prim, p, ng, ns
        medium = next_medium(sa.prim_info, prim, medium, d, ng)
        o = offset_origin(p, ng, d)
        tau += t
        n += 1
    return EV_FAIL, medium, beta, W, lp, tau, -1, o, ZERO3, ZERO3
