"""The volumetric path tracer: Mitsuba 3's ``volpath`` for homogeneous media, one path per call.

The radiative transfer estimator of Mitsuba 3 ``src/integrators/volpath.cpp`` (the volume rendering
equation of Jarosz et al. 2008, Eq. 1-4): along every segment inside a medium a free-flight distance
is sampled (:func:`gdlearn.kernels.media.medium.sample_distance`, spectral MIS over the RGB channels); a
collision before the next surface is a medium scattering vertex (next-event estimation weighted by
the phase function, then Henyey-Greenstein phase sampling, MIS with the power heuristic), otherwise
the ray reaches the surface with weight T / P(pass).

Rules taken from volpath (they change the image, so they follow Mitsuba exactly):

* the camera ray starts in the sensor's medium;
* at a surface of a shape that declares an interior or exterior medium, a ray continuing to the back
  side of the geometric normal enters ``interior``, else ``exterior`` (None = vacuum); a shape
  declaring neither leaves the current medium unchanged (``Shape::is_medium_transition``);
* a ``null`` BSDF is an index-matched interface: the ray passes on, it is not a bounce (depth is
  not incremented, the MIS reference vertex and pdf stay those of the last real scattering event);
* a medium scattering event counts as a bounce; NEE happens at a vertex only while
  ``depth + 1 < max_depth``;
* shadow rays pass null interfaces and accumulate the transmittance of every medium they cross; any
  other surface blocks them. After each crossing the ray is aimed again at the emitter point from its
  new, pushed-off origin (a short ray would otherwise run past the SHADOW_EPS
  slack into the emitter's own surface and count as blocked).

Random numbers: the layout of :mod:`gdlearn.integrators.path.surface`, indexed by the bounce (real
vertices: scattering events and non-null surfaces); a flight that passes through one medium into
another draws the next distance from ``surface.flight_dim``'s own dimensions, so crossing one more
null interface does not shift the numbers of any later vertex.

Compiled without reference counting and with the next-event estimator inlined, for the reasons given
in :mod:`gdlearn.integrators.path.surface`.
"""
import math


from gdlearn.kernels.bsdf.dispatch import (bsdf_eta, bsdf_eval, bsdf_is_delta_only, bsdf_is_null, bsdf_pdf, bsdf_sample,
                   nee_class_share, nee_classes, sampled_lobe_class)
from gdlearn.kernels.accel.bvh import closest_hit_inline
from gdlearn.kernels.camera import camera_ray
from gdlearn.kernels.geometry import INFO_EMITTER, INFO_MAT, offset_origin, surface
from gdlearn.kernels.layout import MAT_TYPE, NULL, V_MEDIUM
from gdlearn.kernels.lights import emitter_pdf, eval_emitter, sample_emitter
from gdlearn.kernels.media.boundary import next_medium   # the one rule, shared with light tracing
from gdlearn.kernels.media.medium import medium_params, sample_distance, transmittance
from gdlearn.kernels.pathclass import pc_init, pc_push, pc_reachable
from gdlearn.kernels.media.phase import hg_eval, hg_sample
from gdlearn.kernels.rng import path_state, rand_at
from gdlearn.kernels.sampling import power_heuristic
from gdlearn.kernels.scene_query import SHADOW_EPS
from gdlearn.integrators.path.surface import (FLIGHT_STRIDE, D_BSDF_U1, D_BSDF_U2, D_EM_SEL, D_EM_U1, D_EM_U2, D_LOBE, D_MED_CH,
                                              D_MED_T, D_RR, _wanted, dim, flight_dim)
from gdlearn.kernels.vec import coordinate_system, dot, max3, to_local, to_world
from gdlearn.kernels.jit import block, inlined, leaf, noalloc

#: hard bound on segments per path (null interfaces do not count as bounces, so max_depth alone
#: does not bound the loop)
MAX_SEGMENTS = 4096
assert MAX_SEGMENTS <= FLIGHT_STRIDE    # surface.flight_dim's media per flight


@inlined
def roulette(beta, eta, depth, rr_depth, u):
    """Mitsuba's Russian roulette from rr_depth on: survive with q = min(max(beta) eta^2, 0.95) and
    divide by q. Returns (alive, beta)."""
    bmax = max3(beta)
    if not bmax > 0.0:
        return False, beta
    if depth < rr_depth:
        return True, beta
    q = min(bmax * eta * eta, 0.95)
    if u >= q:
        return False, beta
    return True, (beta[0] / q, beta[1] / q, beta[2] / q)


# inlined: gpt's media kernel calls it per vertex and offset, and the call line alone held 9 % of a
# fog-box pass (passing the scene's arrays); the cold compile did not move (benchmarks/README.md)
@leaf
def shadow_transmittance(sa, p, ng, q, medium, stack):
    """Transmittance from p (surface normal ng, or zeros in a medium) to q, crossing null interfaces
    and the media between them; 0 if any non-null surface blocks the segment."""
    o, d, remaining = shadow_start(p, ng, q)
    if remaining < 0.0:
        return (1.0, 1.0, 1.0)
    return shadow_march(sa, o, d, remaining, q, medium, (1.0, 1.0, 1.0), MAX_SEGMENTS, stack)


@inlined
def shadow_march(sa, o, d, remaining, q, medium, tr, segments, stack):
    """The transmittance ``tr`` carried along a shadow ray towards q from the segment (o, d,
    ``remaining``) in ``medium`` on, at most ``segments`` segments (:func:`shadow_step` each)."""
    for _ in range(segments):
        # the traversal inlined: one call per shadow ray instead of two, each passing the scene's
        # arrays as dozens of scalars (benchmarks/README, pt speed)
        t, prim, u, v = closest_hit_inline(sa.nodes, sa.node_info, sa.prims, sa.prim_info, o, d, 0.0, remaining,
                                           stack)
        done, tr, o, d, remaining, medium = shadow_step(sa, o, d, remaining, q, medium, tr, t, prim, u, v)
        if done:
            return tr
    return tr


@inlined
def shadow_start(p, ng, q):
    """The first segment (o, d, length) of the shadow ray from p (surface normal ng, or zeros in a
    medium) to q; length -1 when p is q (nothing in between: transmittance 1)."""
    d = (q[0] - p[0], q[1] - p[1], q[2] - p[2])
    o = offset_origin(p, ng, d) if (ng[0] != 0.0 or ng[1] != 0.0 or ng[2] != 0.0) else p
    d = (q[0] - o[0], q[1] - o[1], q[2] - o[2])
    dist = math.sqrt(dot(d, d))
    if dist == 0.0:
        return o, d, -1.0
    d = (d[0] / dist, d[1] / dist, d[2] / dist)
    return o, d, dist * (1.0 - SHADOW_EPS)


@inlined
def shadow_step(sa, o, d, remaining, q, medium, tr, t, prim, u, v):
    """One traced segment of a shadow ray towards q (closest hit t, prim, u, v within ``remaining``
    in ``medium``): (done, transmittance so far, and the next segment's o, d, length, medium)."""
    seg = remaining if prim < 0 else t
    if medium >= 0:
        sig = sa.media[medium]
        x = transmittance((sig[0], sig[1], sig[2]), seg)
        tr = (tr[0] * x[0], tr[1] * x[1], tr[2] * x[2])
    if prim < 0:
        return True, tr, o, d, remaining, medium
    if sa.materials[sa.prim_info[prim, INFO_MAT], MAT_TYPE] != NULL:
        return True, (0.0, 0.0, 0.0), o, d, remaining, medium
    hp, hng, hns = surface(sa.prims, sa.prim_info, prim, o, d, t, u, v)
    medium = next_medium(sa.prim_info, prim, medium, d, hng)
    o = offset_origin(hp, hng, d)
    # aimed again at q from the pushed-off origin (as shadow_ray does for the first segment): the
    # push moves o off the line p -> q by ~1e-7, so keeping d and "remaining -= t" let a short
    # or grazing ray run past its SHADOW_EPS slack into q's own surface (an area emitter), which
    # then counted as a blocker
    d, remaining = _aim(o, q)
    done = remaining <= 0.0 or max3(tr) == 0.0
    return done, tr, o, d, remaining, medium


@inlined
def _aim(o, q):
    """(unit direction, length) of a shadow ray from ``o`` that stops just short of ``q``: the
    length is |q - o| shortened by SHADOW_EPS (:func:`gdlearn.kernels.scene_query.shadow_ray`)."""
    dv = (q[0] - o[0], q[1] - o[1], q[2] - o[2])
    dist = math.sqrt(dot(dv, dv))
    if not dist > 0.0:
        return (0.0, 0.0, 1.0), 0.0
    inv = 1.0 / dist
    return (dv[0] * inv, dv[1] * inv, dv[2] * inv), dist * (1.0 - SHADOW_EPS)


@leaf
def nee_volume(sa, p, ng, prim, medium, h, bounce, stack):
    """Emitter sample from p with transmittance: (em, d, weight, pdf, is_delta) with weight =
    Le T / pdf (Mitsuba volpath's ``sample_emitter``); em = -1 when it carries nothing.
    ``prim`` is the surface p lies on (-1 for a medium vertex): the shadow ray starts in the medium
    on the side it leaves towards, as Mitsuba's ``si.target_medium(ds.d)``."""
    em, q, nq, dl, dist, w_em, pdf_em, pdf_a, delta = sample_emitter(
        sa.emitters, sa.em_prims, sa.em_cdf, sa.prims, sa.prim_info, p,
        rand_at(h, dim(bounce, D_EM_SEL)), rand_at(h, dim(bounce, D_EM_U1)),
        rand_at(h, dim(bounce, D_EM_U2)))
    if em < 0:
        return -1, dl, (0.0, 0.0, 0.0), 0.0, delta
    if prim >= 0:
        medium = next_medium(sa.prim_info, prim, medium, dl, ng)
    tr = shadow_transmittance(sa, p, ng, q, medium, stack)
    if tr[0] == 0.0 and tr[1] == 0.0 and tr[2] == 0.0:
        return -1, dl, (0.0, 0.0, 0.0), 0.0, delta
    return em, dl, (w_em[0] * tr[0], w_em[1] * tr[1], w_em[2] * tr[2]), pdf_em, delta


@noalloc
def radiance_volpath(sa, o, d, tmax, seed, key, sample, max_depth, rr_depth, mask, threshold, stack):
    """Radiance along the camera ray (o, d) (Mitsuba ``volpath``): :func:`radiance_volpath_inline`
    as a function of its own (see ``surface_path.radiance_path``)."""
    return radiance_volpath_inline(sa, o, d, tmax, seed, key, sample, max_depth, rr_depth, mask, threshold, stack)


# forceinline: inlined into the path tracer's pixel loop (see surface_path.radiance_path_inline)
@leaf
def radiance_volpath_inline(sa, o, d, tmax, seed, key, sample, max_depth, rr_depth, mask, threshold, stack):
    """Radiance along the camera ray (o, d) (Mitsuba ``volpath``; see the module docstring)."""
    h = path_state(seed, key, sample)      # hashed once: each number is then one finaliser
    L = (0.0, 0.0, 0.0)
    beta = (1.0, 1.0, 1.0)
    eta = 1.0
    medium = sa.camera_medium
    prev_p = o
    prev_pdf = 1.0
    prev_delta = True           # Mitsuba's count_direct: camera ray or a specular chain
    state = pc_init()
    depth = 0
    b, j = 0, 0                 # the bounce (random-number block) and the media its flight passed through
    for _ in range(MAX_SEGMENTS):
        t, prim, u, v = closest_hit_inline(sa.nodes, sa.node_info, sa.prims, sa.prim_info, o, d, 0.0, tmax, stack)
        tmax = math.inf
        if medium >= 0:
            sig, alb, g = medium_params(sa.media[medium])
            ts, scattered, w = sample_distance(sig, alb, t, rand_at(h, flight_dim(b, j, D_MED_CH)),
                                               rand_at(h, flight_dim(b, j, D_MED_T)))
            j += 1
            beta = (beta[0] * w[0], beta[1] * w[1], beta[2] * w[2])
            if scattered:
                depth += 1
                if depth >= max_depth:
                    break
                p = (o[0] + ts * d[0], o[1] + ts * d[1], o[2] + ts * d[2])
                wi = (-d[0], -d[1], -d[2])
                state = pc_push(state, V_MEDIUM)
                if _wanted(mask, state):
                    em, dl, wl, pdf_em, delta = nee_volume(sa, p, (0.0, 0.0, 0.0), -1, medium, h,
                                                           b, stack)
                    if em >= 0:
                        ph = hg_eval(g, dot(wi, dl))
                        mw = 1.0 if delta else power_heuristic(pdf_em, ph)
                        k = ph * mw
                        L = (L[0] + beta[0] * wl[0] * k, L[1] + beta[1] * wl[1] * k, L[2] + beta[2] * wl[2] * k)
                if not pc_reachable(state, mask):
                    break
                d, pdf = hg_sample(g, wi, rand_at(h, dim(b, D_BSDF_U1)),
                                   rand_at(h, dim(b, D_BSDF_U2)))
                if not pdf > 0.0:
                    break
                o = p
                prev_p = p
                prev_pdf = pdf
                prev_delta = False
                alive, beta = roulette(beta, eta, depth, rr_depth, rand_at(h, dim(b, D_RR)))
                if not alive:
                    break
                b, j = b + 1, 0
                continue
        if prim < 0:
            if sa.env >= 0 and _wanted(mask, state):
                le = eval_emitter(sa.emitters, sa.env, d, d)
                w = 1.0 if prev_delta else power_heuristic(prev_pdf, emitter_pdf(sa.emitters, sa.env, prev_p, d, d))
                L = (L[0] + beta[0] * le[0] * w, L[1] + beta[1] * le[1] * w, L[2] + beta[2] * le[2] * w)
            break
        p, ng, ns = surface(sa.prims, sa.prim_info, prim, o, d, t, u, v)
        em = sa.prim_info[prim, INFO_EMITTER]
        if em >= 0 and _wanted(mask, state):
            le = eval_emitter(sa.emitters, em, ns, d)
            if le[0] + le[1] + le[2] > 0.0:
                w = 1.0 if prev_delta else power_heuristic(prev_pdf, emitter_pdf(sa.emitters, em, prev_p, p, ns))
                L = (L[0] + beta[0] * le[0] * w, L[1] + beta[1] * le[1] * w, L[2] + beta[2] * le[2] * w)
        mat = sa.materials[sa.prim_info[prim, INFO_MAT]]
        if bsdf_is_null(mat):           # index-matched interface: not a bounce, not a vertex
            medium = next_medium(sa.prim_info, prim, medium, d, ng)
            o = offset_origin(p, ng, d)
            continue
        if depth + 1 >= max_depth:
            break
        s, tt = coordinate_system(ns)
        wi = to_local((-d[0], -d[1], -d[2]), s, tt, ns)
        c_coat, c_rest = nee_classes(mat, threshold)
        want_coat = _wanted(mask, pc_push(state, c_coat))
        want_rest = _wanted(mask, pc_push(state, c_rest))
        if not bsdf_is_delta_only(mat) and (want_coat or want_rest):
            em2, dl, wl, pdf_em, delta = nee_volume(sa, p, ng, prim, medium, h, b, stack)
            if em2 >= 0:
                wo = to_local(dl, s, tt, ns)
                f = bsdf_eval(mat, wi, wo)
                k = 1.0 if delta else power_heuristic(pdf_em, bsdf_pdf(mat, wi, wo))
                k *= nee_class_share(mat, wi, wo, want_coat, want_rest)   # a rough plastic's split
                L = (L[0] + beta[0] * f[0] * wl[0] * k, L[1] + beta[1] * f[1] * wl[1] * k,
                     L[2] + beta[2] * f[2] * wl[2] * k)
        u_lobe = rand_at(h, dim(b, D_LOBE))
        wo, weight, pdf, is_delta = bsdf_sample(mat, wi, u_lobe, rand_at(h, dim(b, D_BSDF_U1)),
                                               rand_at(h, dim(b, D_BSDF_U2)))
        if not pdf > 0.0:
            break
        beta = (beta[0] * weight[0], beta[1] * weight[1], beta[2] * weight[2])
        eta *= bsdf_eta(mat, wi, wo)
        d = to_world(wo, s, tt, ns)
        o = offset_origin(p, ng, d)
        medium = next_medium(sa.prim_info, prim, medium, d, ng)
        state = pc_push(state, sampled_lobe_class(mat, wi, u_lobe, is_delta, threshold))
        if not pc_reachable(state, mask):
            break
        prev_p = p
        prev_pdf = pdf
        prev_delta = is_delta
        depth += 1
        alive, beta = roulette(beta, eta, depth, rr_depth, rand_at(h, dim(b, D_RR)))
        if not alive:
            break
        b, j = b + 1, 0
    return L


@block
def radiance(sa, film_x, film_y, seed, key, sample, max_depth, rr_depth, mask, threshold, stack):
    """:func:`radiance_volpath` for the camera ray through raster point (film_x, film_y); the key is
    separate from the position for random-sequence replay (see ``surface_path.radiance``)."""
    o, d, tmax = camera_ray(sa.camera, film_x, film_y)
    return radiance_volpath(sa, o, d, tmax, seed, key, sample, max_depth, rr_depth, mask, threshold, stack)
