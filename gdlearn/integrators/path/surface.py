"""The primal path tracer for surfaces: Mitsuba 3's ``path`` integrator, one path per call.

Unidirectional path tracing with next-event estimation and BSDF sampling combined by multiple
importance sampling (Veach 1997, Sec. 9.2, power heuristic; Mitsuba 3 ``src/integrators/path.cpp``),
Russian roulette from ``rr_depth`` on with Mitsuba's survival probability
``q = min(max(throughput) * eta^2, 0.95)``. ``max_depth`` counts path segments as Mitsuba does:
1 = emitters seen directly, 2 = direct lighting, -1 = unbounded. Media are ignored (``path``
ignores them too); :mod:`gdlearn.integrators.path.volume` is the ``volpath`` counterpart.

Random numbers (the layout random-sequence replay depends on, book chapter "replay"):
``rand_at(h, dim)`` with the pixel's key and

* dims 0, 1: the film position inside the pixel (drawn by the caller),
* bounce b uses dims ``2 + b * DIMS_PER_BOUNCE + k`` with k =
  0 emitter choice, 1-2 emitter point, 3 BSDF lobe, 4-5 BSDF direction, 6 Russian roulette,
  7 medium distance, 8 medium channel (volpath), 9 spare;
* the flight leaving bounce b (volpath) samples its first medium with dims 7-8 of the block and,
  after passing through j >= 1 media (null interfaces between them), the next one with
  ``FLIGHT_DIMS0 + 2 (b FLIGHT_STRIDE + j - 1) + {0, 1}`` (:func:`flight_dim`), far above every
  block. So no vertex's numbers depend on how many null interfaces the path crossed before it, and
  an interface in vacuum changes no number at all: a replayed offset whose ray enters a medium's
  boundary where the base's passes beside it still reads, at its next vertex, the numbers its own
  path tracer would (``gpt_volume.mixed``).

The radiance function receives the key *separately* from the film position, so an offset path can
replay the base path's numbers at a neighbouring pixel.

Speed (benchmarks/README.md, "pt speed"): the kernels here are compiled without reference counting
(numba's ``_nrt=False``): they only read the scene's arrays, which their caller keeps alive, and
never allocate, while every array view (a material row) would otherwise cost two calls to numba's
non-inlinable atomic reference-count functions per bounce. ``forceinline`` lets LLVM inline the
next-event estimator into the bounce loop (a call passes the scene's arrays as ~100 scalars).
"""
import math


from gdlearn.kernels.bsdf.dispatch import (bsdf_eta, bsdf_eval_pdf, bsdf_is_delta_only, bsdf_is_null, bsdf_sample,
                   nee_class_share, nee_classes, sampled_lobe_class)
from gdlearn.kernels.accel.bvh import closest_hit_inline
from gdlearn.kernels.camera import camera_ray
from gdlearn.kernels.geometry import INFO_EMITTER, INFO_MAT, offset_origin, surface
from gdlearn.kernels.lights import emitter_pdf, eval_emitter, sample_emitter
from gdlearn.kernels.pathclass import pc_init, pc_push, pc_reachable, pc_wanted
from gdlearn.kernels.rng import path_state, rand_at
from gdlearn.kernels.sampling import power_heuristic
from gdlearn.kernels.scene_query import occluded
from gdlearn.kernels.vec import coordinate_system, max3, to_local, to_world
from gdlearn.kernels.jit import block, inlined, leaf, noalloc

DIMS_PER_BOUNCE = 10
D_EM_SEL, D_EM_U1, D_EM_U2, D_LOBE, D_BSDF_U1, D_BSDF_U2, D_RR, D_MED_T, D_MED_CH = range(9)
#: first dimension of a flight's media after its first, and the media one flight may pass through
#: (volume.MAX_SEGMENTS bounds the count)
FLIGHT_DIMS0, FLIGHT_STRIDE = 1 << 24, 1 << 12



@inlined
def dim(bounce, k):
    """The RNG dimension of quantity k at bounce b (see the module docstring)."""
    return 2 + bounce * DIMS_PER_BOUNCE + k


@inlined
def flight_dim(bounce, j, k):
    """The RNG dimension of the medium quantity k (D_MED_T, D_MED_CH) of the flight leaving bounce b,
    in the medium it enters after passing through j others (module docstring)."""
    if j == 0:
        return dim(bounce, k)
    return FLIGHT_DIMS0 + 2 * (bounce * FLIGHT_STRIDE + j - 1) + (k - D_MED_T)


@leaf
def nee_surface(sa, p, ng, ns_frame, wi, mat, h, bounce, stack, want_coat=True, want_rest=True):
    """Emitter sampling at a surface vertex, MIS-weighted against BSDF sampling: rgb (no throughput).

    ``want_coat`` / ``want_rest``: which of the vertex's :func:`bsdf.nee_classes` the effects mask
    keeps; a rough plastic's term is split between them by :func:`bsdf.nee_class_share`."""
    s, t, n = ns_frame
    em, q, nq, dl, dist, w_em, pdf_em, pdf_a, delta = sample_emitter(
        sa.emitters, sa.em_prims, sa.em_cdf, sa.prims, sa.prim_info, p,
        rand_at(h, dim(bounce, D_EM_SEL)), rand_at(h, dim(bounce, D_EM_U1)),
        rand_at(h, dim(bounce, D_EM_U2)))
    if em < 0:
        return (0.0, 0.0, 0.0)
    wo = to_local(dl, s, t, n)
    f, pdf_b = bsdf_eval_pdf(mat, wi, wo)
    if f[0] == 0.0 and f[1] == 0.0 and f[2] == 0.0:
        return (0.0, 0.0, 0.0)
    if occluded(sa, p, ng, q, stack):
        return (0.0, 0.0, 0.0)
    w = 1.0 if delta else power_heuristic(pdf_em, pdf_b)
    w *= nee_class_share(mat, wi, wo, want_coat, want_rest)
    return (f[0] * w_em[0] * w, f[1] * w_em[1] * w, f[2] * w_em[2] * w)


@inlined
def _wanted(mask, state):
    """Does the effects mask ask for the class of a path ending at a light after ``state``
    (and, with ``pathclass.MEDIA_TRANSPORT``, for its camera end)?"""
    return pc_wanted(state, mask)


@noalloc
def radiance_path(sa, o, d, tmax, seed, key, sample, max_depth, rr_depth, mask, threshold, stack):
    """Radiance along the camera ray (o, d) (Mitsuba ``path``): :func:`radiance_path_inline` as a
    function of its own, for callers that trace a path here and there (the gradient kernels)."""
    return radiance_path_inline(sa, o, d, tmax, seed, key, sample, max_depth, rr_depth, mask, threshold, stack)


# forceinline: the path tracer's pixel loop inlines the whole path (a call passes the scene's arrays
# as ~100 scalars, ~9% of a Cornell-box sample)
@leaf
def radiance_path_inline(sa, o, d, tmax, seed, key, sample, max_depth, rr_depth, mask, threshold, stack):
    """Radiance along the camera ray (o, d) (Mitsuba ``path``). Returns rgb.

    ``mask``: effect-class bits to keep (``pathclass.ALL_MASK`` for the full image); the class of
    every contribution is tracked with :mod:`gdlearn.kernels.pathclass` (vertex classes from the
    BSDF with roughness ``threshold``) and a path stops once no wanted class is reachable.
    A null BSDF passes the ray on; as in Mitsuba's ``path`` it still counts towards max_depth, but
    it is not a vertex of the path's class.
    """
    h = path_state(seed, key, sample)      # hashed once: each number is then one finaliser
    L0 = 0.0
    L1 = 0.0
    L2 = 0.0
    beta = (1.0, 1.0, 1.0)
    eta = 1.0
    prev_p = o
    prev_pdf = 1.0
    prev_delta = True
    state = pc_init()
    depth = 0
    while True:
        t, prim, u, v = closest_hit_inline(sa.nodes, sa.node_info, sa.prims, sa.prim_info, o, d, 0.0, tmax, stack)
        tmax = math.inf
        if prim < 0:
            if sa.env >= 0 and _wanted(mask, state):       # escaped: the constant emitter
                le = eval_emitter(sa.emitters, sa.env, d, d)
                w = 1.0 if prev_delta else power_heuristic(prev_pdf, emitter_pdf(sa.emitters, sa.env, prev_p, d, d))
                L0 += beta[0] * le[0] * w
                L1 += beta[1] * le[1] * w
                L2 += beta[2] * le[2] * w
            break
        p, ng, ns = surface(sa.prims, sa.prim_info, prim, o, d, t, u, v)
        em = sa.prim_info[prim, INFO_EMITTER]
        if em >= 0 and _wanted(mask, state):   # emission seen by this segment, MIS against NEE before it
            le = eval_emitter(sa.emitters, em, ns, d)
            if le[0] + le[1] + le[2] > 0.0:
                w = 1.0 if prev_delta else power_heuristic(prev_pdf, emitter_pdf(sa.emitters, em, prev_p, p, ns))
                L0 += beta[0] * le[0] * w
                L1 += beta[1] * le[1] * w
                L2 += beta[2] * le[2] * w
        if depth + 1 >= max_depth:
            break
        mat = sa.materials[sa.prim_info[prim, INFO_MAT]]
        s, tt = coordinate_system(ns)
        wi = to_local((-d[0], -d[1], -d[2]), s, tt, ns)
        null = bsdf_is_null(mat)
        c_coat, c_rest = nee_classes(mat, threshold)
        want_coat = _wanted(mask, pc_push(state, c_coat))
        want_rest = _wanted(mask, pc_push(state, c_rest))
        if not bsdf_is_delta_only(mat) and (want_coat or want_rest):
            c = nee_surface(sa, p, ng, (s, tt, ns), wi, mat, h, depth, stack, want_coat, want_rest)
            L0 += beta[0] * c[0]
            L1 += beta[1] * c[1]
            L2 += beta[2] * c[2]
        u_lobe = rand_at(h, dim(depth, D_LOBE))
        wo, weight, pdf, is_delta = bsdf_sample(mat, wi, u_lobe, rand_at(h, dim(depth, D_BSDF_U1)),
                                               rand_at(h, dim(depth, D_BSDF_U2)))
        if not pdf > 0.0:
            break
        beta = (beta[0] * weight[0], beta[1] * weight[1], beta[2] * weight[2])
        eta *= bsdf_eta(mat, wi, wo)
        d = to_world(wo, s, tt, ns)
        o = offset_origin(p, ng, d)
        if not null:
            state = pc_push(state, sampled_lobe_class(mat, wi, u_lobe, is_delta, threshold))
            if not pc_reachable(state, mask):
                break
            prev_p = p
            prev_pdf = pdf
            prev_delta = is_delta
        depth += 1
        bmax = max3(beta)
        if depth >= rr_depth:
            q = min(bmax * eta * eta, 0.95)
            if rand_at(h, dim(depth - 1, D_RR)) >= q:
                break
            beta = (beta[0] / q, beta[1] / q, beta[2] / q)
        if not bmax > 0.0:
            break
    return (L0, L1, L2)


@block
def radiance(sa, film_x, film_y, seed, key, sample, max_depth, rr_depth, mask, threshold, stack):
    """The per-path estimator at raster position (film_x, film_y) with the random numbers of
    (seed, key, sample): the camera ray through the film point, then :func:`radiance_path`.

    ``key`` is passed separately from the film position on purpose: random-sequence replay
    (Hua et al. 2019, Sec. 2.3) evaluates the base pixel's key at a neighbouring pixel's position.
    The caller draws the position inside the pixel with dims 0 and 1 of the same key.
    """
    o, d, tmax = camera_ray(sa.camera, film_x, film_y)
    return radiance_path(sa, o, d, tmax, seed, key, sample, max_depth, rr_depth, mask, threshold, stack)
