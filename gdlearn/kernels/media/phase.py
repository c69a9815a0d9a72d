"""Henyey-Greenstein phase function (Henyey & Greenstein 1941), Mitsuba 3's ``hg`` / ``isotropic``.

Sign convention -- Mitsuba 3's (src/phase/hg.cpp), checked against mitsuba 3.9 in the tests:
``wi`` points BACK along the incoming path (away from the scattering point, like a BSDF's wi) and
``wo`` is the outgoing direction, so undeviated forward scattering is wo = -wi. With
cos_theta = dot(wi, wo),

    p(wi, wo) = (1 - g^2) / (4 pi (1 + g^2 + 2 g cos_theta)^(3/2))

(the textbook HG with the angle between propagation directions, cos -> -cos; it is the normalised
phase function p of Jarosz et al. 2008, Eq. 2, and rho_p of Gruson et al. 2018, Eq. 3)

so g > 0 scatters forward (peak at cos_theta = -1), g < 0 backward, g = 0 is isotropic (1 / 4 pi).
Sampling is exact inversion, so the sample weight p / pdf is 1. Both routines are written without
cancellation: the denominator as (1 -+ g)^2 + 2|g|(1 +- cos) and the sampled cosine in a form that
tends to the isotropic 2u - 1 as g -> 0 (no 0/0), and stays accurate at g = +-0.999.
"""
import math


from gdlearn.kernels.sampling import uniform_unit_circle
from gdlearn.kernels.vec import coordinate_system
from gdlearn.kernels.jit import inlined, ir_inline

INV_FOUR_PI = 0.25 / math.pi


@ir_inline
def hg_eval(g, cos_theta):
    """HG density for cos_theta = dot(wi, wo) (Mitsuba's convention, see module doc). Equals the pdf."""
    if g >= 0.0:
        temp = (1.0 - g) * (1.0 - g) + 2.0 * g * (1.0 + cos_theta)
    else:
        temp = (1.0 + g) * (1.0 + g) + 2.0 * g * (cos_theta - 1.0)
    if temp <= 0.0:          # only |g| = 1 exactly (rejected by the scene loader)
        return 0.0
    return INV_FOUR_PI * (1.0 - g * g) / (temp * math.sqrt(temp))


@inlined
def hg_sample_cos(g, u):
    """The cosine between -wi and wo (1 = straight on) drawn from HG by inversion.

    Textbook form: (1 + g^2 - ((1 - g^2) / (1 - g + 2 g u))^2) / (2 g), which is 0/0 at g = 0.
    Expanded with xi = 2u - 1 and d = 1 + g xi it becomes
    (xi + g (3 + xi^2 + 2 g xi + g^2 (xi^2 - 1)) / 2) / d^2, finite for every ``|g| < 1``.
    """
    xi = 2.0 * u - 1.0
    d = 1.0 + g * xi
    c = (xi + 0.5 * g * (3.0 + xi * xi + 2.0 * g * xi + g * g * (xi * xi - 1.0))) / (d * d)
    return min(1.0, max(-1.0, c))


# forceinline (with hg_sample_cos): called at every medium scattering vertex
@inlined
def hg_sample(g, wi, u1, u2):
    """Sample wo around -wi: returns (wo, pdf) with pdf = hg_eval(g, dot(wi, wo)) (weight 1).
    wi must be a unit vector (any frame: world space is fine). u1 gives the cosine by inversion
    (:func:`hg_sample_cos`), u2 the azimuth (uniform: HG is rotationally symmetric about -wi)."""
    cos_t = hg_sample_cos(g, u1)
    sin_t = math.sqrt(max(0.0, (1.0 - cos_t) * (1.0 + cos_t)))
    cphi, sphi = uniform_unit_circle(u2)    # polynomials, not libm's sincos (benchmarks/README)
    fwd = (-wi[0], -wi[1], -wi[2])
    s, t = coordinate_system(fwd)
    a, b = sin_t * cphi, sin_t * sphi
    wo = (s[0] * a + t[0] * b + fwd[0] * cos_t,
          s[1] * a + t[1] * b + fwd[1] * cos_t,
          s[2] * a + t[2] * b + fwd[2] * cos_t)
    return wo, hg_eval(g, -cos_t)
