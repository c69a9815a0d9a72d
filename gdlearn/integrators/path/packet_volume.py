"""The volume packet path tracer: Mitsuba 3's ``volpath`` for ``PK`` paths at once, the same
estimator as :func:`gdlearn.integrators.path.volume.radiance_volpath_inline` bit for bit.

:mod:`gdlearn.integrators.path.packet` explains why packets pay: a path's segments depend on each
other, independent lanes overlap. A lane here runs one *segment* of ``radiance_volpath`` per
wave -- trace the lanes' rays, draw the segment's random numbers, then per lane: the free flight in
its medium (a scattering vertex, or the surface reached), the emission seen, up to the next-event
estimate's shadow ray, and the next direction -- then the shadow rays of all lanes are traced
together, each lane's transmittance taken over its first segment (a shadow ray that meets a null
interface finishes its march alone: :func:`gdlearn.integrators.path.volume.shadow_step`), and the
visible terms added. The order of every operation on a lane's radiance is the scalar kernel's.

:func:`eligible` says when it applies: a scene with media rendered by ``volpath``, no
environment, an effects mask that keeps every effect the scene can show at the depth rendered
(no ``transport`` split): then no contribution is dropped, and the packet tracer tracks no path
classes. Null interfaces, any BSDF and any emitter but an environment are fine.
"""
import math

import numpy as np

from gdlearn.integrators.path.packet import _trace, fill_pixel_items, sum_items, write_row
from gdlearn.integrators.path.packet_rows import IT_FX, IT_FY, IT_KEY, IT_S, get3, set3
from gdlearn.integrators.path.surface import (D_BSDF_U1, D_BSDF_U2, D_EM_SEL, D_EM_U1, D_EM_U2, D_LOBE, D_MED_CH,
                                              D_MED_T, D_RR, dim, flight_dim)
from gdlearn.integrators.path.volume import MAX_SEGMENTS, roulette, shadow_march, shadow_start, shadow_step
from gdlearn.kernels.accel.packet import N_Q_TRACE, N_S_TRACE, PK, Q_PRIM, S_U, S_V
from gdlearn.kernels.bsdf.dispatch import (bsdf_eta, bsdf_eval, bsdf_is_delta_only, bsdf_is_null, bsdf_pdf,
                                           bsdf_sample)
from gdlearn.kernels.camera import camera_ray
from gdlearn.kernels.geometry import INFO_EMITTER, INFO_MAT, offset_origin, surface
from gdlearn.kernels.jit import block, ir_inline, leaf, noalloc
from gdlearn.kernels.lights import emitter_pdf, eval_emitter, sample_emitter
from gdlearn.kernels.media.boundary import next_medium
from gdlearn.kernels.media.medium import medium_params, sample_distance
from gdlearn.kernels.media.phase import hg_eval, hg_sample
from gdlearn.kernels.pathclass import (CAUSTICS, DIFFUSE_INTERREFLECTION, DIRECT_LIGHTING, EMISSION, GLOSSY,
                                       MEDIA_TRANSPORT, MULTIPLE_SCATTERING, SINGLE_SCATTERING, SPECULAR,
                                       SURFACE_TRANSPORT, VOLUME_CAUSTICS)
from gdlearn.kernels.rng import path_state, rand_at
from gdlearn.kernels.sampling import power_heuristic
from gdlearn.kernels.vec import coordinate_system, dot, to_local, to_world

# float rows after the traversal's: the ray set, the shadow ray set, throughput, radiance, eta,
# previous vertex and its pdf, the pending next-event term (A = beta or beta f, the emitter
# weight, the MIS factor k, the light point q, the shadow ray's length), the segment's numbers
R_O = N_S_TRACE
R_SO = R_O + 7
R_BETA = R_SO + 7
R_L = R_BETA + 3
R_ETA = R_L + 3
R_PP = R_ETA + 1
R_PPDF = R_PP + 3
R_A = R_PPDF + 1
R_WEM = R_A + 3
R_K = R_WEM + 3
R_Q = R_K + 1
R_REM = R_Q + 3
R_U = R_REM + 1          # 9: D_EM_SEL .. D_MED_CH of this segment, in dim order
N_S = R_U + 9
# int rows: path state, depth, segment, item (-1: idle), previous vertex delta, medium, path goes
# on, next-event term pending (1: its shadow ray is traced, 2: the light point is the vertex),
# the shadow ray's medium, the bounce (random-number block) and the media its flight passed through
Q_H = N_Q_TRACE
Q_DEPTH, Q_SEG, Q_ITEM, Q_DELTA, Q_MED, Q_ALIVE, Q_NEE, Q_SMED, Q_B, Q_J = (Q_H + 1 + k for k in range(10))
N_Q = Q_J + 1


def eligible(sa, mask, max_depth, possible) -> bool:
    """Can the volume packet tracer render this compiled scene (media, ``volpath``) with this
    effects mask and max_depth? As :func:`gdlearn.integrators.path.packet.eligible`, with the
    medium classes: every class the scene can show at this depth must be kept."""
    need = 1 << EMISSION
    need |= ((1 << DIRECT_LIGHTING) | (1 << SINGLE_SCATTERING)) if max_depth >= 2 else 0
    if max_depth >= 3:
        for c in (DIFFUSE_INTERREFLECTION, GLOSSY, SPECULAR, CAUSTICS, MULTIPLE_SCATTERING, VOLUME_CAUSTICS):
            need |= 1 << c
    need &= possible
    return bool(mask & need == need and mask & (MEDIA_TRANSPORT | SURFACE_TRANSPORT) == 0 and sa.env < 0
                and len(sa.emitters) > 0)


@block
def new_buffers():
    """A row's packet state (S, Q)."""
    return np.zeros(N_S * PK), np.zeros(N_Q * PK, dtype=np.int64)


@leaf
def _start(sa, S, Q, j, item, items, seed):
    """Lane j starts ``radiance_volpath``'s path of ``item`` (film position, key, sample)."""
    key, s = np.int64(items[item, IT_KEY]), np.int64(items[item, IT_S])
    o, d, tmax = camera_ray(sa.camera, items[item, IT_FX], items[item, IT_FY])
    set3(S, R_O, j, o)
    set3(S, R_O + 3, j, d)
    S[(R_O + 6) * PK + j] = tmax
    set3(S, R_BETA, j, (1.0, 1.0, 1.0))
    set3(S, R_L, j, (0.0, 0.0, 0.0))
    S[R_ETA * PK + j] = 1.0
    set3(S, R_PP, j, o)
    S[R_PPDF * PK + j] = 1.0
    Q[Q_H * PK + j] = np.int64(path_state(seed, key, s))
    Q[Q_DEPTH * PK + j] = 0
    Q[Q_SEG * PK + j] = 0
    Q[Q_B * PK + j] = 0
    Q[Q_J * PK + j] = 0
    Q[Q_DELTA * PK + j] = 1
    Q[Q_MED * PK + j] = sa.camera_medium
    Q[Q_ITEM * PK + j] = item


@leaf
def _draw(S, Q):
    """Every lane's random numbers of its segment (dims D_EM_SEL .. D_MED_CH), ahead of the shading:
    the bounce's, the flight's after a null interface (``surface.flight_dim``)."""
    for j in range(PK):
        h = np.uint64(Q[Q_H * PK + j])
        b, nc = Q[Q_B * PK + j], Q[Q_J * PK + j]
        for k in range(D_MED_T):
            S[(R_U + k) * PK + j] = rand_at(h, dim(b, k))
        for k in (D_MED_T, D_MED_CH):
            S[(R_U + k) * PK + j] = rand_at(h, flight_dim(b, nc, k))


@leaf
def _u(S, j, k):
    return S[(R_U + k) * PK + j]


# not inlined: two call sites (medium and surface vertices) would each inline the emitter sample, a
# cold compile's seconds for no measurable speed
@noalloc
def _nee_setup(sa, S, Q, j, p, ng, prim, medium, a):
    """``volume.nee_volume`` up to its shadow ray, at p (surface normal ng on ``prim``, or zeros and
    -1 in a medium): the emitter sample, the shadow ray's first segment and medium, and ``a``, the
    throughput the term is weighted by. Returns (em, dl, pdf_em, delta); em < 0: no term (the caller
    then stores nothing more), else the caller stores the term's other factor with
    :func:`_nee_factor`."""
    em, q, nq, dl, dist, w_em, pdf_em, pdf_a, delta = sample_emitter(
        sa.emitters, sa.em_prims, sa.em_cdf, sa.prims, sa.prim_info, p, _u(S, j, D_EM_SEL), _u(S, j, D_EM_U1),
        _u(S, j, D_EM_U2))
    if em < 0:
        return em, dl, pdf_em, delta
    if prim >= 0:
        medium = next_medium(sa.prim_info, prim, medium, dl, ng)
    set3(S, R_A, j, a)
    set3(S, R_WEM, j, w_em)
    set3(S, R_Q, j, q)
    Q[Q_SMED * PK + j] = medium
    o, d, remaining = shadow_start(p, ng, q)
    if remaining < 0.0:                      # the light point is the vertex: transmittance 1
        Q[Q_NEE * PK + j] = 2
        return em, dl, pdf_em, delta
    set3(S, R_SO, j, o)
    set3(S, R_SO + 3, j, d)
    S[(R_SO + 6) * PK + j] = remaining
    S[R_REM * PK + j] = remaining
    Q[Q_NEE * PK + j] = 1
    return em, dl, pdf_em, delta


@leaf
def _nee_factor(S, j, f, k):
    """The pending term's A becomes A f (the BSDF value; ``volume``'s beta f), and its MIS factor k."""
    a = get3(S, R_A, j)
    set3(S, R_A, j, (a[0] * f[0], a[1] * f[1], a[2] * f[2]))
    S[R_K * PK + j] = k


@ir_inline
def _medium_vertex(sa, S, Q, j, o, d, ts, g, medium, max_depth, rr_depth):
    """A scattering event at distance ts: next-event estimate, phase sampling, roulette."""
    depth = Q[Q_DEPTH * PK + j] + 1
    Q[Q_DEPTH * PK + j] = depth
    if depth >= max_depth:
        return
    p = (o[0] + ts * d[0], o[1] + ts * d[1], o[2] + ts * d[2])
    wi = (-d[0], -d[1], -d[2])
    beta = get3(S, R_BETA, j)
    em, dl, pdf_em, delta = _nee_setup(sa, S, Q, j, p, (0.0, 0.0, 0.0), -1, medium, beta)
    if em >= 0:                             # the phase function's term, MIS-weighted
        ph = hg_eval(g, dot(wi, dl))
        S[R_K * PK + j] = ph * (1.0 if delta else power_heuristic(pdf_em, ph))
    d2, pdf = hg_sample(g, wi, _u(S, j, D_BSDF_U1), _u(S, j, D_BSDF_U2))
    if not pdf > 0.0:
        return
    set3(S, R_PP, j, p)
    S[R_PPDF * PK + j] = pdf
    Q[Q_DELTA * PK + j] = 0
    alive, beta = roulette(beta, S[R_ETA * PK + j], depth, rr_depth, _u(S, j, D_RR))
    if alive:
        _next_ray(S, Q, j, p, d2, beta, True)


@leaf
def _next_ray(S, Q, j, o, d, beta, bounce):
    """Lane j's next segment: after a vertex (``bounce``: the next random-number block) or a null
    interface (the same flight goes on)."""
    set3(S, R_O, j, o)
    set3(S, R_O + 3, j, d)
    S[(R_O + 6) * PK + j] = math.inf
    set3(S, R_BETA, j, beta)
    Q[Q_SEG * PK + j] += 1
    if bounce:
        Q[Q_B * PK + j] += 1
        Q[Q_J * PK + j] = 0
    Q[Q_ALIVE * PK + j] = 1


@ir_inline
def _surface_vertex(sa, S, Q, j, o, d, t, prim, medium, max_depth, rr_depth):
    """The surface reached: emission, a null interface passed, or next-event estimate and BSDF sample."""
    p, ng, ns = surface(sa.prims, sa.prim_info, prim, o, d, t, S[S_U * PK + j], S[S_V * PK + j])
    beta = get3(S, R_BETA, j)
    em = sa.prim_info[prim, INFO_EMITTER]
    if em >= 0:
        le = eval_emitter(sa.emitters, em, ns, d)
        if le[0] + le[1] + le[2] > 0.0:
            w = 1.0
            if Q[Q_DELTA * PK + j] == 0:
                w = power_heuristic(S[R_PPDF * PK + j], emitter_pdf(sa.emitters, em, get3(S, R_PP, j), p, ns))
            L = get3(S, R_L, j)
            set3(S, R_L, j, (L[0] + beta[0] * le[0] * w, L[1] + beta[1] * le[1] * w, L[2] + beta[2] * le[2] * w))
    mat = sa.materials[sa.prim_info[prim, INFO_MAT]]
    if bsdf_is_null(mat):                   # index-matched interface: not a bounce, not a vertex
        Q[Q_MED * PK + j] = next_medium(sa.prim_info, prim, medium, d, ng)
        _next_ray(S, Q, j, offset_origin(p, ng, d), d, beta, False)
        return
    depth = Q[Q_DEPTH * PK + j]
    if depth + 1 >= max_depth:
        return
    s, tt = coordinate_system(ns)
    wi = to_local((-d[0], -d[1], -d[2]), s, tt, ns)
    if not bsdf_is_delta_only(mat):
        em, dl, pdf_em, delta = _nee_setup(sa, S, Q, j, p, ng, prim, medium, beta)
        if em >= 0:                         # the BSDF's term, MIS-weighted (every class kept: share 1)
            wo = to_local(dl, s, tt, ns)
            k = 1.0 if delta else power_heuristic(pdf_em, bsdf_pdf(mat, wi, wo))
            _nee_factor(S, j, bsdf_eval(mat, wi, wo), k)
    wo, weight, pdf, is_delta = bsdf_sample(mat, wi, _u(S, j, D_LOBE), _u(S, j, D_BSDF_U1), _u(S, j, D_BSDF_U2))
    if not pdf > 0.0:
        return
    beta = (beta[0] * weight[0], beta[1] * weight[1], beta[2] * weight[2])
    eta = S[R_ETA * PK + j] * bsdf_eta(mat, wi, wo)
    S[R_ETA * PK + j] = eta
    d2 = to_world(wo, s, tt, ns)
    Q[Q_MED * PK + j] = next_medium(sa.prim_info, prim, medium, d2, ng)
    set3(S, R_PP, j, p)
    S[R_PPDF * PK + j] = pdf
    Q[Q_DELTA * PK + j] = np.int64(is_delta)
    Q[Q_DEPTH * PK + j] = depth + 1
    alive, beta = roulette(beta, eta, depth + 1, rr_depth, _u(S, j, D_RR))
    if alive:
        _next_ray(S, Q, j, offset_origin(p, ng, d2), d2, beta, True)


@leaf
def _shade(sa, S, Q, j, max_depth, rr_depth):
    """Lane j's segment up to its shadow ray; Q_ALIVE says whether the path goes on."""
    Q[Q_ALIVE * PK + j] = 0
    Q[Q_NEE * PK + j] = 0
    S[(R_SO + 6) * PK + j] = -1.0
    if Q[Q_ITEM * PK + j] < 0 or Q[Q_SEG * PK + j] >= MAX_SEGMENTS:
        return
    prim = Q[Q_PRIM * PK + j]
    t = S[(R_O + 6) * PK + j] if prim >= 0 else math.inf      # a miss: the scalar traversal's t
    o, d = get3(S, R_O, j), get3(S, R_O + 3, j)
    medium = Q[Q_MED * PK + j]
    if medium >= 0:
        sig, alb, g = medium_params(sa.media[medium])
        ts, scattered, w = sample_distance(sig, alb, t, _u(S, j, D_MED_CH), _u(S, j, D_MED_T))
        Q[Q_J * PK + j] += 1                # the flight's next medium, if any, draws other numbers
        beta = get3(S, R_BETA, j)
        set3(S, R_BETA, j, (beta[0] * w[0], beta[1] * w[1], beta[2] * w[2]))
        if scattered:
            _medium_vertex(sa, S, Q, j, o, d, ts, g, medium, max_depth, rr_depth)
            return
    if prim < 0:                            # escaped (no environment)
        return
    _surface_vertex(sa, S, Q, j, o, d, t, prim, medium, max_depth, rr_depth)


@noalloc
def _march_on(sa, o, d, remaining, q, medium, tr, stack):
    """The rest of a shadow ray's march after a null interface (``volume.shadow_transmittance``'s
    from its second segment): rare, so not inlined."""
    return shadow_march(sa, o, d, remaining, q, medium, tr, MAX_SEGMENTS - 1, stack)


@leaf
def _shadow(sa, S, Q, j, stack):
    """Lane j's next-event term: its shadow ray's transmittance (the first segment traced with
    the others, the rest of a march through null interfaces here), then the term if visible."""
    nee = Q[Q_NEE * PK + j]
    if nee == 0:
        return
    tr = (1.0, 1.0, 1.0)
    if nee == 1:
        q = get3(S, R_Q, j)
        o, d, remaining = get3(S, R_SO, j), get3(S, R_SO + 3, j), S[R_REM * PK + j]
        medium = Q[Q_SMED * PK + j]
        prim = Q[Q_PRIM * PK + j]
        t = S[(R_SO + 6) * PK + j] if prim >= 0 else math.inf
        done, tr, o, d, remaining, medium = shadow_step(sa, o, d, remaining, q, medium, tr, t, prim,
                                                        S[S_U * PK + j], S[S_V * PK + j])
        if not done:
            tr = _march_on(sa, o, d, remaining, q, medium, tr, stack)
    if tr[0] == 0.0 and tr[1] == 0.0 and tr[2] == 0.0:
        return
    w_em = get3(S, R_WEM, j)
    wl = (w_em[0] * tr[0], w_em[1] * tr[1], w_em[2] * tr[2])
    a, k, L = get3(S, R_A, j), S[R_K * PK + j], get3(S, R_L, j)
    set3(S, R_L, j, (L[0] + a[0] * wl[0] * k, L[1] + a[1] * wl[1] * k, L[2] + a[2] * wl[2] * k))


@leaf
def _finish(sa, S, Q, buf, nxt, nitems, items, seed):
    """A lane whose path ended stores its radiance and takes the next item. Returns the next item
    and the number of busy lanes."""
    busy = 0
    for j in range(PK):
        item = Q[Q_ITEM * PK + j]
        if item >= 0 and Q[Q_ALIVE * PK + j] == 0:
            for k in range(3):
                buf[3 * item + k] = S[(R_L + k) * PK + j]
            Q[Q_ITEM * PK + j] = -1
            S[(R_O + 6) * PK + j] = -1.0
            if nxt < nitems:
                _start(sa, S, Q, j, nxt, items, seed)
                nxt += 1
        busy += Q[Q_ITEM * PK + j] >= 0
    return nxt, busy


@ir_inline
def trace_items_volume(sa, items, nitems, seed, max_depth, rr_depth, S, Q, buf, stack):
    """:func:`gdlearn.integrators.path.packet.trace_items` with ``radiance_volpath``'s paths."""
    nxt = 0
    for j in range(PK):
        Q[Q_ITEM * PK + j] = -1
        S[(R_O + 6) * PK + j] = -1.0
        if nxt < nitems:
            _start(sa, S, Q, j, nxt, items, seed)
            nxt += 1
    busy = 1
    while busy > 0:
        _trace(sa, S, Q, R_O, stack, False)
        _draw(S, Q)
        for j in range(PK):
            _shade(sa, S, Q, j, max_depth, rr_depth)
        _trace(sa, S, Q, R_SO, stack, False)
        for j in range(PK):
            _shadow(sa, S, Q, j, stack)
        nxt, busy = _finish(sa, S, Q, buf, nxt, nitems, items, seed)


@ir_inline
def render_row_packet_volume(sa, y, seed, sample0, spp, max_depth, rr_depth, out, S, Q, buf, items, acc, stack):
    """Row y of ``pt._rows_volpath``'s image, traced in packets
    (:func:`gdlearn.integrators.path.packet.render_row_packet` with ``radiance_volpath``'s paths)."""
    n = out.shape[1] * spp
    acc[:, :] = 0.0
    nbad = 0
    for i0 in range(0, n, items.shape[0]):
        m = min(items.shape[0], n - i0)
        fill_pixel_items(items, i0, m, y, out.shape[1], spp, seed, sample0)
        trace_items_volume(sa, items, m, seed, max_depth, rr_depth, S, Q, buf, stack)
        nbad += sum_items(buf, m, i0, spp, acc)
    write_row(out, y, acc, spp)
    return nbad
