"""The packet path tracer: Mitsuba 3's ``path`` for ``PK`` paths at once, for surface scenes
rendered whole (every effect they can show), the same estimator bit for bit.

:func:`gdlearn.integrators.path.surface.radiance_path` follows one path from the camera to its end; the
bounces of a path depend on each other, so most of a bounce waits for the previous one (a chain of
divisions, square roots and a traversal per bounce) and its data-dependent branches stall the CPU
each time they are mispredicted. Here a row of the image is a queue of (pixel, sample) *items*
worked off by ``PK`` lanes, each lane one path: every step runs for all lanes before the next step
-- trace the lanes' rays (a packet, :mod:`gdlearn.kernels.accel.packet`), shade every lane up to its
shadow ray, trace the shadow rays, add the next-event terms -- and a lane whose path ended takes
the next item. Independent lanes overlap in the CPU, and the traversal runs SIMD over the rays.

The shading of a lane is :func:`radiance_path`'s bounce, calling the same functions in the same
order on the same random numbers (``rand_at(h, dim(bounce, k))``); the per-sample radiances are
kept per item and summed per pixel in sample order afterwards. So the image equals the scalar
kernel's bit for bit (tests/test_pt_packet.py), threads and passes included.

:func:`eligible` says when it applies: no media (``path``), no null BSDF, no environment, an
effects mask that keeps every effect the scene can show at the depth rendered (the packet tracer
tracks no path classes: with nothing to drop, every contribution counts). Everything else renders
with :mod:`gdlearn.integrators.path.surface`. Rays are traced as a packet when the scene is one leaf
(the Cornell box, the glossy box, the glass and mirror spheres of the caustic scenes), else ray by
ray with the scalar traversal (trees: incoherent rays through a tree share too few nodes for a
packet to pay), and still gain from the lanes' overlap. The next-event estimates and BSDF samples
of diffuse vertices run SIMD over the lanes too (:mod:`gdlearn.integrators.path.packet_nee`,
:func:`next_diffuse`); the lanes' state is laid out in :mod:`gdlearn.integrators.path.packet_rows`.
"""
import math

import numpy as np
from numba.extending import overload


from gdlearn.integrators.path.packet_nee import defer_diffuse_area, nee_diffuse_area, nee_lane
from gdlearn.integrators.path.packet_rows import (IT_FX, IT_FY, IT_KEY, IT_S, Q_ALIVE, Q_CONT, Q_DELTA, Q_DEPTH,
                                                  Q_DIFF, Q_EMP, Q_H, Q_ITEM, Q_MAT, Q_NEE, R_BETA, R_C, R_ETA, R_FS,
                                                  R_FT, R_L, R_M2S, R_MREF, R_NG, R_NS, R_O, R_P, R_PP, R_PPDF, R_SO,
                                                  R_UBSDF, R_UEM, R_URR, R_WI, R_WO, get3, set3, set3_if, set_if)
from gdlearn.integrators.path.surface import D_BSDF_U1, D_BSDF_U2, D_EM_SEL, D_EM_U1, D_EM_U2, D_LOBE, D_RR, dim
from gdlearn.kernels.accel.bvh import any_hit_inline, closest_hit_inline
from gdlearn.kernels.accel.forms import one_leaf
from gdlearn.kernels.accel.packet import PK, Q_HIT, Q_PRIM, S_U, S_V, packet_trace_leaf
from gdlearn.kernels.bsdf.dispatch import bsdf_eta, bsdf_is_delta_only, bsdf_sample
from gdlearn.kernels.camera import camera_ray
from gdlearn.kernels.geometry import INFO_EMITTER, INFO_MAT, offset_origin, surface
from gdlearn.kernels.jit import LEAF_OPTIONS, ir_inline, leaf
from gdlearn.kernels.layout import DIFFUSE, MAT_R, MAT_TWOSIDED, MAT_TYPE, NULL
from gdlearn.kernels.lights import emitter_pdf, eval_emitter
from gdlearn.kernels.pathclass import (CAUSTICS, DIFFUSE_INTERREFLECTION, DIRECT_LIGHTING, EMISSION, GLOSSY,
                                       MEDIA_TRANSPORT, SPECULAR, SURFACE_TRANSPORT)
from gdlearn.kernels.rng import path_state, rand, rand_at
from gdlearn.kernels.sampling import INV_PI, power_heuristic, square_to_cosine_hemisphere
from gdlearn.kernels.vec import coordinate_system, fmax, fmin, max3, to_local, to_world


def eligible(sa, mask, max_depth, possible) -> bool:
    """Can the packet tracer render this compiled scene with this effects mask and max_depth?

    ``possible``: the class bits the scene can show (the effects plan's ``possible``). The packet
    tracer tracks no path classes, so the mask must keep every class a path can have at this
    depth: emission (0 interior vertices), direct lighting (1) and, from max_depth 3 on, every
    class of two or more surface vertices the scene can show."""
    need = 1 << EMISSION
    need |= (1 << DIRECT_LIGHTING) if max_depth >= 2 else 0
    if max_depth >= 3:
        need |= (1 << DIFFUSE_INTERREFLECTION) | (1 << GLOSSY) | (1 << SPECULAR) | (1 << CAUSTICS)
    need &= possible
    return bool(mask & need == need and mask & (MEDIA_TRANSPORT | SURFACE_TRANSPORT) == 0 and sa.env < 0
                and len(sa.emitters) > 0 and not np.any(sa.materials[:, MAT_TYPE] == NULL))


def use_packets(requested, eligible_here: bool, rule: str) -> bool:
    """The ``packets`` option of ``pt`` and ``gpt-replay``: None traces packets where the scene is
    eligible, False never, True insists (ValueError naming ``rule``, what eligibility asks)."""
    if requested and not eligible_here:
        raise ValueError(f"this scene cannot be traced in packets ({rule}); fix: packets=None or False")
    return eligible_here if requested is None else bool(requested) and eligible_here


@leaf
def _start(sa, S, Q, j, item, items, seed):
    """Lane j starts the path of ``item`` (a row of the item table ``items``): the camera ray through
    its film position and ``radiance_path``'s initial state, with the random numbers of its key and
    sample."""
    key, s = np.int64(items[item, IT_KEY]), np.int64(items[item, IT_S])
    o, d, tmax = camera_ray(sa.camera, items[item, IT_FX], items[item, IT_FY])
    set3(S, R_O, j, o)
    set3(S, R_O + 3, j, d)
    S[(R_O + 6) * PK + j] = tmax
    set3(S, R_BETA, j, (1.0, 1.0, 1.0))
    set3(S, R_L, j, (0.0, 0.0, 0.0))
    set3(S, R_PP, j, o)
    S[R_PPDF * PK + j] = 1.0
    S[R_ETA * PK + j] = 1.0
    Q[Q_H * PK + j] = np.int64(path_state(seed, key, s))
    Q[Q_DEPTH * PK + j] = 0
    Q[Q_DELTA * PK + j] = 1
    Q[Q_ITEM * PK + j] = item


@leaf
def _draw(S, Q):
    """Every lane's random numbers of this bounce and its cosine-weighted direction, ahead of the
    shading: they depend on the path state alone, and in a loop of their own the lanes' long
    polynomial and square-root chains overlap instead of stalling each lane's shading in turn."""
    for j in range(PK):
        h = np.uint64(Q[Q_H * PK + j])
        b = Q[Q_DEPTH * PK + j]
        S[R_UEM * PK + j] = rand_at(h, dim(b, D_EM_SEL))
        S[(R_UEM + 1) * PK + j] = rand_at(h, dim(b, D_EM_U1))
        S[(R_UEM + 2) * PK + j] = rand_at(h, dim(b, D_EM_U2))
        u1, u2 = rand_at(h, dim(b, D_BSDF_U1)), rand_at(h, dim(b, D_BSDF_U2))
        set3(S, R_WO, j, square_to_cosine_hemisphere(u1, u2))
        set3(S, R_UBSDF, j, (rand_at(h, dim(b, D_LOBE)), u1, u2))
        S[R_URR * PK + j] = rand_at(h, dim(b, D_RR))


@leaf
def next_diffuse(S, Q, rr_depth):
    """:func:`_shade_next` for every diffuse lane (Q_DIFF) in one branch-free loop the compiler
    vectorises: ``bsdf_sample`` of a diffuse material given the cosine-weighted direction its
    (u1, u2) map to (R_WO, from :func:`_draw`), with the twosided mirroring, checks and guard; the
    next ray (``offset_origin``), and the Russian roulette. The scalar code's operations in its order,
    each branch a select, so the same bits; a diffuse BSDF crosses no interface (``bsdf_eta`` 1: eta
    is kept) and is not a delta."""
    for j in range(PK):
        wiz = S[(R_WI + 2) * PK + j]
        flip = (S[R_M2S * PK + j] != 0.0) & (wiz < 0.0)
        wz = -wiz if flip else wiz
        w0, w1, w2 = S[R_WO * PK + j], S[(R_WO + 1) * PK + j], S[(R_WO + 2) * PK + j]
        pdf = w2 * INV_PI
        r0, r1, r2 = S[R_MREF * PK + j], S[(R_MREF + 1) * PK + j], S[(R_MREF + 2) * PK + j]
        valid = (not ((wz <= 0.0) | (pdf <= 0.0))) & (pdf < math.inf) & (abs(r0 + r1 + r2) < math.inf)
        go = (Q[Q_DIFF * PK + j] != 0) & valid
        w2 = -w2 if flip else w2
        b0, b1, b2 = S[R_BETA * PK + j] * r0, S[(R_BETA + 1) * PK + j] * r1, S[(R_BETA + 2) * PK + j] * r2
        d = to_world((w0, w1, w2), get3(S, R_FS, j), get3(S, R_FT, j), get3(S, R_NS, j))
        p = get3(S, R_P, j)
        o = offset_origin(p, get3(S, R_NG, j), d)
        set3_if(S, R_O, j, go, o)
        set3_if(S, R_O + 3, j, go, d)
        set_if(S, R_O + 6, j, go, math.inf)
        set3_if(S, R_PP, j, go, p)
        set_if(S, R_PPDF, j, go, pdf)
        Q[Q_DELTA * PK + j] = 0 if go else Q[Q_DELTA * PK + j]
        depth = Q[Q_DEPTH * PK + j] + 1
        Q[Q_DEPTH * PK + j] = depth if go else Q[Q_DEPTH * PK + j]
        bmax = fmax(b0, fmax(b1, b2))
        eta = S[R_ETA * PK + j]
        q = fmin(bmax * eta * eta, 0.95)
        roulette = depth >= rr_depth
        survive = (not roulette) | (S[R_URR * PK + j] < q)
        b0 = b0 / q if roulette else b0
        b1 = b1 / q if roulette else b1
        b2 = b2 / q if roulette else b2
        alive = go & survive & (bmax > 0.0)
        set_if(S, R_BETA, j, alive, b0)
        set_if(S, R_BETA + 1, j, alive, b1)
        set_if(S, R_BETA + 2, j, alive, b2)
        Q[Q_ALIVE * PK + j] = 1 if alive else Q[Q_ALIVE * PK + j]


@ir_inline
def _emission(sa, S, Q, j, prim, p, ns, d, beta):
    """Emission seen by the lane's segment, MIS-weighted against the next-event estimate before it."""
    em = sa.prim_info[prim, INFO_EMITTER]
    if em < 0:
        return
    le = eval_emitter(sa.emitters, em, ns, d)
    if le[0] + le[1] + le[2] > 0.0:
        w = 1.0
        if Q[Q_DELTA * PK + j] == 0:
            w = power_heuristic(S[R_PPDF * PK + j], emitter_pdf(sa.emitters, em, get3(S, R_PP, j), p, ns))
        S[R_L * PK + j] += beta[0] * le[0] * w
        S[(R_L + 1) * PK + j] += beta[1] * le[1] * w
        S[(R_L + 2) * PK + j] += beta[2] * le[2] * w


@leaf
def _shade_hit(sa, S, Q, j, max_depth):
    """``radiance_path``'s bounce for lane j up to the next-event estimate: the surface interaction,
    the emission it sees, and whether the path scatters there (Q_CONT, with its frame and wi)."""
    Q[Q_ALIVE * PK + j] = 0
    Q[Q_NEE * PK + j] = 0
    Q[Q_CONT * PK + j] = 0
    Q[Q_EMP * PK + j] = -1
    Q[Q_DIFF * PK + j] = 0
    S[(R_SO + 6) * PK + j] = -1.0
    prim = Q[Q_PRIM * PK + j]
    if Q[Q_ITEM * PK + j] < 0 or prim < 0:          # idle, or escaped (no environment)
        return
    o, d = get3(S, R_O, j), get3(S, R_O + 3, j)
    p, ng, ns = surface(sa.prims, sa.prim_info, prim, o, d, S[(R_O + 6) * PK + j], S[S_U * PK + j], S[S_V * PK + j])
    _emission(sa, S, Q, j, prim, p, ns, d, get3(S, R_BETA, j))
    if Q[Q_DEPTH * PK + j] + 1 >= max_depth:
        return
    s, tt = coordinate_system(ns)
    set3(S, R_WI, j, to_local((-d[0], -d[1], -d[2]), s, tt, ns))
    set3(S, R_P, j, p)
    set3(S, R_NG, j, ng)
    set3(S, R_NS, j, ns)
    set3(S, R_FS, j, s)
    set3(S, R_FT, j, tt)
    m = sa.prim_info[prim, INFO_MAT]
    Q[Q_MAT * PK + j] = m
    Q[Q_CONT * PK + j] = 1
    if sa.materials[m, MAT_TYPE] == DIFFUSE:       # for the SIMD loops: next_diffuse, nee_diffuse_area
        Q[Q_DIFF * PK + j] = 1
        set3(S, R_MREF, j, (sa.materials[m, MAT_R], sa.materials[m, MAT_R + 1], sa.materials[m, MAT_R + 2]))
        S[R_M2S * PK + j] = sa.materials[m, MAT_TWOSIDED]


@leaf
def _shade_nee(sa, S, Q, j):
    """The next-event estimate of lane j's vertex (pending its shadow ray), or its deferral."""
    if Q[Q_CONT * PK + j] == 0:
        return
    mat = sa.materials[Q[Q_MAT * PK + j]]
    if bsdf_is_delta_only(mat) or defer_diffuse_area(sa, S, Q, j, mat):
        return
    frame = (get3(S, R_FS, j), get3(S, R_FT, j), get3(S, R_NS, j))
    nee_lane(sa, S, Q, j, get3(S, R_P, j), get3(S, R_NG, j), frame, get3(S, R_WI, j), mat, get3(S, R_BETA, j))


@leaf
def _shade_next(sa, S, Q, j, rr_depth):
    """Lane j's BSDF sample, next ray and Russian roulette; Q_ALIVE says whether the path goes on.
    A diffuse vertex's is :func:`next_diffuse`'s, for all such lanes at once."""
    if Q[Q_CONT * PK + j] == 0 or Q[Q_DIFF * PK + j] != 0:
        return
    mat = sa.materials[Q[Q_MAT * PK + j]]
    wi = get3(S, R_WI, j)
    u = get3(S, R_UBSDF, j)
    wo, weight, pdf, is_delta = bsdf_sample(mat, wi, u[0], u[1], u[2])
    if not pdf > 0.0:
        return
    beta = get3(S, R_BETA, j)
    beta = (beta[0] * weight[0], beta[1] * weight[1], beta[2] * weight[2])
    eta = S[R_ETA * PK + j] * bsdf_eta(mat, wi, wo)
    p, ng = get3(S, R_P, j), get3(S, R_NG, j)
    d = to_world(wo, get3(S, R_FS, j), get3(S, R_FT, j), get3(S, R_NS, j))
    set3(S, R_O, j, offset_origin(p, ng, d))
    set3(S, R_O + 3, j, d)
    S[(R_O + 6) * PK + j] = math.inf
    set3(S, R_PP, j, p)
    S[R_PPDF * PK + j] = pdf
    S[R_ETA * PK + j] = eta
    Q[Q_DELTA * PK + j] = np.int64(is_delta)
    depth = Q[Q_DEPTH * PK + j] + 1
    Q[Q_DEPTH * PK + j] = depth
    bmax = max3(beta)
    if depth >= rr_depth:
        q = min(bmax * eta * eta, 0.95)
        if S[R_URR * PK + j] >= q:             # rand_at(h, dim(depth - 1, D_RR))
            return
        beta = (beta[0] / q, beta[1] / q, beta[2] / q)
    if not bmax > 0.0:
        return
    set3(S, R_BETA, j, beta)
    Q[Q_ALIVE * PK + j] = 1


def _trace(sa, S, Q, ro, stack, any_hit):
    """The lanes' rays at row ro: as a packet when the tree is one leaf; else ray by ray with the
    scalar traversal (incoherent rays through a tree share too few nodes for a packet to pay).
    Compiled for the BVH's form (:mod:`gdlearn.kernels.accel.forms`): a one-leaf scene's kernels
    hold the packet's leaf test alone."""
    raise NotImplementedError("compiled code only")


@overload(_trace, jit_options=LEAF_OPTIONS)
def _trace_typed(sa, S, Q, ro, stack, any_hit):
    body = _trace_leaf if one_leaf(sa.types[sa.fields.index("node_info")]) else _trace_tree

    def impl(sa, S, Q, ro, stack, any_hit):
        body(sa, S, Q, ro, stack, any_hit)

    return impl


@leaf
def _trace_leaf(sa, S, Q, ro, stack, any_hit):
    packet_trace_leaf(sa.nodes, sa.node_info, sa.prims, sa.prim_info, S, Q, ro, any_hit)


@leaf
def _trace_tree(sa, S, Q, ro, stack, any_hit):
    if sa.node_info[0, 1] > 0:
        packet_trace_leaf(sa.nodes, sa.node_info, sa.prims, sa.prim_info, S, Q, ro, any_hit)
        return
    for j in range(PK):
        o, d, tmax = get3(S, ro, j), get3(S, ro + 3, j), S[(ro + 6) * PK + j]
        if any_hit:
            Q[Q_HIT * PK + j] = 0
            if tmax > 0.0:
                Q[Q_HIT * PK + j] = np.int64(any_hit_inline(sa.nodes, sa.node_info, sa.prims, sa.prim_info, o, d, 0.0,
                                                            tmax, stack, False, sa.materials) >= 0)
        else:
            Q[Q_PRIM * PK + j] = -1
            if tmax > 0.0:
                t, prim, u, v = closest_hit_inline(sa.nodes, sa.node_info, sa.prims, sa.prim_info, o, d, 0.0, tmax, stack)
                Q[Q_PRIM * PK + j] = prim
                S[(ro + 6) * PK + j], S[S_U * PK + j], S[S_V * PK + j] = t, u, v


@leaf
def _finish(sa, S, Q, buf, nxt, nitems, items, seed):
    """Add the visible next-event terms; a lane whose path ended stores its radiance and takes the
    next item. Returns the next item and the number of busy lanes."""
    busy = 0
    for j in range(PK):
        if Q[Q_NEE * PK + j] != 0 and Q[Q_HIT * PK + j] == 0:
            for k in range(3):
                S[(R_L + k) * PK + j] += S[(R_C + k) * PK + j]
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


# IR-inlined into its callers (pt's row, gpt-replay's non-inlined ``_trace``): as a function of its
# own it was compiled twice, in its own library and again in the caller's (kernels.jit)
@ir_inline
def trace_items(sa, items, nitems, seed, max_depth, rr_depth, S, Q, buf, stack):
    """The radiance of the camera paths of items 0 .. nitems-1 of the table ``items`` (film
    position, key, sample: :data:`IT_FX` ...) into ``buf[3 i : 3 i + 3]``, each path
    ``radiance_path``'s with the item's random numbers, ``PK`` paths at a time."""
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
            _shade_hit(sa, S, Q, j, max_depth)
            _shade_nee(sa, S, Q, j)
            _shade_next(sa, S, Q, j, rr_depth)
        nee_diffuse_area(S, Q)             # the deferred estimates read beta before next_diffuse
        next_diffuse(S, Q, rr_depth)
        _trace(sa, S, Q, R_SO, stack, True)
        nxt, busy = _finish(sa, S, Q, buf, nxt, nitems, items, seed)


@leaf
def fill_pixel_items(items, i0, m, y, w, spp, seed, sample0):
    """Items 0 .. m-1 of the table: ``pt._rows_path``'s camera samples i0 .. i0+m-1 of row y (pixel
    by pixel, sample by sample), film positions and random numbers."""
    for i in range(m):
        x, s = (i0 + i) // spp, sample0 + (i0 + i) % spp
        key = y * w + x
        items[i, IT_FX], items[i, IT_FY] = x + rand(seed, key, s, 0), y + rand(seed, key, s, 1)
        items[i, IT_KEY], items[i, IT_S] = key, s


@leaf
def sum_items(buf, m, i0, spp, acc):
    """Add the radiances of items 0 .. m-1 (the row's samples i0 .. i0+m-1) to their pixels' sums
    ``acc`` (W x 3), in sample order as ``pt._rows_path`` does; returns the non-finite ones dropped."""
    nbad = 0
    for i in range(m):
        c0, c1, c2 = buf[3 * i], buf[3 * i + 1], buf[3 * i + 2]
        if np.isfinite(c0) and np.isfinite(c1) and np.isfinite(c2):
            x = (i0 + i) // spp
            acc[x, 0] += c0
            acc[x, 1] += c1
            acc[x, 2] += c2
        else:
            nbad += 1
    return nbad


@leaf
def write_row(out, y, acc, spp):
    inv = 1.0 / spp
    for x in range(out.shape[1]):
        for c in range(3):
            out[y, x, c] = acc[x, c] * inv


@ir_inline
def render_row_packet(sa, y, seed, sample0, spp, max_depth, rr_depth, out, S, Q, buf, items, acc, stack):
    """Row y of ``pt._rows_path``'s image (the mean of samples sample0 .. sample0+spp-1 per pixel
    into out[y]), traced in packets; returns the number of non-finite samples dropped. The row's
    samples go through the item table in chunks; ``acc`` (W x 3) sums them per pixel."""
    n = out.shape[1] * spp
    acc[:, :] = 0.0
    nbad = 0
    for i0 in range(0, n, items.shape[0]):
        m = min(items.shape[0], n - i0)
        fill_pixel_items(items, i0, m, y, out.shape[1], spp, seed, sample0)
        trace_items(sa, items, m, seed, max_depth, rr_depth, S, Q, buf, stack)
        nbad += sum_items(buf, m, i0, spp, acc)
    write_row(out, y, acc, spp)
    return nbad
