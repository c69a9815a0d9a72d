"""Warping functions: map uniform samples in [0,1)^2 to directions and points, with their densities,
plus the multiple-importance-sampling heuristics.

The warps follow Mitsuba 3's ``mitsuba/core/warp.h``: the concentric disk, cosine hemisphere,
uniform sphere and triangle use Mitsuba's parameterisation (the same ``(u1, u2)`` gives the same
point); the uniform hemisphere and cone use the textbook inversion (same distribution, different
mapping). Densities are with respect to solid angle (directions) or area (points). The MIS weights are Veach's balance and power heuristics
(Veach 1997, Sec. 9.2.2, Eq. 9.10 and 9.12) written as ratios so that pdfs of 1e-300 and 1e300 never
overflow or produce 0/0.
"""
import math
from gdlearn.kernels.jit import block, inlined


INV_PI = 1.0 / math.pi
INV_TWO_PI = 0.5 / math.pi
INV_FOUR_PI = 0.25 / math.pi


# Taylor coefficients of sin and cos up to degree 15 / 16: for |a| <= pi/4 the first omitted terms
# are below 5e-17 and 3e-18, i.e. under half an ulp of the result
_S3, _S5, _S7, _S9 = -1.0 / 6.0, 1.0 / 120.0, -1.0 / 5040.0, 1.0 / 362880.0
_S11, _S13, _S15 = -1.0 / 39916800.0, 1.0 / 6227020800.0, -1.0 / 1307674368000.0
_C2, _C4, _C6, _C8 = -0.5, 1.0 / 24.0, -1.0 / 720.0, 1.0 / 40320.0
_C10, _C12, _C14, _C16 = -1.0 / 3628800.0, 1.0 / 479001600.0, -1.0 / 87178291200.0, 1.0 / 20922789888000.0


@inlined
def sincos_quarter(a):
    """(sin a, cos a) for ``|a| <= pi/4`` by polynomials: a few multiply-adds instead of a call into
    libm's sincos (whose argument reduction the concentric map does not need; the call was ~7% of
    a Cornell-box path). Accurate to about an ulp on that range."""
    a2 = a * a
    s = a + a * a2 * (_S3 + a2 * (_S5 + a2 * (_S7 + a2 * (_S9 + a2 * (_S11 + a2 * (_S13 + a2 * _S15))))))
    c = 1.0 + a2 * (_C2 + a2 * (_C4 + a2 * (_C6 + a2 * (_C8 + a2 * (_C10 + a2 * (_C12 + a2 * (_C14 + a2 * _C16)))))))
    return s, c


@inlined
def uniform_unit_circle(u):
    """(cos phi, sin phi) for the uniform angle phi = 2 pi u - pi/4, without libm's sincos.

    u picks the quadrant q = floor(4u) and an angle a = (pi/2)(4u - q - 1/2) in [-pi/4, pi/4) inside
    it, so phi = q pi/2 + a: :func:`sincos_quarter` gives (cos a, sin a), a rotation by q quarter
    turns (a swap and two signs, by arithmetic, not branches: q is a coin toss per sample) the rest.
    The pi/4 offset against 2 pi u is a fixed rotation of the tangent frame: phi stays uniform."""
    q = min(int(4.0 * u), 3)
    s, c = sincos_quarter((0.5 * math.pi) * ((4.0 * u - q) - 0.5))
    odd = q & 1
    sx = float(1 - 2 * (((q + 1) >> 1) & 1))    # cos phi < 0 in quadrants 1, 2
    sy = float(1 - 2 * (q >> 1))                # sin phi < 0 in quadrants 2, 3
    x = s if odd else c
    y = c if odd else s
    return sx * x, sy * y


@inlined
def square_to_uniform_disk_concentric(u1, u2):
    """Shirley-Chiu concentric map of the unit square to the unit disk (area-preserving, low
    distortion); Mitsuba's ``warp::square_to_uniform_disk_concentric``. Returns (x, y).

    The angle is phi = (pi/4) (y/x) in the sectors ``|x| > |y|``, else pi/2 - (pi/4) (x/y), so
    cos/sin of phi are cos/sin (or sin/cos) of an angle in [-pi/4, pi/4]: :func:`sincos_quarter`."""
    x = 2.0 * u1 - 1.0
    y = 2.0 * u2 - 1.0
    if x == 0.0 and y == 0.0:
        return 0.0, 0.0
    # selects, not branches: the sector is a coin toss per sample (a mispredicted branch per bounce)
    wide = abs(x) > abs(y)
    r = x if wide else y
    s, c = sincos_quarter((math.pi / 4.0) * ((y if wide else x) / r))
    return r * (c if wide else s), r * (s if wide else c)



@inlined
def square_to_cosine_hemisphere(u1, u2):
    """Cosine-weighted hemisphere (Malley's method: a concentric disk sample lifted onto the
    hemisphere); pdf = cos(theta) / pi. Mitsuba's ``warp::square_to_cosine_hemisphere``."""
    x, y = square_to_uniform_disk_concentric(u1, u2)
    z = math.sqrt(max(0.0, 1.0 - x * x - y * y))
    return (x, y, z)


@inlined
def cosine_hemisphere_pdf(w):
    """pdf of :func:`square_to_cosine_hemisphere` (0 below the horizon)."""
    return INV_PI * w[2] if w[2] > 0.0 else 0.0


@block
def square_to_uniform_sphere(u1, u2):
    """Uniform direction on the unit sphere; pdf = 1 / (4 pi)."""
    z = 1.0 - 2.0 * u2
    r = math.sqrt(max(0.0, 1.0 - z * z))
    phi = 2.0 * math.pi * u1
    return (r * math.cos(phi), r * math.sin(phi), z)


@block
def uniform_sphere_pdf():
    return INV_FOUR_PI


@block
def square_to_uniform_hemisphere(u1, u2):
    """Uniform direction on the upper (+z) hemisphere; pdf = 1 / (2 pi)."""
    z = u1
    r = math.sqrt(max(0.0, 1.0 - z * z))
    phi = 2.0 * math.pi * u2
    return (r * math.cos(phi), r * math.sin(phi), z)


@block
def uniform_hemisphere_pdf(w):
    return INV_TWO_PI if w[2] >= 0.0 else 0.0


@block
def square_to_uniform_cone(u1, u2, cos_cutoff):
    """Uniform direction in the cone of half-angle acos(cos_cutoff) around +z;
    pdf = 1 / (2 pi (1 - cos_cutoff)).

    ``1 - cos theta`` is sampled directly (``one_minus_cos``) so narrow cones (cos_cutoff -> 1)
    keep their precision: sin^2 = (1 - cos)(1 + cos) never forms 1 - cos^2 from a rounded cos.
    """
    one_minus_cos = u1 * (1.0 - cos_cutoff)
    cos_t = 1.0 - one_minus_cos
    sin_t = math.sqrt(max(0.0, one_minus_cos * (2.0 - one_minus_cos)))
    phi = 2.0 * math.pi * u2
    return (sin_t * math.cos(phi), sin_t * math.sin(phi), cos_t)


@block
def uniform_cone_pdf(w, cos_cutoff):
    """Solid-angle density of :func:`square_to_uniform_cone` (0 outside the cone)."""
    if w[2] < cos_cutoff:
        return 0.0
    denom = 2.0 * math.pi * (1.0 - cos_cutoff)
    return 1.0 / denom if denom > 0.0 else 0.0


@block
def square_to_uniform_triangle(u1, u2):
    """Uniform barycentrics (b1, b2) on a triangle (Mitsuba's ``square_to_uniform_triangle``:
    the square is folded along its diagonal). The point is (1 - b1 - b2) p0 + b1 p1 + b2 p2 and the
    area density is 1 / area."""
    t = math.sqrt(1.0 - u1)
    return 1.0 - t, t * u2


@inlined
def balance_heuristic(pdf_a, pdf_b):
    """Veach's balance heuristic w_a = p_a / (p_a + p_b) (Eq. 9.10) as 1 / (1 + p_b / p_a).

    The ratio form never forms p_a + p_b, so pdfs of 1e300 do not overflow and pdfs of 1e-300 do
    not underflow to 0/0. Returns 0 when p_a <= 0 (the technique could not have produced the sample).
    """
    if not pdf_a > 0.0:
        return 0.0
    if not pdf_b > 0.0:
        return 1.0
    r = pdf_b / pdf_a          # inf when p_b >> p_a (weight 0), 0 when p_b << p_a (weight 1)
    return 1.0 / (1.0 + r)


@inlined
def power_heuristic(pdf_a, pdf_b):
    """Veach's power heuristic with beta = 2, w_a = p_a^2 / (p_a^2 + p_b^2) (Eq. 9.12), computed as
    1 / (1 + (p_b / p_a)^2) so squares of extreme pdfs never overflow. Mitsuba 3's path integrator
    uses this weight for NEE and BSDF sampling. Returns 0 when p_a <= 0."""
    if not pdf_a > 0.0:
        return 0.0
    if not pdf_b > 0.0:
        return 1.0
    r = pdf_b / pdf_a
    if r > 1e150:              # r^2 would overflow to inf: the weight is 0 to double precision
        return 0.0
    return 1.0 / (1.0 + r * r)
