"""Isotropic Beckmann and GGX microfacet distributions (Walter et al. 2007) with visible-normal
sampling (Heitz & d'Eon 2014), as in Mitsuba 3's ``mitsuba/render/microfacet.h``.

``dist`` is ``layout.BECKMANN`` or ``layout.GGX``; ``alpha`` the roughness, clamped to 1e-4 like
Mitsuba's ``MicrofacetDistribution::configure``. Vectors are local (normal = +z) 3-tuples.

* D(m)                      Walter et al. Eq. 25 (Beckmann) and Eq. 33 (GGX)
* G1(v, m)                  Smith masking: Eq. 34 (GGX), Eq. 27 via Mitsuba's rational fit (Beckmann)
* D_wi(m) = G1(wi, m) |wi.m| D(m) / cos(wi)   distribution of visible normals (Heitz 2014, Eq. 1)
"""
import math

from numba import njit

from gdlearn.kernels.layout import BECKMANN
from gdlearn.kernels.sampling import square_to_uniform_disk_concentric

ALPHA_MIN = 1e-4
_INV_SQRT_PI = 1.0 / math.sqrt(math.pi)


@njit(cache=True)
def clamp_alpha(alpha):
    return max(alpha, ALPHA_MIN)


@njit(cache=True)
def mf_D(dist, alpha, m):
    """Normal distribution D(m) (Walter et al. 2007, Eq. 25 / 33); 0 for m.z <= 0 and tiny values
    (Mitsuba drops D cos < 1e-20 to keep later stages finite)."""
    a = clamp_alpha(alpha)
    cos2 = m[2] * m[2]
    if m[2] <= 0.0:
        return 0.0
    xy2 = (m[0] * m[0] + m[1] * m[1]) / (a * a)
    if dist == BECKMANN:
        res = math.exp(-xy2 / cos2) / (math.pi * a * a * cos2 * cos2)
    else:
        t = xy2 + cos2
        res = 1.0 / (math.pi * a * a * t * t)
    return res if res * m[2] > 1e-20 else 0.0


@njit(cache=True)
def mf_G1(dist, alpha, v, m):
    """Smith's masking G1(v, m); 0 when v sees the back of m (Mitsuba's ``smith_g1``)."""
    if (v[0] * m[0] + v[1] * m[1] + v[2] * m[2]) * v[2] <= 0.0:
        return 0.0
    a = clamp_alpha(alpha)
    xy_a2 = a * a * (v[0] * v[0] + v[1] * v[1])
    if xy_a2 == 0.0:                     # normal incidence: no masking
        return 1.0
    tan_a2 = xy_a2 / (v[2] * v[2])       # v[2] != 0 here (checked above)
    if dist == BECKMANN:
        b = abs(v[2]) / math.sqrt(xy_a2)  # 1 / (alpha tan theta)
        if b >= 1.6:
            return 1.0
        # Rational approximation of the Beckmann Smith term (<0.35% rel. error), as Mitsuba
        return (3.535 * b + 2.181 * b * b) / (1.0 + 2.276 * b + 2.577 * b * b)
    return 2.0 / (1.0 + math.sqrt(1.0 + tan_a2))


@njit(cache=True)
def mf_G(dist, alpha, wi, wo, m):
    """Separable Smith shadowing-masking G(wi, wo, m) = G1(wi, m) G1(wo, m)."""
    return mf_G1(dist, alpha, wi, m) * mf_G1(dist, alpha, wo, m)


@njit(cache=True)
def mf_pdf(dist, alpha, wi, m):
    """Density of :func:`mf_sample` over microfacet normals: the visible-normal distribution
    D(m) G1(wi, m) |wi.m| / cos(wi) (Heitz & d'Eon 2014, Eq. 2). wi.z must be > 0."""
    if wi[2] <= 0.0:
        return 0.0
    d = mf_D(dist, alpha, m)
    if d == 0.0:
        return 0.0
    dot_wm = abs(wi[0] * m[0] + wi[1] * m[1] + wi[2] * m[2])
    return d * mf_G1(dist, alpha, wi, m) * dot_wm / wi[2]


@njit(cache=True)
def erfinv(x):
    """Inverse error function in float64: Giles' (2010) approximation refined by two Newton steps
    on math.erf (numba has no erfinv). |x| >= 1 maps to +-inf."""
    if x >= 1.0:
        return math.inf
    if x <= -1.0:
        return -math.inf
    w = -math.log((1.0 - x) * (1.0 + x))
    if w < 5.0:
        w -= 2.5
        p = 2.81022636e-08
        p = 3.43273939e-07 + p * w
        p = -3.5233877e-06 + p * w
        p = -4.39150654e-06 + p * w
        p = 0.00021858087 + p * w
        p = -0.00125372503 + p * w
        p = -0.00417768164 + p * w
        p = 0.246640727 + p * w
        p = 1.50140941 + p * w
    else:
        w = math.sqrt(w) - 3.0
        p = -0.000200214257
        p = 0.000100950558 + p * w
        p = 0.00134934322 + p * w
        p = -0.00367342844 + p * w
        p = 0.00573950773 + p * w
        p = -0.0076224613 + p * w
        p = 0.00943887047 + p * w
        p = 1.00167406 + p * w
        p = 2.83297682 + p * w
    y = p * x
    for _ in range(2):
        dy = 2.0 * _INV_SQRT_PI * math.exp(-y * y)
        if dy > 0.0:
            y -= (math.erf(y) - x) / dy
    return y


@njit(cache=True)
def _visible_slopes_beckmann(cos_i, u1, u2):
    """Slopes of visible normals of the alpha = 1 Beckmann distribution seen from cos_i (Jakob 2014,
    "An improved visible normal sampling routine for the Beckmann distribution": numerical
    inversion of the slope CDF in the erf domain). Mitsuba uses 3 Newton steps in float32; in
    float64 we iterate to convergence so the samples follow the analytic pdf."""
    u1 = min(max(u1, 1e-6), 1.0 - 1e-6)
    u2 = min(max(u2, 1e-6), 1.0 - 1e-6)
    sin_i = math.sqrt(max(0.0, 1.0 - cos_i * cos_i))
    if sin_i < 1e-12 * cos_i:            # normal incidence: tan = 0, cot = inf
        tan_i, maxval, tail = 0.0, 1.0, 0.0
    else:
        tan_i = sin_i / cos_i
        cot_i = cos_i / sin_i
        maxval = math.erf(cot_i)
        tail = _INV_SQRT_PI * tan_i * math.exp(-cot_i * cot_i)
    # initial guess: analytic solution for theta_i = pi/2
    x = maxval - (maxval + 1.0) * math.erf(math.sqrt(-math.log(u1)))
    s = u1 * (1.0 + maxval + tail)       # normalised CDF target
    for _ in range(12):
        slope = erfinv(x)
        value = 1.0 + x + _INV_SQRT_PI * tan_i * math.exp(-slope * slope) - s
        deriv = 1.0 - slope * tan_i
        if deriv == 0.0:
            break
        step = value / deriv
        x -= step
        x = min(max(x, -1.0 + 1e-15), 1.0 - 1e-15)
        if abs(step) < 1e-14:
            break
    return erfinv(x), erfinv(2.0 * u2 - 1.0)


@njit(cache=True)
def _visible_slopes_ggx(cos_i, u1, u2):
    """Slopes of visible normals of the alpha = 1 GGX distribution (Heitz 2017, "A simpler and exact
    sampling routine for the GGX distribution of visible normals"), as Mitsuba."""
    px, py = square_to_uniform_disk_concentric(u1, u2)
    s = 0.5 * (1.0 + cos_i)
    lo = math.sqrt(max(0.0, 1.0 - px * px))
    py = lo + (py - lo) * s
    z = math.sqrt(max(0.0, 1.0 - px * px - py * py))
    sin_i = math.sqrt(max(0.0, 1.0 - cos_i * cos_i))
    den = sin_i * py + cos_i * z
    if den <= 0.0:
        return 0.0, 0.0
    return (cos_i * py - sin_i * z) / den, px / den


@njit(cache=True)
def mf_sample(dist, alpha, wi, u1, u2):
    """Sample a visible microfacet normal m for wi (wi.z > 0): stretch, sample the alpha = 1 slopes,
    rotate and unstretch (Heitz & d'Eon 2014, Sec. 4). Returns (m, pdf) with pdf = :func:`mf_pdf`."""
    a = clamp_alpha(alpha)
    sx, sy, sz = a * wi[0], a * wi[1], wi[2]
    n = math.sqrt(sx * sx + sy * sy + sz * sz)
    sx, sy, sz = sx / n, sy / n, sz / n
    r = math.sqrt(sx * sx + sy * sy)
    if r > 0.0:
        cos_phi, sin_phi = sx / r, sy / r
    else:
        cos_phi, sin_phi = 1.0, 0.0
    if dist == BECKMANN:
        x, y = _visible_slopes_beckmann(sz, u1, u2)
    else:
        x, y = _visible_slopes_ggx(sz, u1, u2)
    x, y = (cos_phi * x - sin_phi * y) * a, (sin_phi * x + cos_phi * y) * a
    inv = 1.0 / math.sqrt(x * x + y * y + 1.0)
    m = (-x * inv, -y * inv, inv)
    return m, mf_pdf(dist, alpha, wi, m)
