"""Homogeneous participating media: transmittance and free-flight distance sampling.

A homogeneous medium has extinction sigma_t (RGB, 1/length) and single-scattering albedo
a = sigma_s / sigma_t. Along a ray (Jarosz et al. 2008, Sec. 2, Eq. 1 and Table 1):

    T(t) = exp(-sigma_t t)                                   transmittance T_r = e^-tau (Table 1)
    L(x, w) = T(s) L(x_s) + int_0^s T(t) sigma_s L_i(x_t) dt  volume rendering equation (Eq. 1)

with L_i the in-scattered radiance through the normalised phase function (Eq. 2). The path tracer
estimates the integral of Eq. 1 by sampling t with the free-flight density pdf(t) = sigma_t T(t),
by inversion t = -log(1 - u) / sigma_t; a sample beyond the next surface at t_max "passes" with
probability P(t >= t_max) = T(t_max). With RGB extinction, one channel c is picked uniformly and
t ~ sigma_c exp(-sigma_c t); the estimator uses the one-sample MIS (balance heuristic) density over
the three channels (spectral MIS, Miller et al. 2019; Novak et al. 2018, Sec. 5.1):

    pdf(t) = (1/3) sum_c sigma_c exp(-sigma_c t),      P(t >= t_max) = (1/3) sum_c exp(-sigma_c t_max)
    scatter weight = sigma_s T(t) / pdf(t),            pass weight = T(t_max) / P(t >= t_max)

which is unbiased whatever channel was picked, fine when some channels have sigma = 0 (they never
scatter but still contribute to P) and never scatters when all do. log1p / expm1 keep thin media
(sigma t ~ 1e-8) accurate; dense media (sigma = 1e4) only underflow channels whose weight is 0 anyway.
"""
import math


from gdlearn.kernels.layout import MED_ALBEDO, MED_G, MED_SIGMA_T
from gdlearn.kernels.jit import block, inlined, ir_inline


@ir_inline
def transmittance(sigma_t, t):
    """T(t) = exp(-sigma_t t) per channel (Jarosz et al. 2008, Eq. 2); t = inf gives 0 (or 1 where
    sigma = 0). A grey medium takes one exp for all three (shadow rays cross the fog box's
    medium on every bounce)."""
    if sigma_t[0] == sigma_t[1] and sigma_t[1] == sigma_t[2]:
        x = _tr1(sigma_t[0], t)
        return (x, x, x)
    return (_tr1(sigma_t[0], t), _tr1(sigma_t[1], t), _tr1(sigma_t[2], t))


@ir_inline
def _tr1(sigma, t):
    if sigma == 0.0:
        return 1.0            # avoids 0 * inf = nan for an unbounded segment in a clear channel
    return math.exp(-sigma * t)


@ir_inline
def sample_distance_1(sigma, t_max, u):
    """Single-channel free-flight sampling: t = -log1p(-u) / sigma.

    Returns ``(t, scattered, pdf)``: if t < t_max the event is a collision with density
    pdf = sigma exp(-sigma t); otherwise t = t_max and pdf is the discrete probability exp(-sigma t_max)
    of passing. sigma = 0 always passes with probability 1.
    """
    if sigma <= 0.0:
        return t_max, False, 1.0
    t = -math.log1p(-u) / sigma
    if t < t_max:
        return t, True, sigma * math.exp(-sigma * t)
    return t_max, False, math.exp(-sigma * t_max)


@inlined
def neg_log1m(u):
    """-log(1 - u) for u in [0, 1), as precise as -log1p(-u) and ~3x cheaper (libm's log1p was a
    tenth of a fog-box sample in perf; log is the faster routine).

    When 1 - u is exact -- always for the renderer's 53-bit numbers k 2^-53, and for every u >= 1/2 --
    log(1 - u) is log1p(-u)'s value (both ~correctly rounded from the same real number); the test
    1 - v == u with v = fl(1 - u) detects exactness (it is exact arithmetic for v >= 1/2, and v < 1/2
    means u > 1/2). Other u (a thin-medium test's 1e-20) fall back to log1p."""
    v = 1.0 - u
    if 1.0 - v == u:
        return 0.0 - math.log(v)        # not -log: u = 0 must give +0.0, as -log1p(-0.0) does
    return -math.log1p(-u)


@ir_inline
def distance_pdf(sigma_t, t):
    """Spectral-MIS collision density (1/3) sum_c sigma_c exp(-sigma_c t)."""
    s = 0.0
    for c in range(3):
        if sigma_t[c] > 0.0:
            s += sigma_t[c] * math.exp(-sigma_t[c] * t)
    return s / 3.0


@ir_inline
def pass_probability(sigma_t, t_max):
    """Spectral-MIS probability of no collision before t_max: (1/3) sum_c exp(-sigma_c t_max)."""
    return (_tr1(sigma_t[0], t_max) + _tr1(sigma_t[1], t_max) + _tr1(sigma_t[2], t_max)) / 3.0


# forceinline: called on every segment of a volume path (a call costs more than the grey case)
@inlined
def sample_distance(sigma_t, albedo, t_max, u_channel, u):
    """Free-flight sampling in an RGB homogeneous medium with spectral MIS (module doc).

    Returns ``(t, scattered, weight)``: on a collision (scattered=True) t < t_max and
    weight = sigma_s T(t) / pdf(t); otherwise t = t_max and weight = T(t_max) / P(t >= t_max).
    A zero-probability outcome returns weight (0, 0, 0).

    A grey medium (equal sigma_t in every channel, as the scenes' scalar ``sigma_t``) needs no
    exponential: pdf(t) = sigma T(t) and P = T(t_max), so the weights are exactly the albedo and 1
    (:func:`!_sample_distance_grey`). Otherwise each channel's exp(-sigma_c t) is computed once and
    shared by the density and the transmittance (the same numbers as computing both separately).
    """
    c = min(int(u_channel * 3.0), 2)
    sc = sigma_t[c]
    t = neg_log1m(u) / sc if sc > 0.0 else math.inf
    if sigma_t[0] == sigma_t[1] and sigma_t[1] == sigma_t[2]:
        return _sample_distance_grey(albedo, t, t_max)
    if t < t_max:
        tr = transmittance(sigma_t, t)
        pdf = _mis_sum(sigma_t, tr, True)
        if not pdf > 0.0:
            return t, True, (0.0, 0.0, 0.0)
        k = 1.0 / pdf
        return t, True, (albedo[0] * sigma_t[0] * tr[0] * k, albedo[1] * sigma_t[1] * tr[1] * k,
                         albedo[2] * sigma_t[2] * tr[2] * k)
    tr = transmittance(sigma_t, t_max)
    p = _mis_sum(sigma_t, tr, False)
    if not p > 0.0:
        return t_max, False, (0.0, 0.0, 0.0)
    return t_max, False, (tr[0] / p, tr[1] / p, tr[2] / p)


@ir_inline
def _mis_sum(sigma_t, tr, collision):
    """From the channels' transmittances tr: :func:`distance_pdf` (collision) or
    :func:`pass_probability` (else), summed in the same order, hence bit for bit the same values."""
    if collision:
        s = 0.0
        for c in range(3):
            if sigma_t[c] > 0.0:
                s += sigma_t[c] * tr[c]
        return s / 3.0
    return (tr[0] + tr[1] + tr[2]) / 3.0


@ir_inline
def _sample_distance_grey(albedo, t, t_max):
    """:func:`sample_distance` for sigma_t equal in all channels: the spectral-MIS density is the
    single-channel one, so sigma_s T(t) / pdf(t) = albedo and T(t_max) / P(pass) = 1 analytically
    (Novak et al. 2018, Sec. 5.1 with one channel). sigma = 0 gives t = inf: always a pass."""
    if t < t_max:
        return t, True, albedo
    return t_max, False, (1.0, 1.0, 1.0)


@block
def scatter_probability_1(sigma, t_max):
    """P(t < t_max) = 1 - exp(-sigma t_max), as -expm1 so sigma t_max ~ 1e-8 keeps full precision."""
    if sigma <= 0.0:
        return 0.0
    return -math.expm1(-sigma * t_max)


@block
def sample_distance_truncated_1(sigma, t_max, u):
    """Collision distance conditioned to lie in [0, t_max) -- Gruson et al. 2018, Eq. 14 (camera edge
    distance sampling), also forced scattering in single-scattering estimators and photon tracing:
    t = -log1p(u expm1(-sigma t_max)) / sigma with density sigma exp(-sigma t) / (1 - exp(-sigma t_max)).
    Returns (t, pdf). sigma = 0 -> uniform on [0, t_max)."""
    if sigma <= 0.0 or t_max <= 0.0:
        if t_max <= 0.0:
            return 0.0, 0.0
        return u * t_max, 1.0 / t_max
    em = math.expm1(-sigma * t_max)          # -(1 - T(t_max)), accurate for thin media
    t = -math.log1p(u * em) / sigma
    t = min(t, t_max)
    return t, sigma * math.exp(-sigma * t) / (-em)


@ir_inline
def medium_params(med):
    """(sigma_t, albedo, g) of a medium row (columns layout.MED_*)."""
    return ((med[MED_SIGMA_T], med[MED_SIGMA_T + 1], med[MED_SIGMA_T + 2]),
            (med[MED_ALBEDO], med[MED_ALBEDO + 1], med[MED_ALBEDO + 2]), med[MED_G])
