"""Isotropic Beckmann and GGX microfacet distributions (Walter et al. 2007) with visible-normal
sampling (Heitz & d'Eon 2014), as in Mitsuba 3's ``mitsuba/render/microfacet.h``.

``dist`` is ``layout.BECKMANN`` or ``layout.GGX``; ``alpha`` the roughness, clamped to 1e-4 like
Mitsuba's ``MicrofacetDistribution::configure``. Vectors are local (normal = +z) 3-tuples.

* D(m)                      Walter et al. Eq. 25 (Beckmann) and Eq. 33 (GGX)
* G1(v, m)                  Smith masking: Eq. 34 (GGX), Eq. 27 via Mitsuba's rational fit (Beckmann)
* D_wi(m) = G1(wi, m) |wi.m| D(m) / cos(wi)   distribution of visible normals (Heitz 2014, Eq. 1)
"""
import math


from gdlearn.kernels.layout import BECKMANN
from gdlearn.kernels.sampling import square_to_uniform_disk_concentric
from gdlearn.kernels.jit import block, ir_inline

ALPHA_MIN = 1e-4
_INV_SQRT_PI = 1.0 / math.sqrt(math.pi)


@ir_inline
def clamp_alpha(alpha):
    return max(alpha, ALPHA_MIN)


@block
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


@block
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


@block
def mf_G(dist, alpha, wi, wo, m):
    """Separable Smith shadowing-masking G(wi, wo, m) = G1(wi, m) G1(wo, m)."""
    return mf_G1(dist, alpha, wi, m) * mf_G1(dist, alpha, wo, m)


@block
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


@block
def erfinv_approx(x):
    """Giles (2010) single-precision approximation of the inverse error function (|x| < 1)."""
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
    return p * x


@block
def erfinv(x):
    """Inverse error function in float64 (numba has none): :func:`erfinv_approx` refined by Newton
    steps; for |x| > 1/2 on log erfc(|y|) = log(1 - |x|) -- the complement keeps its relative
    precision as |x| -> 1 (erf(y) - x would cancel) and the log makes the tail nearly quadratic so
    Newton converges in a few steps. |x| >= 1 maps to +-inf."""
    if x >= 1.0:
        return math.inf
    if x <= -1.0:
        return -math.inf
    ax = abs(x)
    y = erfinv_approx(ax)
    c = 1.0 - ax                         # exact for ax >= 0.5 (Sterbenz)
    for _ in range(4):
        dy = 2.0 * _INV_SQRT_PI * math.exp(-y * y)
        if not dy > 0.0:
            break
        if ax > 0.5:
            ec = math.erfc(y)
            step = (math.log(ec) - math.log(c)) * ec / dy
        else:
            step = (ax - math.erf(y)) / dy
        y += step
        if abs(step) <= 1e-15 * y:
            break
    return y if x >= 0.0 else -y


@block
def _visible_slopes_beckmann(cos_i, u1, u2):
    """Slopes of visible normals of the alpha = 1 Beckmann distribution seen from cos_i (Jakob 2014,
    "An improved visible normal sampling routine for the Beckmann distribution": numerical
    inversion of the slope CDF  C(s) = 1 + erf(s) + tan_i exp(-s^2) / sqrt(pi)  (unnormalised)).

    Mitsuba runs 3 Newton steps in the erf domain in float32. We do the same 3 steps with the
    single-precision erfinv, then polish in the slope domain (dC/ds = 2 exp(-s^2)(1 - s tan_i) /
    sqrt(pi), no erfinv needed) until float64 convergence, so the samples follow the analytic pdf.
    """
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
    target = u1 * (1.0 + maxval + tail)  # C(s) at the sample
    lo, hi = -1.0 + 1e-16, 1.0 - 1e-16
    for _ in range(3):
        slope = erfinv_approx(min(max(x, lo), hi))
        value = 1.0 + x + _INV_SQRT_PI * tan_i * math.exp(-slope * slope) - target
        deriv = 1.0 - slope * tan_i
        if deriv <= 0.0:
            break
        x = min(max(x - value / deriv, lo), hi)
    slope = erfinv_approx(x)             # ~1e-7 accurate; the polish below converges quadratically
    for _ in range(4):
        e = math.exp(-slope * slope)
        value = 1.0 + math.erf(slope) + _INV_SQRT_PI * tan_i * e - target
        deriv = 2.0 * _INV_SQRT_PI * e * (1.0 - slope * tan_i)
        if not deriv > 0.0:
            break
        step = value / deriv
        if abs(step) > 0.25 * (1.0 + abs(slope)):   # far from the root: keep the erf-domain result
            break
        slope -= step
        if abs(step) < 1e-9 * (1.0 + abs(slope)):   # quadratic convergence: the error is now ~1e-18
            break
    y = 2.0 * u2 - 1.0                   # |y| < 1 - 2e-6: one Newton step polishes Giles' 1e-7 to 1e-14
    z = erfinv_approx(y)
    z -= (math.erf(z) - y) / (2.0 * _INV_SQRT_PI * math.exp(-z * z))
    return slope, z


@block
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


@block
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
    r2 = x * x + y * y
    if not r2 < 1e300:                   # a numerically horizontal microfacet (or nan): no sample
        return (0.0, 0.0, 1.0), 0.0
    inv = 1.0 / math.sqrt(r2 + 1.0)
    m = (-x * inv, -y * inv, inv)
    return m, mf_pdf(dist, alpha, wi, m)
